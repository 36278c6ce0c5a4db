"""``--grow-past-edge`` (issue 22 item 5): a feature cut by the frame may grow past the edges
that cut it, so the background it stretches takes less; nothing else changes, and where it
cannot be done a warning says so."""

from __future__ import annotations

import json
import os

import cv2
import numpy as np
import pytest

from featurewarp_cli import FeatureWarper, load_warp
from featurewarp_cli.cli.main import cli as main
from featurewarp_cli.engine.record import BLANK, KEPT, STREAKS

SAMPLES = os.path.join(os.path.dirname(__file__), os.pardir, "samples")


def mask_of(name: str) -> np.ndarray:
    return cv2.imread(os.path.join(SAMPLES, name), cv2.IMREAD_GRAYSCALE) >= 128


def solve(mask, preset="stretch", mode="similarity", grow=True, **params):
    h, w = mask.shape
    warper = FeatureWarper(w, h, mask, grow_past_edge=grow)
    return warper.solve(load_warp(preset)(w, h, **params), mode)


@pytest.mark.parametrize("mask, params", [
    ("astronaut_body_mask.png", {"sy": 2}),          # the bust: cut by the bottom and left edges
    ("astronaut_body_mask.png", {"sx": 0.6}),
    ("closeup_mask.png", {"sy": 2}),                 # a face filling the frame
    ("dahlia_mask.png", {"sy": 2}),                  # a flower cut by the top and right edges
    ("dahlia_mask.png", {"sx": 2}),
])
def test_a_cut_feature_grows_past_its_edges_until_nothing_streaks(mask, params):
    features = mask_of(mask)
    plain = solve(features, grow=False, **params).record
    assert plain.background_stretch > STREAKS                       # it streaks without the option
    mesh = solve(features, **params)
    record = mesh.record
    assert record.background_stretch <= STREAKS
    assert record.grown["k"] > 1.0 and record.grown["components"]
    assert all(record.components[c].anisotropy_worst <= 1e-6 for c in record.grown["components"])   # exact
    assert all(c.kept for c in record.components)
    assert mesh.flips() == 0 and record.warnings == []
    assert record.blank_share <= record.plain_blank_share + BLANK and record.outline_departure <= 1.0
    assert set(record.grown["past_px"]) == set(record.grown["sides"]) and max(record.grown["past_px"].values()) > 1


def test_the_portrait_rises_into_the_strip_above_it():
    """The head moves up, the body grows, and it crops at the edges that cut it only."""
    features = mask_of("astronaut_body_mask.png")
    before, after = solve(features, grow=False, sy=2), solve(features, sy=2)
    body = np.flatnonzero(before.node_component == 0)
    assert after.target[body, 1].min() < before.target[body, 1].min() - 200          # the head rises
    assert after.record.components[0].scale > 1.5 * before.record.components[0].scale
    assert set(after.record.grown["sides"]) == {"bottom", "left"}


def test_without_streaks_or_without_the_option_nothing_changes():
    features = mask_of("astronaut_body_mask.png")
    for params in ({"sy": 1.2}, {"sx": 1.5}):                      # streaks nowhere: the option is idle
        with_option, without = solve(features, **params), solve(features, grow=False, **params)
        assert with_option.record.background_stretch <= STREAKS and with_option.record.grown is None
        np.testing.assert_array_equal(with_option.target, without.target)
    swirl = solve(features, preset="swirl", angle=120)
    np.testing.assert_array_equal(swirl.target, solve(features, preset="swirl", grow=False, angle=120).target)


def test_where_growing_cannot_help_nothing_grows_and_a_warning_says_why():
    """The pagoda is cut by the bottom edge only: it cannot grow without squeezing the sky and
    the lake beside it; the trees would grow into it. The result is the one without the option."""
    features = mask_of("china_mask.png")
    mesh, without = solve(features, sy=2), solve(features, grow=False, sy=2)
    np.testing.assert_array_equal(mesh.target, without.target)
    assert mesh.record.grown["k"] == 1.0 and mesh.record.grown["declined"]
    assert sum(w.startswith("--grow-past-edge grew nothing") for w in mesh.record.warnings) == 1
    assert mesh.record.warnings[:-1] == without.record.warnings
    rigid = solve(mask_of("astronaut_body_mask.png"), mode="rigid", sy=2).record
    assert "rigid mode" in rigid.grown["declined"] and any("grew nothing" in w for w in rigid.warnings)


def test_grow_past_edge_on_the_command_line(tmp_path):
    from click.testing import CliRunner

    out, report = tmp_path / "grown.png", tmp_path / "featurewarp-report" / "grown.json"
    report.parent.mkdir()
    result = CliRunner().invoke(main, ["warp", "stretch", "--sy", "2", os.path.join(SAMPLES, "astronaut.png"),
                                       str(out), "-m", os.path.join(SAMPLES, "astronaut_body_mask.png"),
                                       "--grow-past-edge", "--strict", "--report", str(report)])
    assert result.exit_code == 0, result.output
    data = json.loads(report.read_text())
    assert data["background_stretch"] <= STREAKS and data["grown"]["k"] > 1 and data["warnings"] == []
    assert cv2.imread(str(out)).shape[:2] == (1024, 512)
    assert data["components"]["items"][0]["anisotropy_worst"] <= KEPT

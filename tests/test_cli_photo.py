"""The retoucher trial (photo findings 10, 11 and nits 1-4): style names, the input's alpha as
its mask, the warp help, --grow-past-edge's crop on stderr, a run that moves nothing, arc's help."""

from __future__ import annotations

import json

import numpy as np
import pytest
from test_cli import SIZE, runner, save, scene, square_mask, textured  # noqa: F401  (runner: a fixture)

from featurewarp_cli.cli.styles import style_owners, summary_styles


# --- style names (finding 10) ----------------------------------------------------------------

@pytest.mark.parametrize("name, preset, options", [
    ("fisheye", "bulge", []), ("pinch", "bulge", []), ("twist", "swirl", []), ("twirl", "swirl", []),
    ("wave", "flag", ["--waves", "2"]), ("resize", "stretch", []), ("spherize", "sphere", []),
    ("Arc-Lower", "arc", [])])
def test_a_style_name_leads_to_its_preset(runner, name, preset, options):
    run = runner("warp", name, "in.png", "out.png", "--bend", "30")
    assert run.code == 2
    line = " ".join(["featurewarp warp", preset, "in.png out.png --bend 30", *options])
    assert line in run.stderr and "did you mean" not in run.stderr, run.stderr
    assert run.stderr.count("\n") <= 2                     # usage line and the error, no traceback


def test_fisheye_is_not_fish_and_a_misspelling_still_gets_the_nearest_name(runner):
    assert "'fish'" not in runner("warp", "fisheye", "a.png", "b.png").stderr
    assert "did you mean 'swirl'?" in runner("batch", "swril", "a.png", "-o", "out").stderr


def test_a_style_of_several_presets_names_them_all(runner):
    run = runner("compare", "lower", "a.png", "b.png")
    assert run.code == 2
    assert "featurewarp compare arc a.png b.png" in run.stderr and "featurewarp compare shell a.png b.png" in run.stderr


def test_styles_come_from_the_summaries():
    styles = summary_styles("Flag (--waves 1) and Wave (--waves 2 or more) of Photoshop and Illustrator: a sine.")
    assert styles == {"flag": ("Flag", "--waves 1"), "wave": ("Wave", "--waves 2")}
    assert [owner[0] for owner in style_owners("photoshop")] == []

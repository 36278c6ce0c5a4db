"""Real photos (issue 10): frame-cut and frame-filling features, measured on the output image.

The portrait's mask (head and body) touches the bottom and left edges; the close-up's
covers 81 % of the frame. Distortion is read off the written image by keypoints
(:mod:`featurewarp_cli.app.measure`), not only off the mesh, and the report must agree.
"""

from __future__ import annotations

import json
import os

import cv2
import numpy as np
import pytest

from featurewarp_cli import FeatureWarper, load_warp
from featurewarp_cli.app.measure import measure
from featurewarp_cli.cli.main import cli as main
from featurewarp_cli.engine.record import STREAKS

SAMPLES = os.path.join(os.path.dirname(__file__), os.pardir, "samples")


def sample(name: str) -> np.ndarray:
    image = cv2.imread(os.path.join(SAMPLES, name), cv2.IMREAD_UNCHANGED)
    assert image is not None, name
    return image


@pytest.fixture(scope="module")
def portrait():
    return sample("astronaut.png"), sample("astronaut_body_mask.png") >= 128


@pytest.fixture(scope="module")
def closeup():
    return sample("closeup.png"), sample("closeup_mask.png") >= 128


def warped(image, mask, preset, mode="similarity", cell=None, **params):
    h, w = mask.shape
    warper = FeatureWarper(w, h, mask, cell=cell)
    mesh = warper.solve(load_warp(preset)(w, h, **params), mode)
    return warper.render(image, mesh, background=(255, 255, 255)), mesh


def test_the_portrait_is_cut_by_the_frame_and_the_closeup_fills_it(portrait, closeup):
    """The two cases are what they claim to be (guards against a sample that drifts)."""
    _, mask = portrait
    assert mask[-1].any() and mask[:, 0].any() and 0.3 < mask.mean() < 0.7
    assert closeup[1].mean() > 0.8


@pytest.mark.parametrize("mode,params", [("similarity", {"sy": 2}), ("similarity", {"sx": 2}),
                                         ("similarity", {"sx": 0.6}), ("rigid", {"sy": 2}),
                                         ("rigid", {"sx": 2})])
def test_frame_cut_portrait_keeps_its_shape_in_the_image(portrait, mode, params):
    """Every masked region's keypoint-fitted map is a similarity within 0.03 (rigid: scale 1 +- 0.03),
    and the report's figure agrees with the image's within 0.02. What it costs, the strip that
    the edge leaves between the subject and the frame stretched into streaks, is said: one
    warning naming the place, and nothing else."""
    image, mask = portrait
    out, mesh = warped(image, mask, "stretch", mode, **params)
    fits = measure(image, out, mask)
    assert fits and all(f.distortion is not None for f in fits), [f.reason for f in fits]
    for fit, component in zip(fits, mesh.info["components"]):
        assert fit.distortion <= 0.03, (fit.distortion, component)
        assert abs(component["distortion"] - fit.distortion) <= 0.02
        assert component["kept"]
        if mode == "rigid":
            assert abs(fit.scale - 1.0) <= 0.03
    assert mesh.flips() == 0
    stretch = mesh.info["background_stretch"]
    said = [w for w in mesh.info["warnings"] if w.startswith("background stretched")]
    assert len(said) == (stretch > STREAKS) and len(mesh.info["warnings"]) == len(said), mesh.info["warnings"]
    if said:
        x, y = mesh.info["background_stretch_at"]
        assert f"near ({x:.0f}, {y:.0f})" in said[0]
        width, height = mesh.canvas
        assert 0 <= x < width and 0 <= y < height


def test_rigid_portrait_that_cannot_fit_warns_and_is_no_worse_than_plain(portrait):
    """Rigid --sx 0.6: a subject wider than the new canvas cannot keep its size: the tool says
    so and the subject is no more distorted than under the plain stretch.

    Solved on an 8 px grid (a quarter of the solve's time on the automatic 4 px one): the same
    route, the fold guard's path from W ends in one release round that lets the subject go."""
    image, mask = portrait
    out, mesh = warped(image, mask, "stretch", "rigid", cell=8.0, sx=0.6)
    guard = mesh.record.guard
    assert guard.path_steps > 0 and guard.release_rounds == 1 and guard.released_components == [0]
    assert any("not kept" in line for line in mesh.info["warnings"])
    for component in mesh.info["components"]:
        assert component["anisotropy_worst"] <= component["plain_anisotropy_worst"] + 1e-6
    fit = measure(image, out, mask)[0]
    plain_fit = measure(image, warped(image, mask, "stretch", "plain", cell=8.0, sx=0.6)[0], mask)[0]
    assert fit.distortion < plain_fit.distortion


def test_portrait_background_stretch_is_spread(portrait):
    """With 40 px of room above the head, stretch --sy 2 stretches no background triangle more
    than 8.5 times beyond the warp (the stretch is not piled into a few rows; the figure is the
    largest singular value, which the area ratio under 8 bounded before)."""
    image, mask = portrait
    image = cv2.copyMakeBorder(image, 40, 0, 0, 0, cv2.BORDER_REFLECT)
    mask = np.pad(mask, ((40, 0), (0, 0)))
    _, mesh = warped(image, mask, "stretch", sy=2)
    assert mesh.info["components"][0]["kept"]
    assert mesh.info["background_stretch"] <= 8.5


def test_subject_that_fills_the_height_grows_instead_of_streaking_the_sky(portrait, monkeypatch):
    """stretch --sy 2 on a portrait with room at the side: the subject grows uniformly (scale
    above least squares' 1.1) and the strip over the head takes less of the stretch."""
    from featurewarp_cli.engine import scale_search

    image, mask = portrait
    image = cv2.copyMakeBorder(image, 11, 0, 0, 500, cv2.BORDER_REFLECT)
    mask = np.pad(mask, ((11, 0), (0, 500)))
    _, spread = warped(image, mask, "stretch", sy=2)
    monkeypatch.setattr(scale_search, "SPREAD_ABOVE", np.inf)
    _, piled = warped(image, mask, "stretch", sy=2)
    grown, least_squares = spread.info["components"][0], piled.info["components"][0]
    assert grown["kept"] and spread.flips() == 0
    assert grown["scale"] >= least_squares["scale"] + 0.1
    assert spread.info["background_stretch"] < piled.info["background_stretch"]


def test_frame_filling_closeup_swirl_warns_that_the_output_is_the_input(closeup):
    """A swirl whose disc the mask fills (its rim pinned) leaves the picture as it was: said so."""
    image, mask = closeup
    out, mesh = warped(image, mask, "swirl", angle=180)
    assert any("the output is the input" in line for line in mesh.info["warnings"])
    assert np.abs(out.astype(int) - image[..., :3]).mean() < 2.0


def test_frame_filling_closeup_arc_is_no_worse_than_plain(closeup):
    """arc 300: no component comes out more distorted than under the plain arc; the tool says
    that the feature was not kept.

    Solved on an 8 px grid (an eighth of the time on the automatic 4 px one): the same route,
    the fold guard's path from W, then the feature moved back towards W (plain_blend below 1)
    as more distorted than under it."""
    image, mask = closeup
    _, mesh = warped(image, mask, "arc", cell=8.0, angle=300)
    guard = mesh.record.guard
    assert guard.path_steps > 0 and 0 < guard.plain_blend < 1 and guard.degraded_components == [0]
    assert mesh.flips() == 0
    for component in mesh.info["components"]:
        assert component["anisotropy_worst"] <= component["plain_anisotropy_worst"] + 1e-6
    assert any("not kept" in line for line in mesh.info["warnings"])


def test_arc_300_keeps_the_head_exact_when_only_the_frame_cut_helmet_must_give(portrait):
    """Head + helmet mask, arc 300: the helmet (cut by the frame, against curved pins) cannot
    stay a similarity; relaxing it must not drag the head, which stays exact."""
    image, _ = portrait
    mask = sample("astronaut_helmet_mask.png") >= 128
    _, mesh = warped(image, mask, "arc", angle=300)
    head, helmet = sorted(mesh.info["components"], key=lambda c: c["quads"])
    assert mesh.flips() == 0
    assert head["kept"], head
    assert helmet["anisotropy_worst"] <= helmet["plain_anisotropy_worst"] + 1e-6
    assert any("not kept" in line for line in mesh.info["warnings"])


def test_strict_turns_the_warning_into_exit_1_with_nothing_written(tmp_path):
    """--strict: where a warning is due the command fails and writes no image; its --report
    is written, marked refused with the warnings that caused it (a CI gate reads why)."""
    out, report = tmp_path / "out.png", tmp_path / "r.json"
    args = ["warp", "swirl", os.path.join(SAMPLES, "closeup.png"), str(out), "-m",
            os.path.join(SAMPLES, "closeup_mask.png"), "--angle", "180", "--report", str(report)]
    from click.testing import CliRunner

    runner = CliRunner()
    relaxed = runner.invoke(main, args)
    assert relaxed.exit_code == 0 and "the output is the input" in relaxed.output and out.exists()
    out.unlink()
    report.unlink()
    strict = runner.invoke(main, args + ["--strict"])
    assert strict.exit_code == 1 and "--strict" in strict.output
    assert not out.exists() and json.loads(report.read_text())["refused"]["warnings"]
    quiet = runner.invoke(main, args + ["-q"])
    assert quiet.exit_code == 0 and quiet.output == ""


@pytest.mark.parametrize("preset", ["cylinder", "sphere", "inflate"])
def test_a_closeup_is_never_worse_than_plain_globally_nor_locally(closeup, preset):
    """Issue 22 item 2: the close-up (its mask fills 83 % of the frame) under the presets that
    made its overall proportions worse than the plain warp's (affine fit 0.115 against 0.094
    under cylinder): per component, both the affine fit and the worst triangle are no worse
    than under the plain warp, as the report measures them (over the mesh's nodes; keypoints
    on the image weigh the textured face more: under sphere they read 0.036 against the plain
    warp's 0.017, which the issue's acceptance still asks for)."""
    image, mask = closeup
    _, mesh = warped(image, mask, preset)
    for component in mesh.info["components"]:
        assert component["distortion"] <= component["plain_distortion"] + 1e-6, component
        assert component["anisotropy_worst"] <= component["plain_anisotropy_worst"] + 1e-6, component


@pytest.mark.parametrize("name,preset", [("china", "arc"), ("china", "fish"), ("china", "cylinder"),
                                         ("china", "perspective"), ("dahlia", "arc"), ("dahlia", "inflate"),
                                         ("dahlia", "sphere"), ("dahlia", "squeeze")])
@pytest.mark.parametrize("mode", ["similarity", "rigid"])
def test_new_photos_keep_the_canvas_and_are_no_worse_than_plain(name, preset, mode):
    """Issue 22's rules on two photos whose masks touch two edges (scikit-learn's pagoda with
    the trees at the bottom right, 44 % of the frame; a dahlia cut by the top and right edges,
    80 %): at the preset's defaults the outline is the plain warp's, the canvas covers what it
    covers, and every component is no worse than under it by the report's two figures
    (``benchmarks/photo_acceptance.py`` checks all presets and the keypoints too).

    The pagoda's arc is solved on a 5 px grid (about half the time of the automatic 4 px one,
    the slowest two cases here): the same route, its two components both, the fold guard's
    path from W ending in two release rounds, then component 1 moved back towards W
    (``degraded_components``)."""
    mask = sample(f"{name}_mask.png") >= 128
    h, w = mask.shape
    cell = 5.0 if (name, preset) == ("china", "arc") else None
    record = FeatureWarper(w, h, mask, cell=cell).solve(load_warp(preset)(w, h), mode).record
    if cell:
        guard = record.guard
        assert len(record.components) == 2 and guard.path_steps > 0 and guard.release_rounds == 2, guard
        assert guard.degraded_components == [1] and guard.plain_blend < 1, guard
    assert record.outline_departure <= 1.0 and record.blank_share <= record.plain_blank_share + 0.005
    for component in record.components:
        assert component.distortion <= component.plain_distortion + 1e-6, component
        assert component.anisotropy_worst <= component.plain_anisotropy_worst + 1e-6, component


@pytest.mark.parametrize("mode", ["similarity", "rigid"])
def test_the_middle_of_a_frame_cut_feature_is_no_worse_than_plain(mode):
    """The dahlia (cut by two edges the cylinder curves) came out as one affine map of
    distortion 0.083 all over, better than plain's 0.102 over the whole flower but not in its
    middle (plain: 0.044 over the nodes within half its radius), where the keypoints of its
    textured heart said 0.08-0.09 against 0.04. The middle's fit is now no worse either."""
    from featurewarp_cli.engine import quality

    mask = sample("dahlia_mask.png") >= 128
    h, w = mask.shape
    middle = {}
    for which in ("plain", mode):
        mesh = FeatureWarper(w, h, mask).solve(load_warp("cylinder")(w, h), which)
        on = np.flatnonzero(mesh.node_component == 0)
        reach = np.hypot(*(mesh.source[on] - mesh.source[on].mean(axis=0)).T)
        core = on[reach <= 0.5 * reach.max()]
        fit = quality.affine_fits(mesh.source[core], mesh.target[core], np.zeros(core.size, int), 1)
        middle[which] = float(quality.map_anisotropy(fit)[0])
    assert middle[mode] <= middle["plain"] + 1e-6, middle

"""The path of barrier minima from W (engine/path.py): where the guard's window cannot open the
folds, the barrier starts from a point that is a continuous function of the inputs (issue 21)."""

from pathlib import Path

import cv2
import numpy as np
import pytest

from featurewarp_cli import FeatureWarper, load_warp
from featurewarp_cli.engine import barrier, guard, path
from featurewarp_cli.engine.grid import signed_areas

SAMPLES = Path(__file__).resolve().parent.parent / "samples"
PERSPECTIVE = {"tl": "20%,5%", "tr": "85%,0%", "br": "100%,100%", "bl": "0%,90%"}


def _solve(preset, params, mode, mask_name, warp_wrapper=lambda warp: warp, size=256):
    mask = cv2.resize(cv2.imread(str(SAMPLES / mask_name), cv2.IMREAD_GRAYSCALE), (size, size),
                      interpolation=cv2.INTER_NEAREST) >= 128
    warp = load_warp(preset)(size, size, **params)
    return FeatureWarper(size, size, mask).solve(warp_wrapper(warp), mode), warp


def _path_only(monkeypatch):
    """Switch the guard's window off (:func:`guard._open_window`), so that the path from W opens
    the folds: these cases' windows open them since 2026-11-28 (until then the windows'
    untangling could not, and the path ran)."""
    monkeypatch.setattr(guard, "_open_window", lambda problem, x, floor, record: (None, 0, 0))


_PATH_ONLY_MESHES = {}


def _path_only_solve(monkeypatch, preset, params, mode, mask_name):
    """:func:`_solve` with the window off (:func:`_path_only`), the window left off; each case
    solved once for the tests of this module (1-3 s a case), the mesh only read."""
    _path_only(monkeypatch)
    key = (preset, repr(params), mode, mask_name)
    if key not in _PATH_ONLY_MESHES:
        _PATH_ONLY_MESHES[key] = _solve(preset, params, mode, mask_name)[0]
    return _PATH_ONLY_MESHES[key]


def test_the_path_starts_at_w_itself_and_ends_at_a_minimum_that_keeps_the_features(monkeypatch):
    """The astronaut under the gallery's rigid perspective at 256 px, the window off: the path's
    right-hand side ``L W`` gives W itself at s = 0; it reaches s = 1 with every feature kept,
    no fold, every triangle above BLOCKED_SHARE of its floor, converged: the minimum the window
    reaches (1.8e-7 px apart), in 13 steps against the window's 38 Newton steps."""
    windowed, _ = _solve("perspective", PERSPECTIVE, "rigid", "astronaut_mask.png")
    assert windowed.record.guard.window_quads > 0 and not windowed.record.guard.path_steps
    _path_only(monkeypatch)
    starts = []
    follow = path.path_from_warp

    def recorded(problem, floor, record):
        rhs = path._stacked(problem.normal, problem.warped)
        starts.append(np.abs(problem.systems.solve(rhs, problem.warped) - problem.warped).max())
        return follow(problem, floor, record)
    monkeypatch.setattr(guard, "path_from_warp", recorded)
    mesh, warp = _solve("perspective", PERSPECTIVE, "rigid", "astronaut_mask.png")
    record = mesh.record.guard
    assert starts and max(starts) < 1e-9
    assert record.path_steps > 1 and record.release_rounds == 0 and record.converged and mesh.flips() == 0
    floor = barrier.SAFE_FRACTION * signed_areas(warp(mesh.source), mesh.triangles)
    assert (signed_areas(mesh.target, mesh.triangles) / floor).min() >= path.BLOCKED_SHARE
    assert np.abs(mesh.target - windowed.target).max() < 1e-5


@pytest.mark.parametrize("preset, params, mode, mask_name, released", [
    ("perspective", PERSPECTIVE, "rigid", "astronaut_mask.png", False),
    ("stretch", {"sx": 0.6}, "rigid", "astronaut_body_mask.png", True),    # blocked: the body cannot fit
])
def test_one_ulp_of_w_moves_a_result_of_the_path_by_rounding_only(monkeypatch, preset, params, mode, mask_name,
                                                                  released):
    """Kept or blocked (the rigid body pressed to 0.6 of the width crushes the ground before s = 1;
    the features near where it stopped are released), a one-ulp nudge of W in two patterns moves
    the mesh by rounding only: the path's steps are roots and converged minima, not counts (the
    window off: :func:`_path_only`)."""
    from benchmarks.stability import Nudged

    mesh = _path_only_solve(monkeypatch, preset, params, mode, mask_name)
    assert mesh.record.guard.path_steps > 0 and bool(mesh.record.guard.release_rounds) == released
    assert mesh.record.guard.converged            # a blocked path's loose runs are not the result's
    for pattern in ("up", "alternate"):
        nudged, _ = _solve(preset, params, mode, mask_name, lambda warp: Nudged(warp, pattern))
        assert np.abs(nudged.target - mesh.target).max() < 1e-6, pattern


@pytest.mark.parametrize("preset, params, mode, mask_name, released", [
    ("perspective", PERSPECTIVE, "rigid", "astronaut_mask.png", False),
    ("stretch", {"sx": 0.6}, "rigid", "astronaut_body_mask.png", True),    # blocked: the same release
])
def test_the_predictor_takes_the_curvature_the_last_step_predicts_and_ends_at_the_same_minimum(
        monkeypatch, preset, params, mode, mask_name, released):
    """The predictor's barrier curvature is taken where the last step's tangent takes each triangle
    (:func:`path._resisting`: never above its own ratio, never below CRUSHED_SHARE): a triangle
    a crease is about to crush resists in the prediction, so fewer steps end on the next cell
    of the front. At 256 px, the astronaut under the gallery's rigid perspective (kept: 25 ->
    13 steps) and her body pressed to 0.6 of the width (blocked: 30 -> 21), the window off
    (:func:`_path_only`): fewer steps than with the triangles' own ratios, the same decision and
    the same result."""
    from featurewarp_cli.engine import injectivity

    current, floor = np.array([3.0, 1.0, 0.8, 0.6]), np.ones(4)
    ahead = np.array([0.5, -2.0, 0.9, 0.7])
    ratio = path._resisting(current, ahead, floor)
    assert np.array_equal(path._resisting(current, None, floor), current)
    assert np.all(ratio <= current) and np.all(ratio >= np.minimum(current, injectivity.CRUSHED_SHARE))
    assert ratio.tolist() == [0.5, injectivity.CRUSHED_SHARE, 0.8, 0.6]

    looked = _path_only_solve(monkeypatch, preset, params, mode, mask_name)
    monkeypatch.setattr(path, "_resisting", lambda current, ahead, floor: current / floor)
    own, _ = _solve(preset, params, mode, mask_name)
    assert 0 < looked.record.guard.path_steps < own.record.guard.path_steps
    assert looked.record.guard.release_rounds == own.record.guard.release_rounds
    assert bool(looked.record.guard.release_rounds) == released
    assert np.abs(looked.target - own.target).max() < 1e-6

"""The fold-over guard's windows (engine/window.py): runs converged to the path's tolerance where
the whole grid is converged after them, decided on minima all the same (issue 21)."""

from pathlib import Path

import cv2
import numpy as np
import pytest

from featurewarp_cli import FeatureWarper, load_warp
from featurewarp_cli.engine import barrier, window
from featurewarp_cli.engine.grid import signed_areas
from featurewarp_cli.engine.path import PATH_TOLERANCE

SAMPLES = Path(__file__).resolve().parent.parent / "samples"
#: Presets whose least-squares solution folds by the 256 px astronaut's features, each opening
#: its folds in a window: the first run's point keeps every triangle at the share (squeeze), has
#: one in the continued part (swirl 180), or folds and goes on to a stiffer share (fish).
CASES = (("squeeze", {}), ("swirl", {"angle": 180}), ("fish", {}))


def _solve(preset: str, params: dict):
    mask = cv2.imread(str(SAMPLES / "astronaut_mask.png"), cv2.IMREAD_GRAYSCALE)
    mask = cv2.resize(mask, (256, 256), interpolation=cv2.INTER_NEAREST) >= 128
    return FeatureWarper(256, 256, mask).solve(load_warp(preset)(256, 256, **params), "similarity")


@pytest.fixture
def window_runs(monkeypatch):
    """The window's runs of the continued barrier, in order: (tolerance, below, the thinnest
    triangle's share of its floor at the run's end, converged)."""
    runs, converge = [], barrier.converge

    def recorded(*args, **kwargs):
        x, how = converge(*args, **kwargs)
        if kwargs.get("below"):
            runs.append((kwargs["tolerance"], kwargs["below"], float((signed_areas(x, args[4]) / args[5]).min()),
                         how.converged))
        return x, how
    monkeypatch.setattr(barrier, "converge", recorded)
    return runs


def test_a_loose_point_below_the_share_is_converged_on_before_it_is_judged(window_runs):
    """A run stops at the path's tolerance only where its point keeps every triangle at the
    continuation's share or above (there the barrier's own energy is the same, and the whole grid
    is converged from it); a point with a triangle below it, folded or not, is converged on to
    the barrier's tolerance from there before the guard decides whether the window opened the
    folds and whether to converge the barrier's own minimum."""
    branches = set()
    for preset, params in CASES:
        window_runs.clear()
        mesh = _solve(preset, params)
        assert mesh.record.guard.window_quads > 0 and mesh.record.guard.path_steps == 0
        for k, (tolerance, below, thinnest, converged) in enumerate(window_runs):
            if tolerance != PATH_TOLERANCE:
                continue
            assert converged
            following = window_runs[k + 1][:2] if k + 1 < len(window_runs) else None
            if thinnest < below:
                assert following == (barrier.TOLERANCE, below), (preset, window_runs)
                branches.add("folded" if thinnest <= 0 else "continued part")
            else:                                       # kept loose: no run to 1e-12 at its share
                assert following != (barrier.TOLERANCE, below), (preset, window_runs)
                branches.add("kept")
    assert branches == {"folded", "continued part", "kept"}


def test_the_loose_runs_reach_the_same_minima_in_fewer_newton_steps(monkeypatch):
    """Windows converged to the barrier's tolerance (until the evening of 2026-11-28) and to the path's give
    the same routes and, the whole grid converged after them, the same meshes, in fewer Newton
    steps in all."""
    loose = {name: _solve(name, params) for name, params in CASES}
    monkeypatch.setattr(window, "PATH_TOLERANCE", barrier.TOLERANCE)
    tight = {name: _solve(name, params) for name, params in CASES}
    for name in loose:
        a, b = loose[name].record.guard, tight[name].record.guard
        assert (a.window_quads, a.path_steps, a.release_rounds) == (b.window_quads, b.path_steps, b.release_rounds)
        assert a.converged and b.converged
        assert np.abs(loose[name].target - tight[name].target).max() < 1e-6
        assert a.newton_steps <= b.newton_steps
    assert sum(m.record.guard.newton_steps for m in loose.values()) < sum(
        m.record.guard.newton_steps for m in tight.values())


def test_a_triangle_crushed_to_nothing_but_not_folded_is_opened_as_a_fold_is():
    """At bend 13.771263431715989 the fish's least-squares solution crushes a triangle of the
    256 px astronaut to 4e-12 of its floor without folding it (a step further, it folds). The
    barrier is too steep to start from there: its Newton steps stopped, the triangle left at that
    area, not converged, and one ulp of W moved the mesh 1.5 px. A triangle below the
    continuation's share now sends the solution to the window's continued energy, as a fold
    does: converged, every triangle at 0.87 of its floor or more, one ulp moving it by rounding."""
    from benchmarks.stability import Nudged

    bend = 13.771263431715989
    mask = cv2.imread(str(SAMPLES / "astronaut_mask.png"), cv2.IMREAD_GRAYSCALE)
    mask = cv2.resize(mask, (256, 256), interpolation=cv2.INTER_NEAREST) >= 128
    warp = load_warp("fish")(256, 256, bend=bend)
    base = FeatureWarper(256, 256, mask).solve(warp, "similarity")
    floor = barrier.SAFE_FRACTION * signed_areas(warp(base.source), base.triangles)
    guard = base.record.guard
    assert guard.flipped_before == 0 and guard.window_quads > 0 and guard.converged
    assert (signed_areas(base.target, base.triangles) / floor).min() > 0.8
    for pattern in ("up", "alternate"):
        nudged = FeatureWarper(256, 256, mask).solve(Nudged(warp, pattern), "similarity")
        assert np.abs(nudged.target - base.target).max() < 1e-6, pattern


def test_a_guard_that_stops_before_its_energy_converged_says_so(monkeypatch):
    """Fold-free all the same, but not the energy's minimum: a warning, and the report's flag."""
    assert not any("stopped before its energy converged" in w for w in _solve("swirl", {"angle": 180}).record.warnings)
    monkeypatch.setattr(barrier, "MAX_STEPS", 3)
    mesh = _solve("swirl", {"angle": 180})
    assert mesh.flips() == 0 and not mesh.record.guard.converged
    assert any("the fold guard stopped before its energy converged" in w for w in mesh.record.warnings)
    assert mesh.record.to_dict()["barrier_converged"] is False          # the report's fold_guard.barrier.converged


def test_the_guards_back_substitutions_are_its_seconds_as_the_progress_line_shows(monkeypatch):
    """The report's ``solve`` stops growing when the guard begins: its back-substitutions (the
    Newton steps' solves) are ``guard``, the stage the progress line shows throughout; only the
    factorizations a release asks for are ``factor`` (engine/attempts.py)."""
    from featurewarp_cli.engine import attempts, guard

    seen, run = {}, guard.guard

    def recorded(problem, *args, **kwargs):
        seen.setdefault("solve", problem.timings.get("solve", 0.0))
        return run(problem, *args, **kwargs)
    monkeypatch.setattr(guard, "guard", recorded)
    mesh = _solve("swirl", {"angle": 180})
    assert mesh.record.guard.newton_steps > 0 and mesh.record.timings["guard"] > 0
    assert mesh.record.timings["solve"] == seen["solve"]
    timings = {"solve": 5.0, "factor": 1.0, "rhs": 0.5, "guard": 0.25}
    attempts._guard_seconds(timings, {"solve": 2.0, "factor": 0.5, "rhs": 0.25}, 10.0)
    assert timings == {"solve": 2.0, "factor": 1.0, "rhs": 0.25, "guard": 9.75}

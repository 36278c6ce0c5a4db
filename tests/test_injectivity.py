"""No fold-overs: the final grid has no triangle of non-positive area anywhere in the presets' ranges."""

from pathlib import Path

import numpy as np
import pytest

from featurewarp_cli.engine import injectivity
from featurewarp_cli.engine.warper import FeatureWarper, load_warp
from featurewarp_cli.engine.grid import Grid, signed_areas

W, H = 160, 120

SWEEP = [
    ("swirl", {"angle": a}) for a in (-360, -180, 90, 180, 360)
] + [
    ("arc", {"angle": a}) for a in (10, 120, 250, 360)
] + [
    ("bulge", {"strength": s}) for s in (-0.95, -0.5, 1.5, 2.95)
] + [
    ("stretch", p) for p in ({"sx": 0.2}, {"sy": 5}, {"sx": 0.2, "sy": 5}, {"sx": 5, "sy": 0.2}, {"sx": 3, "sy": 3})
]


def blobs(scale=1.0):
    """Discs and a square, one near the centre, one cut by the border (of a W x H image; at
    ``scale``, of a scale * W x scale * H one, every figure scaled with it)."""
    y, x = np.mgrid[0:round(H * scale), 0:round(W * scale)] / scale
    mask = (x - 80) ** 2 + (y - 60) ** 2 < 18**2
    mask |= (x - 35) ** 2 + (y - 35) ** 2 < 14**2
    mask |= (abs(x - 125) < 15) & (abs(y - 80) < 15)
    mask |= (x - 80) ** 2 + (y - 118) ** 2 < 12**2          # cut by the bottom border
    return mask


#: The sweep with features runs at 3/4 size (120 x 90, the blobs scaled): half the time of W x
#: H, most of it in the guard's path from W. The bare grid is swept at W x H (0.4 s in all).
SWEEP_SCALE = 0.75
MASKS = {"none": (None, 1.0), "blobs": (blobs(SWEEP_SCALE), SWEEP_SCALE)}


#: (mask, w_F): w_F does not matter without features, so the bare grid is swept once.
SWEEP_SETTINGS = [("none", 10.0), ("blobs", 10.0), ("blobs", 100.0)]

#: Which cases of SWEEP fold before the guard (``F``: the least-squares solution has a folded
#: triangle, so the guard must find another; ``.``: it has none), similarity then rigid. At
#: 120 x 90 every case that folds at 160 x 120 folds, and two more: bulge 2.95 rigid at w_F 10
#: and bulge -0.95 similarity at w_F 100 (``.`` at 160 x 120).
FOLDS = {
    ("none", 10.0): ".. " * len(SWEEP),
    ("blobs", 10.0): "FF FF FF FF FF .. FF FF FF .. .. .. FF .F .. FF FF ..",
    ("blobs", 100.0): "FF FF FF FF FF .. FF FF FF F. .. F. FF .F .. FF FF ..",
}


@pytest.mark.parametrize("preset,params", SWEEP, ids=[f"{p}-{v}" for p, v in SWEEP])
@pytest.mark.parametrize("mask_name,feature_weight", SWEEP_SETTINGS, ids=[f"{m}-wF{w:g}" for m, w in SWEEP_SETTINGS])
def test_sweep_has_no_fold_overs(preset, params, mask_name, feature_weight):
    """Every preset over its declared range, with and without features, at w_F 10 and 100; with
    features at 120 x 90 (SWEEP_SCALE), where the guard has folds to undo in every case it has
    at 160 x 120 (FOLDS)."""
    mask, scale = MASKS[mask_name]
    width, height = round(W * scale), round(H * scale)
    folds = FOLDS[mask_name, feature_weight].split()[SWEEP.index((preset, params))]
    warper = FeatureWarper(width, height, mask, feature_weight=feature_weight)
    for mode, folded in zip(("similarity", "rigid"), folds):
        mesh = warper.solve(load_warp(preset)(width, height, **params), mode)
        assert (mesh.info["flipped_before_guard"] > 0) == (folded == "F"), (mode, mesh.info["flipped_before_guard"])
        assert mesh.flips() == 0, mesh.info
        assert np.isfinite(mesh.target).all()


@pytest.mark.parametrize("angle", [-540, 540])
def test_extreme_swirl_plain_grid_does_not_fold(angle):
    """Swirl +-540 without features: the automatic grid is fine enough that W itself does not fold."""
    mesh = FeatureWarper(W, H, None).solve(load_warp("swirl")(W, H, angle=angle), "plain")
    assert mesh.flips() == 0


@pytest.mark.slow
def test_extreme_swirl_with_features_does_not_fold(monkeypatch):
    """Swirl 540 with features (the slowest case: sub-pixel grid, features relaxed towards W):
    the path from W runs out of steps with no triangle below its blocked share, so the guard
    releases every feature at once (``release_rounds`` 2, round 1 skipped), and the result has
    no fold.

    The path's step limit is 1 here: at the default (``path.MAX_STEPS``, 200) the path takes
    all 200 steps without reaching s = 1 and the guard releases the same four features, in
    40 s; its first step is the same step, so the route (steps run out, the release, no
    fold) is the same (at 1, 2, 3 and 5 steps: 11829 folds before the guard, release_rounds 2,
    components 0-3 released, no fold); most of the time is the release's."""
    from featurewarp_cli.engine import path

    monkeypatch.setattr(path, "MAX_STEPS", 1)
    mesh = FeatureWarper(W, H, blobs()).solve(load_warp("swirl")(W, H, angle=540))
    guard = mesh.record.guard
    assert mesh.info["flipped_before_guard"] > 0
    assert guard.path_steps == path.MAX_STEPS and guard.release_rounds == 2
    assert sorted(guard.released_components) == [0, 1, 2, 3]          # all four features
    assert mesh.flips() == 0


def test_guard_leaves_features_exact_when_folds_are_local():
    """Swirl 180 folds the background near the centre; untangling keeps every feature a similarity."""
    y, x = np.mgrid[0:360, 0:500]
    mask = np.zeros((360, 500), bool)
    for cx, cy in ((110, 100), (250, 100), (390, 100), (110, 260), (250, 260), (390, 260)):
        mask |= (x - cx) ** 2 + (y - cy) ** 2 < 36**2
    warper = FeatureWarper(500, 360, mask)
    mesh = warper.solve(load_warp("swirl")(500, 360, angle=180))
    assert mesh.info["flipped_before_guard"] > 0
    assert mesh.flips() == 0
    assert max(c["residual_percent"] for c in mesh.info["quality"]["components"]) < 0.5


def test_local_folds_are_opened_in_a_window_that_starts_the_whole_grids_minimum(monkeypatch):
    """Folds next to one feature are opened in a window (a fraction of the grid); its result
    holds everything outside at the least-squares solution, so it only starts the whole grid's
    convergence: the result is the barrier energy's minimum on the whole grid (converging it
    again moves nothing; from the window's result it moved 3-27 px on the 1 and 12 MP
    astronaut), and the features stay exact."""
    from featurewarp_cli.engine import barrier, guard

    y, x = np.mgrid[0:360, 0:500]
    mask = ((x - 250) ** 2 + (y - 90) ** 2 < 60**2) | ((x - 120) ** 2 + (y - 280) ** 2 < 30**2)
    warp = load_warp("swirl")(500, 360, angle=150)
    raw = FeatureWarper(500, 360, mask, injective=False).solve(warp)
    seen = []
    guard_of = guard.guard
    monkeypatch.setattr(guard, "guard", lambda problem, x, record, *hook: seen.append(problem) or guard_of(problem, x, record, *hook))
    mesh = FeatureWarper(500, 360, mask).solve(warp)
    assert raw.flips() > 0 and mesh.flips() == 0
    assert 0 < mesh.info["untangle_window_quads"] < 0.2 * mesh.info["grid"]["quads"]
    assert mesh.record.guard.converged and mesh.record.guard.plain_blend == 1.0
    assert len(seen) == 1
    problem = seen[0]
    floor = barrier.SAFE_FRACTION * signed_areas(problem.warped, problem.triangles)
    again, _ = guard._converge_grid(problem, problem.systems, problem.rhs, problem.offset, problem.tied,
                                    mesh.target, floor, guard.GuardRecord())
    assert np.abs(again - mesh.target).max() < 1e-6
    assert max(c["residual_percent"] for c in mesh.info["quality"]["components"]) < 0.5


@pytest.mark.parametrize("preset", ["fish", "rise"])
def test_a_window_takes_in_the_ground_around_a_tied_feature_it_reaches(preset):
    """The astronaut's head, patch and shuttle at 256 px: the folds lie between her head (cut
    by the top edge) and the edge. A window that let the head move as a whole but held the
    ground beyond it could not open them, and her features were released (blend towards W);
    with that ground in the window, a window opens them and every feature keeps its shape."""
    import cv2

    samples = Path(__file__).resolve().parent.parent / "samples"
    mask = cv2.resize(cv2.imread(str(samples / "astronaut_mask.png"), cv2.IMREAD_GRAYSCALE), (256, 256),
                      interpolation=cv2.INTER_NEAREST) >= 128
    mesh = FeatureWarper(256, 256, mask).solve(load_warp(preset)(256, 256), "similarity")
    guard = mesh.record.guard
    assert guard.flipped_before > 0 and mesh.flips() == 0
    assert guard.window_quads > 0 and guard.release_rounds == 0 and guard.converged
    assert max(c.anisotropy_worst for c in mesh.record.components) < 1e-6


def test_window_inner_nodes_change_only_window_triangles():
    """Moving a window's inner nodes changes no triangle outside the window."""
    grid = Grid.for_image(60, 40, 2)
    quads = np.zeros(grid.quad_shape, bool)
    quads[5, 7] = quads[14, 22] = True
    window, nodes, inner = injectivity.window(grid, quads.ravel(), 3)
    assert window.reshape(grid.quad_shape)[2:9, 4:11].all() and window.sum() == 2 * 49
    assert not (inner & grid.boundary()).any() and (nodes >= inner).all()
    moved = grid.nodes().copy()
    moved[inner] += np.random.default_rng(0).normal(0, 0.5, (int(inner.sum()), 2))
    tris = grid.triangles()
    changed = signed_areas(moved, tris) != signed_areas(grid.nodes(), tris)
    assert not changed[np.r_[~window, ~window]].any()
    assert changed.any()


def test_extent_is_the_largest_groups_longest_side():
    grid = Grid.for_image(100, 100, 2)
    quads = np.zeros(grid.quad_shape, bool)
    quads[3:6, 10:30] = True          # 20 wide
    quads[40:52, 40:43] = True        # 12 tall
    assert injectivity.extent(grid, np.flatnonzero(quads)) == 20
    assert injectivity.extent(grid, np.zeros(0, int)) == 0


def test_without_guard_folds_remain():
    """The guard is what removes them (injective=False keeps the raw least-squares solution)."""
    y, x = np.mgrid[0:360, 0:500]
    mask = np.zeros((360, 500), bool)
    for cx, cy in ((250, 100), (250, 260)):
        mask |= (x - cx) ** 2 + (y - cy) ** 2 < 36**2
    mesh = FeatureWarper(500, 360, mask, injective=False).solve(load_warp("swirl")(500, 360, angle=360))
    assert mesh.flips() > 0


def test_max_step_stops_before_the_first_fold():
    """Along the segment, every triangle keeps positive area up to the returned step, not beyond."""
    grid = Grid.for_image(20, 20, 5)
    start = grid.nodes()
    end = start.copy()
    centre = np.flatnonzero(~grid.boundary())[0]
    end[centre] += [30.0, 30.0]                     # drags one node across its neighbours
    tris = grid.triangles()
    t = injectivity.max_step(start, end, tris)
    assert 0 < t < 1
    assert signed_areas(start + 0.999 * t * (end - start), tris).min() > 0
    assert signed_areas(start + min(1.0, 1.01 * t) * (end - start), tris).min() <= 0


def test_auto_cell_follows_the_warp():
    """The automatic grid stays within 0.5 px of the analytic warp and folds nothing of it."""
    for angle in (90, 360, 540):
        warper = FeatureWarper(W, H, None)
        mesh = warper.solve(load_warp("swirl")(W, H, angle=angle), "plain")
        assert mesh.info["grid"]["pl_error_px"] <= 0.5
        assert mesh.flips() == 0


def test_eased_stops_short_of_the_folds_and_keeps_the_end_away_from_them():
    """injectivity.eased: the end where it folds nothing; else fold-free, the nodes around the
    folds a share of the way, the nodes beyond the reach at the end."""
    grid = Grid.for_image(64, 64, 4)
    triangles = grid.triangles()
    start = grid.nodes()
    end = start * 1.5                                         # a similarity: no fold
    points, step = injectivity.eased(grid, start, end, triangles, 0.8, 4.0)
    np.testing.assert_array_equal(points, end)
    assert step == 1.0
    folded = end.copy()
    middle = (grid.ny // 2) * grid.nx + grid.nx // 2
    folded[middle] += (12.0, 12.0)                            # pushed across its neighbours
    assert (signed_areas(folded, triangles) <= 0).any()
    points, step = injectivity.eased(grid, start, folded, triangles, 0.8, 4.0)
    assert 0.0 < step < 1.0 and (signed_areas(points, triangles) > 0).all()
    far = np.hypot(*(start - start[middle]).T) > 8 * 4.0     # beyond the reach (4 cells) of the fold
    np.testing.assert_array_equal(points[far], folded[far])

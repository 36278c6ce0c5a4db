"""The rigid map of handles (issue 23 item 1): as rigid as libigl's ARAP (run to convergence:
500 iterations suffice on this grid, the benchmark runs 2 000) where that folds nothing, never
folded, similarities exact, the same map for a one-ulp nudge."""

import json
from pathlib import Path

import cv2
import numpy as np
import pytest

from benchmarks.rigidity import cases, compare
from featurewarp_cli.engine.arap import RigidDeformer, rest_scale
from featurewarp_cli.engine.deform import RigidMap, solve_grid
from featurewarp_cli.engine.grid import Grid, signed_areas
from featurewarp_cli.engine.handles import Handles

W, H = 192, 144
SAMPLES = Path(__file__).resolve().parent.parent / "samples"
MASK = cv2.resize(cv2.imread(str(SAMPLES / "astronaut_mask.png"), cv2.IMREAD_GRAYSCALE), (W, H),
                  interpolation=cv2.INTER_NEAREST) > 127
CASES = cases(W, H)


@pytest.mark.parametrize("name", sorted(CASES))
def test_as_rigid_as_libigl_where_it_folds_nothing_and_never_folded(name):
    pytest.importorskip("igl", reason="libigl is a test dependency (pip install -e '.[test]')")
    handles, with_mask = CASES[name]
    result = compare(handles, W, H, MASK if with_mask else None, iterations=500)
    ours, theirs = result["ours"], result["libigl"]
    assert ours["folds"] == 0 and ours["converged"]
    if theirs["folds"] == 0:
        assert ours["rigidity"] <= 1.2 * theirs["rigidity"] + 1e-6
        assert abs(ours["area_ratio"] / theirs["area_ratio"] - 1) <= 0.05
    if name == "squash, sides held":           # half width asks 0.5; a rest size below 1 bit into it
        assert ours["area_ratio"] >= 0.475


def test_handles_that_describe_a_similarity_give_it_exactly():
    grid = Grid.for_image(W, H, 8)
    sources = np.array([[20.0, 30.0], [170.0, 25.0], [90.0, 120.0], [150.0, 130.0]])
    turn = 0.7 * np.array([[np.cos(0.4), -np.sin(0.4)], [np.sin(0.4), np.cos(0.4)]])
    targets = sources @ turn.T + [15.0, -8.0]
    assert rest_scale(sources, targets) == pytest.approx(0.7)
    nodes = RigidDeformer(grid, sources, radius=6).deform(targets)
    assert np.abs(nodes - (grid.nodes() @ turn.T + [15.0, -8.0])).max() < 1e-3


def test_a_squash_does_not_shrink_the_direction_it_leaves_alone():
    sources = np.array([[0.0, 0.0], [0.0, 100.0], [200.0, 0.0], [200.0, 100.0]])
    assert rest_scale(sources, sources * [0.5, 1.0]) == 1.0


def test_a_one_ulp_nudge_of_the_targets_moves_no_node_more_than_a_hundredth_of_a_pixel():
    for name in ("bend (curve)", "drag onto a feature", "squash, point handles"):
        handles, with_mask = CASES[name]
        maps = []
        for nudge in (False, True):
            data = json.loads(json.dumps({"version": 1, "canvas": "input", **handles}))

            def up(p):
                return [float(np.nextafter(v, np.inf)) for v in p] if nudge else p

            for point in data.get("points", []):
                point["to"] = up(point["to"])
            for curve in data.get("curves", []):
                curve["to"] = [up(p) for p in curve["to"]]
            assert nudge is False or data != {"version": 1, "canvas": "input", **handles}
            rigid = RigidMap(W, H, mask=MASK if with_mask else None)
            maps.append(rigid.deformation(Handles.from_dict(data, W, H)).nodes)
        assert np.abs(maps[0] - maps[1]).max() < 0.01, name


def test_the_solve_grid_nests_in_the_rigid_grid_so_w_folds_no_fine_triangle():
    handles, _ = CASES["drag onto a feature"]
    rigid = RigidMap(W, H, mask=MASK)
    warp = rigid.deformation(Handles.from_dict({"version": 1, "canvas": "input", **handles}, W, H))
    coarse = max(rigid.grid.spacing)
    for cell in (1.3, 1.7, 2.6, coarse, 3 * coarse):        # finer, non-integer ratios, as coarse, coarser
        fine = solve_grid(W, H, cell)
        k = (fine.nx - 1) // (rigid.grid.nx - 1)
        assert fine.nx - 1 == k * (rigid.grid.nx - 1) and fine.ny - 1 == k * (rigid.grid.ny - 1) and k >= 1
        assert k == max(1, round(coarse / cell))             # never coarser than the rigid grid
        assert np.all(signed_areas(warp(fine.nodes()), fine.triangles()) > 0)


def test_two_handles_are_a_similarity_reached_at_once():
    """Any two handles describe a similarity: the energy is 0 up to rounding, where only the
    step floor can say converged (the relative test ran to the step cap on noise)."""
    grid = Grid.for_image(W, H, 8)
    sources = np.array([[131.66, 98.17], [122.33, 57.80]])
    targets = np.array([[131.16, 131.76], [122.33, 57.80]])
    rigid = RigidDeformer(grid, sources, radius=6)
    rigid.deform(targets)
    assert rigid.converged and rigid.newton_steps <= 1

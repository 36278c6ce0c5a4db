"""Correctness of the fast paths: banded rendering, antialiasing, nested-dissection solve."""

from __future__ import annotations

import cv2
import numpy as np
import pytest
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from featurewarp_cli.engine import cholmod
from featurewarp_cli.engine import features as feat
from featurewarp_cli.render import raster as render
from featurewarp_cli.engine import ordering, solver
from featurewarp_cli.engine import system
from featurewarp_cli.engine.warper import load_warp
from featurewarp_cli.engine.grid import Grid


def mesh_for(width, height, preset, cell=4, **params):
    grid = Grid.for_image(width, height, cell)
    warp = load_warp(preset)(width, height, **params)
    source = grid.nodes()
    return source, warp(source), grid.triangles(), tuple(warp.canvas)


def photo(width, height, seed=0):
    rng = np.random.default_rng(seed)
    base = cv2.resize(rng.integers(0, 256, (height // 8 + 1, width // 8 + 1, 3), dtype=np.uint8),
                      (width, height), interpolation=cv2.INTER_CUBIC)
    noise = rng.integers(0, 40, (height, width, 3), dtype=np.uint8)
    return cv2.add(base, noise)


# --------------------------------------------------------------------------- banded rendering

@pytest.mark.parametrize("preset, params", [("swirl", {"angle": 180}), ("arc", {"angle": 120}),
                                            ("stretch", {"sx": 0.5, "sy": 1.3}), ("bulge", {"strength": -0.6})])
@pytest.mark.parametrize("antialias", [False, True])
def test_banded_rendering_equals_one_band(preset, params, antialias):
    image = photo(120, 90)
    mesh = mesh_for(120, 90, preset, **params)
    whole = render.render(image, *mesh, "cubic", None, antialias=antialias, band_pixels=10**9, threads=1)
    for band_pixels, threads in ((97, 1), (1000, 2), (4096, 3)):
        banded = render.render(image, *mesh, "cubic", None, antialias=antialias,
                               band_pixels=band_pixels, threads=threads)
        np.testing.assert_array_equal(banded, whole)


@pytest.mark.parametrize("background", [None, (10, 200, 30)])
@pytest.mark.parametrize("preset, params", [("swirl", {"angle": 120}), ("arc", {"angle": 200})])
def test_render_without_antialiasing_equals_inverse_map_then_resample(preset, params, background):
    image = photo(100, 80)
    source, target, triangles, canvas = mesh_for(100, 80, preset, **params)
    expected = render.resample(image, *render.inverse_map(source, target, triangles, canvas), "cubic", background)
    out = render.render(image, source, target, triangles, canvas, "cubic", background, antialias=False)
    np.testing.assert_array_equal(out, expected)


def test_shared_edges_leave_no_cracks():
    """A perturbed grid covering the whole canvas covers every pixel."""
    rng = np.random.default_rng(3)
    grid = Grid.for_image(90, 70, 5)
    source = grid.nodes()
    target = source + np.where(grid.boundary()[:, None], 0.0, rng.uniform(-1.5, 1.5, source.shape))
    _, covered = render.inverse_map(source, target, grid.triangles(), (90, 70))
    assert covered.all()


# --------------------------------------------------------------------------- antialiasing

def test_warps_that_do_not_shrink_are_not_filtered():
    image = photo(100, 80)
    mesh = mesh_for(100, 80, "stretch", sx=2.0, sy=1.5)
    np.testing.assert_array_equal(render.render(image, *mesh), render.render(image, *mesh, antialias=False))


def high_frequency_energy(image: np.ndarray) -> float:
    """Energy above a quarter of the sampling rate in x (where a 2x shrink folds detail)."""
    gray = image.astype(np.float64).mean(axis=2) if image.ndim == 3 else image.astype(np.float64)
    gray = gray[4:-4, 4:-4]
    spectrum = np.abs(np.fft.rfft(gray - gray.mean(axis=1, keepdims=True), axis=1)) ** 2
    return float(spectrum[:, 1:].sum())


@pytest.mark.parametrize("sx", [0.5, 0.45])
def test_fine_checkerboard_shrunk_has_no_moire(sx):
    ys, xs = np.mgrid[0:120, 0:240]
    board = ((xs + ys) % 2 * 255).astype(np.uint8)
    image = cv2.merge([board, board, board])
    mesh = mesh_for(240, 120, "stretch", sx=sx, sy=1.0)
    naive = render.render(image, *mesh, antialias=False)
    smooth = render.render(image, *mesh)
    assert high_frequency_energy(smooth) < 0.05 * high_frequency_energy(naive) + 1e-6 or smooth.std() < 4
    assert abs(float(smooth.mean()) - 127.5) < 3


def test_grating_near_nyquist_shrunk_by_two_is_damped():
    """A 0.4 cycles/px grating would alias to 0.2 cycles/px in the output."""
    xs = np.arange(300)
    row = (127.5 + 100 * np.cos(2 * np.pi * 0.4 * xs)).astype(np.uint8)
    image = cv2.merge([np.tile(row, (60, 1))] * 3)
    mesh = mesh_for(300, 60, "stretch", sx=0.5, sy=1.0)
    naive = render.render(image, *mesh, antialias=False)[5:-5, 5:-5].astype(float)
    smooth = render.render(image, *mesh)[5:-5, 5:-5].astype(float)
    assert smooth.std() < 0.25 * naive.std()


def test_isotropic_shrink_keeps_a_ramp_in_place():
    """Pyramid levels are aligned: a linear ramp shrunk 4x is the ramp at the mapped positions."""
    xs = np.arange(400, dtype=np.float64)
    ramp = np.tile(xs * 0.5 + 20, (200, 1)).astype(np.uint8)
    image = cv2.merge([ramp] * 3)
    mesh = mesh_for(400, 200, "stretch", sx=0.25, sy=0.25)
    out = render.render(image, *mesh)[:, :, 0].astype(float)
    ox = np.arange(out.shape[1])
    expected = ((ox + 0.5) / 0.25 - 0.5) * 0.5 + 20
    inner = slice(3, -3)
    np.testing.assert_allclose(out[10:-10, inner].mean(axis=0), expected[inner], atol=1.0)


def test_arc_silhouette_gets_partial_alpha():
    image = np.full((60, 160, 3), 200, np.uint8)
    mesh = mesh_for(160, 60, "arc", angle=120)
    out = render.render(image, *mesh, "linear", None)
    assert out.shape[2] == 4
    alpha = out[:, :, 3]
    partial = (alpha > 0) & (alpha < 255)
    # Every row that the sector's straight edges cross has a partially covered pixel.
    rows_with_edge = np.flatnonzero((alpha == 255).any(axis=1) & (alpha == 0).any(axis=1))
    assert np.count_nonzero(partial.any(axis=1)[rows_with_edge]) >= 0.9 * rows_with_edge.size
    assert np.count_nonzero(partial) > 100
    # A binary staircase is what the old renderer gave; the feathered edge keeps the colour.
    assert np.all(out[partial][:, :3] == 200)
    naive = render.render(image, *mesh, "linear", None, antialias=False)
    assert set(np.unique(naive[:, :, 3])) <= {0, 255}
    # The total coverage is close to the binary one (the edge moves by less than a pixel).
    assert abs(alpha.astype(float).sum() - naive[:, :, 3].astype(float).sum()) < 0.02 * naive[:, :, 3].sum()


def test_silhouette_blends_with_a_background_colour():
    image = np.full((60, 160, 3), 200, np.uint8)
    mesh = mesh_for(160, 60, "arc", angle=120)
    out = render.render(image, *mesh, "linear", (0, 0, 0))
    assert out.shape[2] == 3
    values = np.unique(out[:, :, 0])
    assert values.min() == 0 and values.max() == 200
    assert np.count_nonzero((out[:, :, 0] > 0) & (out[:, :, 0] < 200)) > 100


def test_gray_and_sixteen_bit_images_render():
    gray = (photo(80, 60)[:, :, 0].astype(np.uint16) * 257)
    mesh = mesh_for(80, 60, "arc", angle=90)
    out = render.render(gray, *mesh, "cubic", None)
    assert out.dtype == np.uint16 and out.shape[2] == 4
    out = render.render(gray, *mesh_for(80, 60, "stretch", sx=0.5), "cubic", None)
    assert out.dtype == np.uint16 and out.ndim == 2


# --------------------------------------------------------------------------- solver ordering

@pytest.mark.parametrize("ny, nx", [(1, 1), (1, 9), (3, 7), (20, 13), (64, 64)])
@pytest.mark.parametrize("holes", [False, True])
@pytest.mark.parametrize("leaf", [0, 1, 4, 16])
def test_nested_dissection_is_a_permutation_of_the_live_nodes(ny, nx, holes, leaf):
    live = np.random.default_rng(ny * nx).random((ny, nx)) > 0.3 if holes else np.ones((ny, nx), bool)
    order = ordering.grid_nested_dissection(live, leaf=leaf)
    assert np.array_equal(np.sort(order), np.flatnonzero(live))


@pytest.mark.parametrize("ny, nx", [(2, 6), (3, 7), (20, 13), (64, 64), (30, 55)])
def test_nested_dissection_numbers_both_halves_then_a_diagonal_cut(ny, nx):
    order = ordering.grid_nested_dissection(np.ones((ny, nx), bool), leaf=4)
    # The last nodes are the top cut: every node of one diagonal (x + y or x - y
    # constant); before it all nodes of one side, then all of the other (never adjacent).
    y, x = np.divmod(order, nx)
    assert any(cut_last(coord) for coord in (x + y, x - y))


@pytest.mark.parametrize("ny, nx", [(5, 60), (60, 5), (1, 30)])
def test_nested_dissection_cuts_long_strips_straight_across_first(ny, nx):
    order = ordering.grid_nested_dissection(np.ones((ny, nx), bool), leaf=4)
    along = order % nx if nx > ny else order // nx          # position along the strip
    short, long = min(ny, nx), max(ny, nx)
    # Blocks at most about twice as long as wide, one after the other, then the
    # whole lines across the strip between them.
    n_cuts = -(-long // (2 * short + 2)) - 1
    cuts = np.unique(along[-n_cuts * short:])
    assert cuts.size == n_cuts and np.all(np.bincount(along[-n_cuts * short:])[cuts] == short)
    assert np.all(np.diff(np.searchsorted(cuts, along[:-n_cuts * short])) >= 0)
    assert np.diff(np.concatenate([[-1], cuts, [long]])).max() - 1 <= 2 * short + 2


def cut_last(coord):
    other = np.flatnonzero(coord[::-1] != coord[-1])
    size = other[0] if other.size else coord.size
    side = np.sign(coord[:-size] - coord[-1])
    return (np.count_nonzero(coord == coord[-1]) == size and side[0] == -side[-1] != 0
            and np.count_nonzero(np.diff(side)) == 1)


def test_nested_dissection_of_nothing_is_empty():
    assert ordering.grid_nested_dissection(np.zeros((5, 4), bool)).size == 0


def grid_system(width, height, cell, with_mask=True):
    grid = Grid.for_image(width, height, cell)
    mask = np.zeros((height, width), bool)
    if with_mask:
        yy, xx = np.mgrid[0:height, 0:width]
        mask |= (xx - width * 0.3) ** 2 + (yy - height * 0.4) ** 2 < (0.15 * width) ** 2
        mask |= (xx - width * 0.7) ** 2 + (yy - height * 0.6) ** 2 < (0.12 * width) ** 2
    features = feat.analyse(mask, grid, 10.0, 2.0)
    fixed = grid.boundary()
    tied = np.full(grid.n_nodes, -1)
    if features.n_components:
        own = features.is_feature
        tied[grid.quads()[own].ravel()] = np.repeat(features.component[own], 4)
        tied[np.isin(tied, np.unique(tied[fixed & (tied >= 0)]))] = -1
    free = ~fixed & (tied < 0)
    unknown = np.full(grid.n_nodes, -1)
    unknown[free] = np.arange(np.count_nonzero(free))
    _, inverse = np.unique(tied[tied >= 0], return_inverse=True)
    unknown[tied >= 0] = np.count_nonzero(free) + inverse
    return grid, system.normal_matrix(grid, features.weight), unknown


needs_cholmod = pytest.mark.skipif(not cholmod.AVAILABLE, reason="scikit-sparse is not installed")


def reference_solve(matrix, unknown, rhs, offset):
    rows = np.flatnonzero(unknown >= 0)
    p = sp.csr_matrix((np.ones(rows.size), (rows, unknown[rows])), shape=(unknown.size, unknown.max() + 1))
    reduced = (p.T @ matrix @ p).tocsc()
    z = spla.spsolve(reduced, p.T @ (rhs - matrix @ offset))
    return p @ z.reshape(-1, rhs.shape[1]) + offset


@pytest.mark.parametrize("with_mask", [False, True])
@pytest.mark.parametrize("columns", [1, 2])
def test_nested_dissection_solution_equals_the_reference(with_mask, columns):
    grid, matrix, unknown = grid_system(240, 160, 4, with_mask)
    rng = np.random.default_rng(1)
    rhs = rng.normal(size=(grid.n_nodes, columns))
    offset = np.where(unknown[:, None] < 0, rng.normal(size=(grid.n_nodes, columns)) * 50, 0.0)
    reduced = solver.ReducedSystem(matrix, unknown)
    assert reduced.ordering == "grid-nested-dissection"
    x = reduced.solve(rhs, offset)
    expected = reference_solve(matrix, unknown, rhs, offset)
    assert np.abs(x - expected).max() <= 1e-9 * np.abs(expected).max()


def test_a_matrix_that_is_not_a_grid_uses_the_default_ordering():
    rng = np.random.default_rng(2)
    a = sp.random(60, 60, density=0.1, random_state=3)
    matrix = (a @ a.T + sp.identity(60) * 5).tocsc()
    unknown = np.arange(60)
    unknown[:3] = -1
    unknown[3:] = np.arange(57)
    reduced = solver.ReducedSystem(matrix, unknown)
    assert reduced.ordering == "default"
    rhs, offset = rng.normal(size=(60, 2)), np.zeros((60, 2))
    offset[:3] = 1.0
    np.testing.assert_allclose(reduced.solve(rhs, offset), reference_solve(matrix, unknown, rhs, offset),
                               rtol=1e-9, atol=1e-9)


@needs_cholmod
def test_symbolic_analysis_is_reused_for_the_same_pattern():
    grid, matrix, unknown = grid_system(200, 120, 4)
    solver._symbolic_cache.clear()
    first = solver.ReducedSystem(matrix, unknown)
    kept = dict(solver._symbolic_cache)
    assert len(kept) == 2                        # the grid ordering and the symbolic analysis
    # Other weights, same pattern: the cached ordering and analysis serve the new factorization.
    heavier = system.normal_matrix(grid, np.linspace(1.0, 5.0, grid.quad_shape[0] * grid.quad_shape[1]))
    second = solver.ReducedSystem(heavier, unknown)
    assert solver._symbolic_cache.keys() == kept.keys()
    assert all(solver._symbolic_cache[k] is v for k, v in kept.items())
    rng = np.random.default_rng(4)
    rhs, offset = rng.normal(size=(grid.n_nodes, 2)), np.zeros((grid.n_nodes, 2))
    np.testing.assert_allclose(second.solve(rhs, offset), reference_solve(heavier, unknown, rhs, offset),
                               rtol=1e-9, atol=1e-9)
    assert not np.allclose(first.solve(rhs, offset), second.solve(rhs, offset))


def test_renumbered_unknowns_reuse_the_grid_ordering_and_solve_the_same():
    grid, matrix, unknown = grid_system(200, 120, 4)
    rng = np.random.default_rng(5)
    shuffled = unknown.copy()
    free = (unknown >= 0) & (np.bincount(unknown[unknown >= 0])[np.maximum(unknown, 0)] == 1)
    shuffled[free] = rng.permutation(unknown[free])
    rhs = rng.normal(size=(grid.n_nodes, 2))
    offset = np.where(unknown[:, None] < 0, rng.normal(size=(grid.n_nodes, 2)) * 20, 0.0)
    solver._symbolic_cache.clear()
    x = solver.ReducedSystem(matrix, unknown).solve(rhs, offset)
    orderings = [k for k in solver._symbolic_cache if k[0] == "nested-dissection"]
    y = solver.ReducedSystem(matrix, shuffled).solve(rhs, offset)
    assert [k for k in solver._symbolic_cache if k[0] == "nested-dissection"] == orderings
    np.testing.assert_allclose(y, x, rtol=1e-9, atol=1e-9)


@pytest.mark.parametrize("with_mask", [False, True])
@pytest.mark.parametrize("sliding", [False, True])
def test_the_linear_part_is_the_solve_with_a_zero_offset_bit_for_bit(with_mask, sliding):
    """``move(force)`` skips the product of the matrix and a zero offset: the same bits as
    ``solve(force, 0)``, for one shared system and for separate x and y systems, shared
    (tied) unknowns or none; exactly 0 on held nodes, one value per tied unknown."""
    grid, matrix, unknown = grid_system(240, 160, 4, with_mask)
    other = unknown.copy()
    if sliding:                                   # the top border slides in x: x has its own system
        top = np.zeros(grid.n_nodes, bool)
        top[1:grid.nx - 1] = True
        other[top] = unknown.max() + 1 + np.arange(np.count_nonzero(top))
    systems = solver.AxisSystems(matrix, other, unknown)
    assert systems.factorizations == 1 + sliding
    force = np.random.default_rng(3).normal(size=(grid.n_nodes, 2)) * 1e3
    moved = systems.move(force)
    assert np.array_equal(moved, systems.solve(force, np.zeros_like(force)))
    assert not np.shares_memory(moved, force)
    assert np.all(moved[other < 0, 0] == 0) and np.all(moved[unknown < 0, 1] == 0)
    for k, numbering in enumerate((other, unknown)):
        tied = numbering >= 0
        spread = np.full(numbering.max() + 1, -np.inf)
        np.maximum.at(spread, numbering[tied], moved[tied, k])
        assert np.array_equal(spread[numbering[tied]], moved[tied, k])   # one value per unknown


def test_systems_with_other_fixed_nodes_share_the_grid_ordering():
    grid, matrix, unknown = grid_system(200, 120, 4)
    top = np.zeros(grid.n_nodes, bool)
    top[1:grid.nx - 1] = True                     # the top border slides in x: its nodes are free
    sliding = unknown.copy()
    sliding[top] = unknown.max() + 1 + np.arange(np.count_nonzero(top))
    rng = np.random.default_rng(7)
    rhs = rng.normal(size=(grid.n_nodes, 1))
    offset = np.where(sliding[:, None] < 0, rng.normal(size=(grid.n_nodes, 1)) * 20, 0.0)
    solver._symbolic_cache.clear()
    for numbering in (unknown, sliding):
        expected = reference_solve(matrix, numbering, rhs, offset)
        x = solver.ReducedSystem(matrix, numbering).solve(rhs, offset)
        assert np.abs(x - expected).max() <= 1e-9 * np.abs(expected).max()
    assert len([k for k in solver._symbolic_cache if k[0] == "nested-dissection"]) == 1


@pytest.mark.parametrize("with_mask", [False, True])
def test_grid_ordering_solves_like_the_default_ordering(with_mask, monkeypatch):
    grid, matrix, unknown = grid_system(320, 200, 4, with_mask)
    rng = np.random.default_rng(6)
    rhs = rng.normal(size=(grid.n_nodes, 2))
    offset = np.where(unknown[:, None] < 0, rng.normal(size=(grid.n_nodes, 2)) * 50, 0.0)
    nested = solver.ReducedSystem(matrix, unknown)
    monkeypatch.setattr(solver, "_grid_width", lambda *args: None)
    default = solver.ReducedSystem(matrix, unknown)
    assert (nested.ordering, default.ordering) == ("grid-nested-dissection", "default")
    expected = default.solve(rhs, offset)
    assert np.abs(nested.solve(rhs, offset) - expected).max() <= 1e-9 * np.abs(expected).max()


@needs_cholmod
def test_grid_ordering_fills_about_as_little_as_cholmods_own(monkeypatch):
    """The diagonal dissection fills about as little as CHOLMOD's default ordering (AMD here)
    on a 200 x 150 grid (0.98 times its nnz(L); straight cuts had 1.4 times)."""
    grid, matrix, unknown = grid_system(800, 600, 4)
    lower = {}

    def capture(matrix, natural):
        lower[natural] = matrix
        return capture.__wrapped__(matrix, natural)

    capture.__wrapped__ = solver._cholmod_factor
    monkeypatch.setattr(solver, "_cholmod_factor", capture)
    solver.ReducedSystem(matrix, unknown)
    monkeypatch.setattr(solver, "_grid_width", lambda *args: None)
    solver.ReducedSystem(matrix, unknown)

    def fill(matrix, ordering):
        return cholmod.factor_nnz(cholmod.factorize(cholmod.analyze(matrix, ordering), matrix))

    assert fill(lower[True], "natural") <= 1.05 * fill(lower[False], "default")


@needs_cholmod
def test_other_masks_of_the_same_size_reuse_the_analysis_with_soft_features():
    """With the paper's soft feature constraints the pattern is the grid's, whatever the mask:
    a second image of the same size with another mask factors without a new analysis.
    (The exact formulation ties each feature's nodes to one unknown, so its pattern
    depends on the mask; it reuses the analysis for the same mask only.)"""
    from featurewarp_cli.engine.warper import FeatureWarper

    y, x = np.mgrid[0:120, 0:160]
    masks = [(x - 50) ** 2 + (y - 60) ** 2 < 20**2, (abs(x - 110) < 25) & (abs(y - 40) < 15)]
    warp = load_warp("swirl")(160, 120, angle=60)
    solver._symbolic_cache.clear()
    FeatureWarper(160, 120, masks[0], cell=4, formulation="paper").solve(warp)
    kept = dict(solver._symbolic_cache)
    mesh = FeatureWarper(160, 120, masks[1], cell=4, formulation="paper").solve(warp)
    assert solver._symbolic_cache.keys() == kept.keys()
    assert all(solver._symbolic_cache[k] is v for k, v in kept.items())
    assert mesh.flips() == 0

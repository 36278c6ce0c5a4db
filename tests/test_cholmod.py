"""The CHOLMOD binding (featurewarp_cli._cholmod), the numpy matrices of system.py, the
solver around them (threads, SciPy fallback) and the import-time promise (no SciPy)."""

from __future__ import annotations

import subprocess
import sys
import threading
from concurrent.futures import ThreadPoolExecutor

import numpy as np
import pytest

from featurewarp_cli.engine import solver
from featurewarp_cli.engine import system
from featurewarp_cli.engine.warper import AxisSystems, FeatureWarper, load_warp
from featurewarp_cli.engine.grid import Grid

cholmod = pytest.importorskip("featurewarp_cli._cholmod")
INDEX = solver.INDEX             # the binding's index type (int32)


def random_spd(n, seed, density=0.05):
    """A random SPD matrix as dense, and the triplets of its lower triangle with every
    entry split into two duplicates (shuffled)."""
    rng = np.random.default_rng(seed)
    a = np.where(rng.random((n, n)) < density, rng.normal(size=(n, n)), 0.0)
    dense = a @ a.T + n * 0.1 * np.eye(n)
    rows, cols = np.nonzero(np.tril(dense))
    vals = dense[rows, cols]
    part = rng.uniform(0.2, 0.8, vals.size)
    order = rng.permutation(2 * vals.size)
    rows, cols = np.concatenate([rows, rows])[order], np.concatenate([cols, cols])[order]
    vals = np.concatenate([vals * part, vals * (1 - part)])[order]
    return dense, rows.astype(INDEX), cols.astype(INDEX), vals


def laplacian_triplets(side, shift=1e-3):
    """Lower triangle of a side x side grid Laplacian plus shift * I (SPD)."""
    grid = Grid.for_image(side - 1, side - 1, 1)
    matrix = system.normal_matrix(grid, np.ones(grid.quad_shape[0] * grid.quad_shape[1]))
    rows, cols, vals = matrix.lower_triplets()
    return grid.n_nodes, rows.astype(INDEX), cols.astype(INDEX), np.where(rows == cols, vals + shift, vals)


@pytest.mark.parametrize("supernodal", [False, True])
@pytest.mark.parametrize("ordering", ["NATURAL", "DEFAULT", "AMD"])
@pytest.mark.parametrize("n", [1, 7, 120])
def test_factor_and_solve_match_a_dense_solve(n, ordering, supernodal):
    dense, rows, cols, vals = random_spd(n, seed=n)
    factor = cholmod.analyze(n, rows, cols, supernodal, getattr(cholmod, ordering)).factorize(rows, cols, vals)
    rng = np.random.default_rng(1)
    for b in (rng.normal(size=n), rng.normal(size=(n, 1)), rng.normal(size=(n, 3))):
        x = factor.solve(b)
        assert x.shape == b.shape and x.dtype == np.float64
        np.testing.assert_allclose(x, np.linalg.solve(dense, b), rtol=1e-10, atol=1e-10)
    out = np.empty((n, 3))
    assert factor.solve(np.ascontiguousarray(b), out) is out
    np.testing.assert_allclose(out, np.linalg.solve(dense, b), rtol=1e-10, atol=1e-10)
    assert (factor.n, factor.supernodal) == (n, supernodal)


def test_natural_ordering_keeps_the_order():
    n, rows, cols, vals = laplacian_triplets(30)
    for supernodal in (False, True):
        symbolic = cholmod.analyze(n, rows, cols, supernodal)
        perm = np.empty(n, INDEX)
        symbolic.perm(perm)
        assert np.array_equal(perm, np.arange(n))
        counts = np.empty(n, INDEX)
        symbolic.column_counts(counts)
        assert counts.sum() == symbolic.lnz and counts.min() >= 1


def test_one_analysis_serves_other_values():
    n, rows, cols, vals = laplacian_triplets(40)
    symbolic = cholmod.analyze(n, rows, cols)
    b = np.random.default_rng(2).normal(size=(n, 2))
    for scale in (1.0, 3.0):
        x = symbolic.factorize(rows, cols, vals * scale).solve(b)
        full = system.symmetric_scipy(rows, cols, vals * scale, n)
        np.testing.assert_allclose(full @ x, b, rtol=1e-8, atol=1e-8)


@pytest.mark.parametrize("supernodal", [False, True])
def test_not_positive_definite_raises_and_leaks_nothing(supernodal):
    n, rows, cols, vals = laplacian_triplets(20)
    singular = np.where((rows == 5) | (cols == 5), 0.0, vals)       # node 5 cut off: a zero pivot
    indefinite = np.where(rows == cols, vals - 1.0, vals)
    symbolic = cholmod.analyze(n, rows, cols, supernodal)
    assert issubclass(cholmod.NotPositiveDefinite, ArithmeticError)
    for _ in range(50):
        for bad in (singular, indefinite):
            with pytest.raises(cholmod.NotPositiveDefinite, match="not positive definite"):
                symbolic.factorize(rows, cols, bad)
    symbolic.factorize(rows, cols, vals).solve(np.ones(n))
    del symbolic
    assert cholmod._leaked_bytes() == 0


def test_bad_arguments_raise():
    n, rows, cols, vals = laplacian_triplets(6)
    symbolic = cholmod.analyze(n, rows, cols)
    with pytest.raises(ValueError, match="lower triangle"):
        cholmod.analyze(n, cols, rows + (rows == cols))            # an upper-triangle entry
    with pytest.raises(ValueError, match="lower triangle"):
        cholmod.analyze(n - 1, rows, cols)                         # out of range
    with pytest.raises(ValueError, match="same length"):
        symbolic.factorize(rows, cols, vals[:-1])
    with pytest.raises(ValueError, match="analysed pattern"):
        symbolic.factorize(rows[1:], cols[1:], vals[1:])
    with pytest.raises(TypeError):
        symbolic.factorize(rows.astype(np.float64), cols, vals)
    factor = symbolic.factorize(rows, cols, vals)
    with pytest.raises(ValueError, match="shape"):
        factor.solve(np.ones(n + 1))
    with pytest.raises(ValueError, match="shape of b"):
        factor.solve(np.ones(n), np.ones(n + 1))
    del symbolic, factor
    assert cholmod._leaked_bytes() == 0


@pytest.mark.parametrize("supernodal", [False, True])
def test_factorizations_in_two_threads_equal_serial_ones(supernodal):
    n, rows, cols, vals = laplacian_triplets(150)
    weights = [vals, np.where(rows == cols, vals * 2.0, vals)]
    symbolic = cholmod.analyze(n, rows, cols, supernodal)
    b = np.random.default_rng(3).normal(size=(n, 2))
    serial = [symbolic.factorize(rows, cols, w).solve(b) for w in weights]
    for _ in range(3):
        with ThreadPoolExecutor(2) as pool:
            factors = list(pool.map(lambda w: symbolic.factorize(rows, cols, w), weights))
            # Solves on one factor from two threads at once, too.
            solves = list(pool.map(lambda f: f.solve(b), [factors[0], factors[0], factors[1]]))
        for x, expected in zip(solves, [serial[0], serial[0], serial[1]]):
            np.testing.assert_array_equal(x, expected)


# ------------------------------------------------------------------ system.py matrices

def test_stencil_matrix_equals_its_scipy_form():
    grid = Grid.for_image(37, 23, 4)
    rng = np.random.default_rng(4)
    matrix = system.normal_matrix(grid, rng.uniform(1, 10, grid.quad_shape[0] * grid.quad_shape[1]))
    reference = matrix.to_scipy()
    assert np.allclose(reference.toarray(), reference.toarray().T)
    for x in (rng.normal(size=grid.n_nodes), rng.normal(size=(grid.n_nodes, 2))):
        np.testing.assert_array_equal(matrix.dot(x), reference @ x)
    nodes = np.flatnonzero(rng.random(grid.n_nodes) < 0.5)
    sub = matrix.submatrix(nodes)
    np.testing.assert_array_equal(sub.to_scipy().toarray(), reference[nodes][:, nodes].toarray())
    x = rng.normal(size=(nodes.size, 2))
    np.testing.assert_array_equal(sub.dot(x), reference[nodes][:, nodes] @ x)
    rows, cols, vals = matrix.lower_triplets()
    assert np.all(rows >= cols) and rows.size == grid.n_nodes + 2 * grid.n_nodes - grid.nx - grid.ny


# ------------------------------------------------------------------ solver around the binding

def grid_problem(width=160, height=120, cell=4):
    grid = Grid.for_image(width, height, cell)
    yy, xx = np.mgrid[0:height, 0:width]
    mask = (xx - 60) ** 2 + (yy - 50) ** 2 < 25 ** 2
    from featurewarp_cli.engine import features as feat

    features = feat.analyse(mask, grid, 10.0, 2.0)
    matrix = system.normal_matrix(grid, features.weight)
    fixed = grid.boundary()
    tied = system.tie_features(grid, features, fixed)
    rng = np.random.default_rng(5)
    rhs = rng.normal(size=(grid.n_nodes, 2))
    offset = np.where(fixed[:, None], rng.normal(size=(grid.n_nodes, 2)) * 30, 0.0)
    return grid, matrix, system.number_unknowns(fixed, tied), rhs, offset


def test_scipy_fallback_when_the_binding_is_missing(monkeypatch, capsys):
    grid, matrix, unknown, rhs, offset = grid_problem()
    expected = solver.ReducedSystem(matrix, unknown).solve(rhs, offset)
    monkeypatch.setattr(solver, "_cholmod", None)
    monkeypatch.setattr(solver, "_fallback_noted", False)
    fallback = solver.ReducedSystem(matrix, unknown)
    assert fallback.method == "scipy-splu"
    assert "CHOLMOD binding" in capsys.readouterr().err
    np.testing.assert_allclose(fallback.solve(rhs, offset), expected, rtol=1e-9, atol=1e-9)
    solver.ReducedSystem(matrix, unknown)
    assert capsys.readouterr().err == ""                      # one notice per process
    # The whole engine, x and y apart (a sliding border).
    y, x = np.mgrid[0:90, 0:120]
    warper = FeatureWarper(120, 90, (x - 60) ** 2 + (y - 40) ** 2 < 20 ** 2, cell=4)
    mesh = warper.solve(load_warp("stretch")(120, 90, sx=1.6))
    assert mesh.info["solver"] == "scipy-splu" and warper.factorizations == 2 and mesh.flips() == 0


def test_axis_systems_factored_in_two_threads_solve_like_serial_ones():
    grid, matrix, unknown, rhs, offset = grid_problem()
    top = np.zeros(grid.n_nodes, bool)
    top[1:grid.nx - 1] = True
    sliding = unknown.copy()
    sliding[top] = unknown.max() + 1 + np.arange(np.count_nonzero(top))
    solver._symbolic_cache.clear()
    both = AxisSystems(matrix, sliding, unknown)
    assert both.factorizations == 2
    x = solver.ReducedSystem(matrix, sliding).solve(rhs[:, :1], offset[:, :1])
    y = solver.ReducedSystem(matrix, unknown).solve(rhs[:, 1:], offset[:, 1:])
    np.testing.assert_array_equal(both.solve(rhs, offset), np.concatenate([x, y], axis=1))


def test_openmp_and_blas_settings_are_restored_after_threads():
    omp = solver._openmp_runtime()
    blas = solver._openblas_runtime()
    before = (omp.omp_get_max_active_levels() if omp else None,
              blas.openblas_get_num_threads() if blas else None)
    barrier = threading.Barrier(2)

    def work():
        with solver._single_threaded_blas(), solver._without_openmp():
            barrier.wait()
            if omp is not None:
                assert omp.omp_get_max_active_levels() == 0
            if blas is not None:
                assert blas.openblas_get_num_threads() == 1

    with ThreadPoolExecutor(2) as pool:
        for future in [pool.submit(work) for _ in range(2)]:
            future.result()
    after = (omp.omp_get_max_active_levels() if omp else None,
             blas.openblas_get_num_threads() if blas else None)
    assert after == before


def test_the_engine_does_not_import_scipy():
    code = ("import sys, numpy as np\n"
            "from featurewarp_cli.engine.warper import warp\n"
            "image = np.zeros((90, 120, 3), np.uint8)\n"
            "mask = np.zeros((90, 120), bool); mask[30:60, 40:80] = True\n"
            "warp(image, mask, 'stretch', sx=1.5)\n"
            "warp(image, mask, 'swirl', angle=270, cell=3)\n"
            "print(sorted(m for m in sys.modules if m.split('.')[0] in ('scipy', 'sksparse')))\n")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "[]", out.stdout + out.stderr

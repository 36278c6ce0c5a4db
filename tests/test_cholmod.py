"""CHOLMOD through scikit-sparse (featurewarp_cli.engine.cholmod), the normal matrix of
system.py, the solver around them (x and y systems, SciPy fallback) and the import-time
promise (no SciPy for --help and warps)."""

from __future__ import annotations

import contextlib
import subprocess
import sys

import numpy as np
import pytest
import scipy.sparse as sp

from featurewarp_cli.engine import cholmod, solver, system
from featurewarp_cli.engine.grid import Grid
from featurewarp_cli.engine.solver import AxisSystems
from featurewarp_cli.engine.warper import FeatureWarper, load_warp

needs_cholmod = pytest.mark.skipif(not cholmod.AVAILABLE, reason="scikit-sparse is not installed")


def random_spd(n, seed, density=0.05):
    """A random SPD matrix as dense, and its lower triangle as CSC."""
    rng = np.random.default_rng(seed)
    a = np.where(rng.random((n, n)) < density, rng.normal(size=(n, n)), 0.0)
    dense = a @ a.T + n * 0.1 * np.eye(n)
    return dense, sp.csc_matrix(np.tril(dense))


def laplacian_lower(side, shift=1e-3):
    """Lower triangle (CSC) of a side x side grid Laplacian plus shift * I (SPD)."""
    grid = Grid.for_image(side - 1, side - 1, 1)
    matrix = system.normal_matrix(grid, np.ones(grid.quad_shape[0] * grid.quad_shape[1]))
    return sp.tril(matrix + shift * sp.identity(grid.n_nodes), format="csc")


# ------------------------------------------------------------------ the scikit-sparse module

@needs_cholmod
@pytest.mark.parametrize("supernodal", [False, True])
@pytest.mark.parametrize("ordering", ["natural", "default", "amd"])
@pytest.mark.parametrize("n", [1, 7, 120])
def test_factor_and_solve_match_a_dense_solve(n, ordering, supernodal):
    dense, lower = random_spd(n, seed=n)
    factor = cholmod.factorize(cholmod.analyze(lower, ordering, supernodal), lower)
    rng = np.random.default_rng(1)
    for b in (rng.normal(size=n), rng.normal(size=(n, 1)), rng.normal(size=(n, 3))):
        x = cholmod.solve(factor, b)
        assert x.shape == b.shape and x.dtype == np.float64
        np.testing.assert_allclose(x, np.linalg.solve(dense, b), rtol=1e-10, atol=1e-10)


@needs_cholmod
def test_unknown_ordering_is_refused():
    with pytest.raises(ValueError, match="ordering must be one of"):
        cholmod.analyze(laplacian_lower(4), "best")


@needs_cholmod
@pytest.mark.parametrize("supernodal", [False, True])
def test_one_analysis_serves_other_values_and_stays_symbolic(supernodal):
    lower = laplacian_lower(40)
    analysis = cholmod.analyze(lower, "natural", supernodal)
    b = np.random.default_rng(2).normal(size=(lower.shape[0], 2))
    full = lower + sp.tril(lower, -1).T
    factors = [cholmod.factorize(analysis, lower * scale) for scale in (1.0, 3.0)]
    for factor, scale in zip(factors, (1.0, 3.0)):         # the first is still valid
        np.testing.assert_allclose((full * scale) @ cholmod.solve(factor, b), b, rtol=1e-8, atol=1e-8)
    assert cholmod.factor_nnz(factors[0]) >= lower.nnz


@needs_cholmod
@pytest.mark.parametrize("supernodal", [False, True])
def test_not_positive_definite_is_the_project_exception(supernodal):
    """A zero pivot (node 5 cut off: what a piece of grid with no fixed node gives) and an
    indefinite matrix, with either method (the simplicial method computes LDL', which has no
    square roots to fail on negative pivots: ``factorize(simplicial=True)`` checks them)."""
    lower = laplacian_lower(20)
    column = np.repeat(np.arange(lower.shape[1]), np.diff(lower.indptr))
    singular = lower.copy()
    singular.data[(lower.indices == 5) | (column == 5)] = 0.0       # same pattern, zero values
    indefinite = lower - sp.diags(lower.diagonal() * 1.5, format="csc")
    assert issubclass(cholmod.NotPositiveDefinite, ArithmeticError)
    analysis = cholmod.analyze(lower, "natural", supernodal)
    for matrix in (singular, indefinite):
        with pytest.raises(cholmod.NotPositiveDefinite, match="not positive definite"):
            cholmod.factorize(analysis, matrix, simplicial=not supernodal)
    if not supernodal:                          # unchecked, CHOLMOD's LDL' takes it
        assert cholmod.factorize(analysis, indefinite).D().min() < 0
    b = np.ones(lower.shape[0])
    full = lower + sp.tril(lower, -1).T
    factor = cholmod.factorize(analysis, lower, simplicial=not supernodal)
    np.testing.assert_allclose(full @ cholmod.solve(factor, b), b)   # still serves


@needs_cholmod
def test_spd_solver_refuses_an_indefinite_matrix():
    """The barrier's local preconditioner (spd_solver) relies on the refusal: its matrix is a
    principal submatrix of the Newton system, so an indefinite one means the whole is."""
    from featurewarp_cli.engine.solver import spd_solver

    with pytest.raises(cholmod.NotPositiveDefinite):
        spd_solver(sp.csc_matrix(np.array([[2.0, 1.0, 0.0], [1.0, -3.0, 1.0], [0.0, 1.0, 2.0]])))


@needs_cholmod
def test_openmp_is_off_while_factoring_and_restored_after(monkeypatch):
    omp = cholmod._openmp_runtime()
    if omp is None:
        pytest.skip("CHOLMOD runs without an OpenMP runtime here")
    before = omp.omp_get_max_active_levels()
    with cholmod._openmp_off():
        assert omp.omp_get_max_active_levels() == 0
    assert omp.omp_get_max_active_levels() == before
    levels = []
    off = cholmod._openmp_off

    @contextlib.contextmanager
    def spy():
        with off():
            yield
            levels.append(omp.omp_get_max_active_levels())

    monkeypatch.setattr(cholmod, "_openmp_off", spy)
    lower = laplacian_lower(10)
    cholmod.factorize(cholmod.analyze(lower, "natural", True), lower)
    assert levels == [0] and omp.omp_get_max_active_levels() == before


# ------------------------------------------------------------------ system.py's matrix

def test_normal_matrix_is_a_transpose_a_of_the_edge_equations():
    grid = Grid.for_image(37, 23, 4)
    rng = np.random.default_rng(4)
    weights = rng.uniform(1, 10, grid.quad_shape[0] * grid.quad_shape[1])
    # A: one row w (v_b - v_a) per quad edge (top, right, bottom, left).
    corners = grid.quads()
    start, end = corners.ravel(), np.roll(corners, -1, axis=1).ravel()
    w = np.repeat(weights, 4)
    rows = np.arange(start.size)
    a = sp.csr_matrix((np.concatenate([-w, w]), (np.concatenate([rows, rows]), np.concatenate([start, end]))),
                      shape=(start.size, grid.n_nodes))
    matrix = system.normal_matrix(grid, weights)
    np.testing.assert_allclose(matrix.toarray(), (a.T @ a).toarray(), rtol=1e-12, atol=1e-12)
    # Every grid edge is stored (the pattern is the stencil's), each row sorted.
    assert matrix.nnz == grid.n_nodes + 2 * (2 * grid.n_nodes - grid.nx - grid.ny)
    assert matrix.has_sorted_indices
    np.testing.assert_allclose(matrix.diagonal(), system.node_stiffness(grid, weights), rtol=1e-12)


# ------------------------------------------------------------------ solver around the module

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


@needs_cholmod
def test_scipy_fallback_when_scikit_sparse_is_missing(monkeypatch, capsys):
    grid, matrix, unknown, rhs, offset = grid_problem()
    expected = solver.ReducedSystem(matrix, unknown).solve(rhs, offset)
    monkeypatch.setattr(cholmod, "AVAILABLE", False)
    monkeypatch.setattr(solver, "_fallback_noted", False)
    fallback = solver.ReducedSystem(matrix, unknown)
    assert fallback.method == "scipy-splu"
    assert "scikit-sparse" in capsys.readouterr().err
    np.testing.assert_allclose(fallback.solve(rhs, offset), expected, rtol=1e-9, atol=1e-9)
    solver.ReducedSystem(matrix, unknown)
    assert capsys.readouterr().err == ""                      # one notice per process
    # The whole engine, x and y apart (a sliding border).
    y, x = np.mgrid[0:90, 0:120]
    warper = FeatureWarper(120, 90, (x - 60) ** 2 + (y - 40) ** 2 < 20 ** 2, cell=4)
    mesh = warper.solve(load_warp("stretch")(120, 90, sx=1.6))
    assert mesh.info["solver"] == "scipy-splu" and warper.factorizations == 2 and mesh.flips() == 0


def test_fallback_of_a_singular_matrix_is_the_project_exception(monkeypatch):
    monkeypatch.setattr(cholmod, "AVAILABLE", False)
    monkeypatch.setattr(solver, "_fallback_noted", True)
    singular = sp.csr_matrix(np.array([[1.0, -1.0, 0.0], [-1.0, 1.0, 0.0], [0.0, 0.0, 1.0]]))
    with pytest.raises(cholmod.NotPositiveDefinite):
        solver.ReducedSystem(singular, np.arange(3))


def test_a_process_without_scikit_sparse_warps_with_one_notice(tmp_path):
    """sksparse hidden: the report's solver is scipy-splu, with one notice on stderr."""
    code = ("import sys; sys.modules['sksparse'] = None\n"
            "import numpy as np\n"
            "from featurewarp_cli import FeatureWarper, load_warp\n"
            "y, x = np.mgrid[0:90, 0:120]\n"
            "warper = FeatureWarper(120, 90, (x - 60) ** 2 + (y - 40) ** 2 < 20 ** 2, cell=4)\n"
            "meshes = [warper.solve(load_warp('stretch')(120, 90, sx=s)) for s in (1.6, 0.7)]\n"
            "meshes.append(FeatureWarper(120, 90, x < 30, cell=5).solve(load_warp('swirl')(120, 90)))\n"
            "print(sorted({m.info['solver'] for m in meshes}), max(m.flips() for m in meshes))\n")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.split() == ["['scipy-splu']", "0"]
    assert out.stderr.count("featurewarp:") == 1 and "scikit-sparse" in out.stderr


def test_axis_systems_solve_like_one_system_per_axis():
    grid, matrix, unknown, rhs, offset = grid_problem()
    top = np.zeros(grid.n_nodes, bool)
    top[1:grid.nx - 1] = True
    sliding = unknown.copy()
    sliding[top] = unknown.max() + 1 + np.arange(np.count_nonzero(top))
    both = AxisSystems(matrix, sliding, unknown)
    assert both.factorizations == 2 and both.method == solver.ReducedSystem(matrix, unknown).method
    x = solver.ReducedSystem(matrix, sliding).solve(rhs[:, :1], offset[:, :1])
    y = solver.ReducedSystem(matrix, unknown).solve(rhs[:, 1:], offset[:, 1:])
    np.testing.assert_array_equal(both.solve(rhs, offset), np.concatenate([x, y], axis=1))
    one = AxisSystems(matrix, unknown, unknown.copy())
    assert one.factorizations == 1 and one.x is one.y


# ------------------------------------------------------------------ imports

SCIPY_MODULES = "sorted({m.split('.')[0] for m in sys.modules} & {'scipy', 'sksparse'})"


@pytest.mark.parametrize("args", [["--help"], ["warps"]])
def test_help_and_warps_import_no_scipy(args):
    code = ("import sys\nfrom featurewarp_cli.cli.main import main\n"
            f"sys.argv = ['featurewarp', *{args!r}]\n"
            "try:\n    main()\nexcept SystemExit:\n    pass\n"
            f"sys.stderr.write(repr({SCIPY_MODULES}))\n")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stderr.strip().endswith("[]"), out.stderr


def warp_process_modules(tmp_path, *options, modules=SCIPY_MODULES):
    """The SciPy packages (or what ``modules`` lists) a ``featurewarp warp swirl`` process with
    these options loaded."""
    import cv2

    y, x = np.mgrid[0:60, 0:80]
    cv2.imwrite(str(tmp_path / "in.png"), np.dstack([x * 3, y * 4, x + y]).astype(np.uint8))
    cv2.imwrite(str(tmp_path / "mask.png"), (((x - 40) ** 2 + (y - 30) ** 2 < 150) * 255).astype(np.uint8))
    options = [str(tmp_path / o) if o.endswith(".png") else o for o in options]
    code = ("import sys\nfrom featurewarp_cli.cli.main import main\n"
            f"sys.argv = ['featurewarp', 'warp', 'swirl', {str(tmp_path / 'in.png')!r}, "
            f"{str(tmp_path / 'out.png')!r}, *{options!r}]\n"
            "try:\n    main()\nexcept SystemExit as exit:\n    assert not exit.code, exit.code\n"
            f"print({modules})\n")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    return out.stdout.strip()


@needs_cholmod
def test_a_warp_process_uses_scikit_sparse(tmp_path):
    assert warp_process_modules(tmp_path, "--mask", "mask.png") == "['scipy', 'sksparse']"


@needs_cholmod
def test_the_fold_guard_imports_neither_scipy_linalg_nor_scipy_optimize(tmp_path):
    """Importing them took 40 ms (LAPACK's pivoted Cholesky, for the Woodbury solves) and
    0.13-0.2 s (brentq) of a 1 MP command; the guard's Newton steps and roots need neither."""
    import json

    report = tmp_path / "report.json"
    assert warp_process_modules(tmp_path, "--angle", "180", "--mask", "mask.png", "--report", str(report),
                                modules="sorted(m for m in sys.modules if m.startswith(('scipy.linalg', "
                                        "'scipy.optimize')))") == "[]"
    guard = json.loads(report.read_text())["fold_guard"]
    assert guard["flipped_before"] and guard["barrier"]["newton_steps"]       # the guard did its work


@pytest.mark.parametrize("options", [[], ["--mask", "mask.png", "--mode", "plain"]])
def test_a_warp_that_factors_nothing_imports_no_scipy(tmp_path, options):
    assert warp_process_modules(tmp_path, *options) == "[]"


@needs_cholmod
def test_many_tied_features_take_cholmods_ordering_and_the_same_solution(monkeypatch):
    """Shared unknowns come last in the grid order: a dense block of their count (10 000 specks
    on 1 MP factored in 12 s). Past MAX_SHARED_LAST, CHOLMOD's own ordering; the solution is
    the same to rounding."""
    from featurewarp_cli.engine import features as feat

    grid = Grid.for_image(160, 120, 4)
    mask = np.zeros((120, 160), bool)
    mask[2::9, 3::9] = True                                   # 234 single-pixel features, 192 tied
    features = feat.analyse(mask, grid, 10.0, 2.0)
    matrix = system.normal_matrix(grid, features.weight)
    fixed = grid.boundary()
    unknown = system.number_unknowns(fixed, system.tie_features(grid, features, fixed))
    shared = np.count_nonzero(np.bincount(unknown[unknown >= 0]) > 1)
    rng = np.random.default_rng(6)
    rhs, offset = rng.normal(size=(grid.n_nodes, 1)), np.where(fixed[:, None], 5.0, 0.0)
    monkeypatch.setattr(solver, "MAX_SHARED_LAST", shared)
    by_grid = solver.ReducedSystem(matrix, unknown)
    monkeypatch.setattr(solver, "MAX_SHARED_LAST", shared - 1)
    by_cholmod = solver.ReducedSystem(matrix, unknown)
    assert shared > 100 and by_grid.ordering == "grid-nested-dissection" and by_cholmod.ordering == "default"
    np.testing.assert_allclose(by_cholmod.solve(rhs, offset), by_grid.solve(rhs, offset), atol=1e-8)

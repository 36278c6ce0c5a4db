"""Solver benchmark: fill-reducing orderings, factorization methods and cold factor times.

Builds the systems that FeatureWarper factors for four cases and measures:

orderings  For the reduced matrix of the case's first system: nnz(L) and the
           analysis, numeric factorization and solve (x and y) times of the grid
           nested dissection of ``featurewarp_cli.engine.solver`` (the matrix
           permuted, then CHOLMOD's natural ordering) and of CHOLMOD's own
           orderings (``default``: AMD, or METIS when AMD fills much; ``amd``;
           ``metis``; ``nesdis`` with --nesdis), each with CHOLMOD's simplicial
           and supernodal methods (``--modes``). Everything goes through
           ``featurewarp_cli.engine.cholmod`` (scikit-sparse).
factor     ``ReducedSystem(matrix, unknown)`` with the symbolic cache cleared (a
           cold factorization: what FeatureWarper.timings['factor'] measures), for
           every system of the case one after the other (x and y when the border
           slides), wall and process CPU seconds (CPU includes BLAS threads).

To see what OpenMP costs (Debian's CHOLMOD runs its supernodal assembly in
OpenMP teams), run it again with ``OMP_NUM_THREADS=1 OPENBLAS_NUM_THREADS=2``
(the BLAS keeps its threads; OpenBLAS would otherwise read OMP_NUM_THREADS too).

Cases: table1-1000 and table1-500 (the Table 1 grids of benchmarks/run.py: cell 4,
disc mask, swirl 90), 12MP-swirl (samples/astronaut.png and its mask upscaled to
4000x3000, default cell, swirl 180), 1MP-stretch (1024x1024, cell 4, stretch x2:
the sliding border gives two systems). Medians of --runs runs.

Usage::

    .venv/bin/python benchmarks/solver_orderings.py [--cases 1MP-stretch,...] [--runs 5]
        [--only orderings|factor] [--modes simplicial,supernodal] [--nesdis]
"""

from __future__ import annotations

import argparse
import statistics
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

import numpy as np  # noqa: E402

from benchmarks.inputs import make_photos  # noqa: E402
from samples.scenes import disc_mask  # noqa: E402
from featurewarp_cli.engine import cholmod, solver  # noqa: E402
from featurewarp_cli.engine import warper as api  # noqa: E402
from featurewarp_cli.io.decode import mask_from_image, read_image  # noqa: E402

CASES = ("table1-1000", "table1-500", "12MP-swirl", "1MP-stretch")


def case_inputs(name: str, photos) -> tuple:
    """(width, height, mask, cell, warp) of a case."""
    if name.startswith("table1-"):
        g = int(name.split("-")[1])
        width = height = (g - 1) * 4
        return width, height, disc_mask(width, height), 4, api.load_warp("swirl")(width, height, angle=90)
    label, preset, params, cell = {"12MP-swirl": ("12MP", "swirl", {"angle": 180}, None),
                                   "1MP-stretch": ("1MP", "stretch", {"sx": 2.0}, 4)}[name]
    mask = mask_from_image(read_image(str(photos[label][1])))
    height, width = mask.shape
    return width, height, mask, cell, api.load_warp(preset)(width, height, **params)


def systems(name: str, photos) -> list:
    """The (matrix, unknown) pairs of the first factorization of a case (x, and y if it differs)."""
    width, height, mask, cell, warp = case_inputs(name, photos)
    seen, original = [], solver.AxisSystems.__init__

    def record(self, matrix, unknown_x, unknown_y):
        if not seen:
            seen.extend([(matrix, unknown_x)] + ([] if np.array_equal(unknown_x, unknown_y) else
                                                 [(matrix, unknown_y)]))
        original(self, matrix, unknown_x, unknown_y)

    solver.AxisSystems.__init__ = record
    try:
        api.FeatureWarper(width, height, mask, cell=cell).solve(warp)
    finally:
        solver.AxisSystems.__init__ = original
    return seen


def reduced_lower(matrix, unknown) -> dict:
    """The reduced lower triangle (CSC) in the grid order and in the unknowns' own order."""
    captured = []
    factor, grid_width = solver._cholmod_factor, solver._grid_width
    solver._cholmod_factor = lambda lower, natural: captured.append(lower)
    try:
        solver.ReducedSystem(matrix, unknown)
        solver._grid_width = lambda *args: None
        solver.ReducedSystem(matrix, unknown)
    finally:
        solver._cholmod_factor, solver._grid_width = factor, grid_width
    return {"grid": captured[0], "own": captured[1]}


def timed(fn, runs):
    """(median seconds, last result) of ``runs`` calls."""
    times, result = [], None
    for _ in range(runs):
        t0 = time.perf_counter()
        result = fn()
        times.append(time.perf_counter() - t0)
    return statistics.median(times), result


def orderings(name, pairs, runs, modes, nesdis):
    lower = reduced_lower(*pairs[0])
    n = lower["own"].shape[0]
    print(f"\n{name}: {n} unknowns, nnz(lower A) {lower['own'].nnz} (solver's method: "
          f"{'supernodal' if n > solver._SIMPLICIAL_MAX else 'simplicial'})")
    print(f"{'ordering':>22} {'method':>11} {'nnz(L)':>9} {'analyze':>8} {'factor':>8} {'solve x,y':>9}")
    methods = [("grid (natural)", "grid", "natural"), ("cholmod default", "own", "default"),
               ("cholmod amd", "own", "amd"), ("cholmod metis", "own", "metis")]
    if nesdis:
        methods.append(("cholmod nesdis", "own", "nesdis"))
    b = np.asfortranarray(np.random.default_rng(0).normal(size=(n, 2)))
    for label, which, ordering in methods:
        matrix = lower[which]
        nnz = cholmod.factor_nnz(cholmod.factorize(cholmod.analyze(matrix, ordering, False), matrix))
        for mode in modes:
            supernodal = mode == "supernodal"
            analyze_s, analysis = timed(lambda: cholmod.analyze(matrix, ordering, supernodal), runs)
            factor_s, factor = timed(lambda: cholmod.factorize(analysis, matrix), runs)
            solve_s, _ = timed(lambda: cholmod.solve(factor, b), runs)
            print(f"{label:>22} {mode:>11} {nnz / 1e6:8.2f}M {analyze_s:8.3f} {factor_s:8.3f} {solve_s:9.4f}")


def factor_times(name, pairs, runs):
    wall, cpu = [], []
    for _ in range(runs):
        solver._symbolic_cache.clear()
        t0, c0 = time.perf_counter(), time.process_time()
        for matrix, unknown in pairs:
            solver.ReducedSystem(matrix, unknown)
        wall.append(time.perf_counter() - t0)
        cpu.append(time.process_time() - c0)
    sizes = " + ".join(str(int(u.max()) + 1) for _, u in pairs)
    print(f"{name:>12} {sizes:>16} unknowns: cold factor median {statistics.median(wall):.3f} s "
          f"(min {min(wall):.3f}), CPU {statistics.median(cpu):.3f} s, {runs} runs")


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--cases", default=",".join(CASES), help=f"comma-separated: {', '.join(CASES)}")
    parser.add_argument("--runs", type=int, default=5)
    parser.add_argument("--only", choices=("orderings", "factor"))
    parser.add_argument("--modes", default="simplicial,supernodal",
                        help="CHOLMOD methods to time in the orderings table")
    parser.add_argument("--nesdis", action="store_true", help="also CHOLMOD's NESDIS (slow: seconds per run)")
    args = parser.parse_args()
    if not cholmod.AVAILABLE:
        parser.error("scikit-sparse is not installed: nothing to measure")
    with tempfile.TemporaryDirectory(prefix="featurewarp-solver-") as tmp:
        photos = make_photos(ROOT / "samples", Path(tmp))
        for name in args.cases.split(","):
            pairs = systems(name, photos)
            if args.only != "factor":
                orderings(name, pairs, args.runs, args.modes.split(","), args.nesdis)
            if args.only != "orderings":
                factor_times(name, pairs, args.runs)


if __name__ == "__main__":
    main()

"""Solver benchmark: fill-reducing orderings and cold factorization times.

Builds the systems that FeatureWarper factors for four cases and measures:

orderings  nnz(L) and work (sum of squared column counts of L, simplicial
           analysis) for the grid nested dissection of ``featurewarp_cli.engine.solver``
           and for CHOLMOD's own orderings (AMD, METIS; NESDIS with --nesdis),
           with the analysis and numeric factorization times of each.
factor     ``ReducedSystem(matrix, unknown)`` with the symbolic cache cleared (a
           cold factorization: what FeatureWarper.timings['factor'] measures), for
           every system of the case one after the other (x and y when the border
           slides), and for two systems also ``solver.factor_concurrently`` (the
           two in parallel threads, as FeatureWarper factors them); with
           ``--baseline FILE`` (another solver.py, e.g. ``git show
           HEAD:featurewarp_cli/solver.py > /tmp/solver_head.py``; one without
           ``_lower_triplets`` gets the matrix as SciPy CSR) the variants run
           interleaved (A B A B ...).

Orderings and factorizations go through the CHOLMOD binding featurewarp_cli._cholmod.

Cases: table1-1000 and table1-500 (the Table 1 grids of benchmarks/run.py: cell 4,
disc mask, swirl 90), 12MP-swirl (samples/astronaut.png and its mask upscaled to
4000x3000, default cell, swirl 180), 1MP-stretch (1024x1024, cell 4, stretch x2:
the sliding border gives two systems). Medians of --runs runs, wall and process CPU
seconds (CPU includes BLAS threads).

Usage::

    .venv/bin/python benchmarks/solver_orderings.py [--cases 1MP-stretch,...] [--runs 5]
        [--only orderings|factor] [--baseline /tmp/solver_head.py] [--nesdis]
"""

from __future__ import annotations

import argparse
import importlib.util
import statistics
import sys
import tempfile
import time
from pathlib import Path
from types import SimpleNamespace

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

import numpy as np  # noqa: E402

from benchmarks.inputs import make_photos  # noqa: E402
from samples.scenes import disc_mask  # noqa: E402
from featurewarp_cli.engine import warper as api
from featurewarp_cli.engine import solver  # noqa: E402
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
    seen, original = [], api.AxisSystems.__init__

    def record(self, matrix, unknown_x, unknown_y):
        if not seen:
            seen.extend([(matrix, unknown_x)] + ([] if np.array_equal(unknown_x, unknown_y) else
                                                 [(matrix, unknown_y)]))
        original(self, matrix, unknown_x, unknown_y)

    api.AxisSystems.__init__ = record
    try:
        api.FeatureWarper(width, height, mask, cell=cell).solve(warp)
    finally:
        api.AxisSystems.__init__ = original
    return seen


def lower_triangles(matrix, unknown):
    """The reduced lower triangle in the grid order, and in the unknowns' own order, each
    as (n, rows, cols, vals) triplets (duplicates not summed)."""
    captured = []
    factor = solver._cholmod_factor
    unfactored = SimpleNamespace(solve=None)
    solver._cholmod_factor = lambda n, rows, cols, vals, natural, key: (captured.append((n, rows, cols, vals))
                                                                        or unfactored)
    grid_width = solver._grid_width
    try:
        solver.ReducedSystem(matrix, unknown)
        solver._grid_width = lambda *args: None
        solver.ReducedSystem(matrix, unknown)
    finally:
        solver._cholmod_factor, solver._grid_width = factor, grid_width
    return captured


def orderings(name, pairs, runs, nesdis):
    from featurewarp_cli import _cholmod

    grid, plain = lower_triangles(*pairs[0])
    n = plain[0]
    print(f"\n{name}: {n} unknowns, nnz(lower A) {np.unique(plain[1] * n + plain[2]).size}")
    print(f"{'ordering':>22} {'nnz(L)':>10} {'work':>8} {'analyze':>8} {'factor':>8}")
    supernodal = n > solver._SIMPLICIAL_MAX
    mode = "supernodal" if supernodal else "simplicial"
    methods = [("grid (natural)", grid, _cholmod.NATURAL), ("cholmod amd", plain, _cholmod.AMD),
               ("cholmod metis", plain, _cholmod.METIS)]
    if nesdis:
        methods.append(("cholmod nesdis", plain, _cholmod.NESDIS))
    for label, (n, rows, cols, vals), method in methods:
        counts = np.empty(n, solver.INDEX)
        _cholmod.analyze(n, rows, cols, False, method).column_counts(counts)
        an, fa = [], []
        for _ in range(runs):
            t0 = time.perf_counter()
            symbolic = _cholmod.analyze(n, rows, cols, supernodal, method)
            t1 = time.perf_counter()
            with solver._without_openmp():
                symbolic.factorize(rows, cols, vals)
            an.append(t1 - t0)
            fa.append(time.perf_counter() - t1)
        print(f"{label:>22} {counts.sum() / 1e6:9.2f}M {np.sum(counts.astype(float) ** 2) / 1e9:7.2f}G "
              f"{statistics.median(an):8.3f} {statistics.median(fa):8.3f}  ({mode}, {runs} runs)")


def factor_times(name, pairs, runs, baseline):
    variants = {"current": solver}
    if baseline:
        spec = importlib.util.spec_from_file_location("solver_baseline", baseline)
        module = importlib.util.module_from_spec(spec)
        spec.loader.exec_module(module)
        variants = {"baseline": module, **variants}
    if len(pairs) == 2:
        variants["concurrent"] = None
    as_scipy = [(matrix.to_scipy(), unknown) for matrix, unknown in pairs]   # for an older solver.py
    times = {k: ([], []) for k in variants}
    for _ in range(runs):
        for label, module in variants.items():
            (module or solver)._symbolic_cache.clear()
            t0, c0 = time.perf_counter(), time.process_time()
            if module is None:
                solver.factor_concurrently(pairs[0][0], [unknown for _, unknown in pairs])
            for matrix, unknown in (() if module is None else pairs if hasattr(module, "_lower_triplets")
                                    else as_scipy):
                module.ReducedSystem(matrix, unknown)
            times[label][0].append(time.perf_counter() - t0)
            times[label][1].append(time.process_time() - c0)
    sizes = " + ".join(str(int(u.max()) + 1) for _, u in pairs)
    for label, (wall, cpu) in times.items():
        print(f"{name:>12} {sizes:>16} unknowns {label:>9}: cold factor median {statistics.median(wall):.3f} s "
              f"(min {min(wall):.3f}), CPU {statistics.median(cpu):.3f} s, {runs} runs")


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--cases", default=",".join(CASES), help=f"comma-separated: {', '.join(CASES)}")
    parser.add_argument("--runs", type=int, default=5)
    parser.add_argument("--only", choices=("orderings", "factor"))
    parser.add_argument("--baseline", help="another solver.py to time against (interleaved)")
    parser.add_argument("--nesdis", action="store_true", help="also CHOLMOD's NESDIS (slow: seconds per run)")
    args = parser.parse_args()
    with tempfile.TemporaryDirectory(prefix="featurewarp-solver-") as tmp:
        photos = make_photos(ROOT / "samples", Path(tmp))
        for name in args.cases.split(","):
            pairs = systems(name, photos)
            if args.only != "factor":
                orderings(name, pairs, args.runs, args.nesdis)
            if args.only != "orderings":
                factor_times(name, pairs, args.runs, args.baseline)


if __name__ == "__main__":
    main()

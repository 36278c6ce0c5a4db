"""featurewarp benchmark: what ``make bench`` runs.

Sections (each prints a table; everything goes to one JSON file):

table1    The paper's Table 1 (setup = normal matrix assembly, factor, rhs setup,
          back-substitution) on grids of 50x100 ... 1000x1000 nodes with a disc mask
          covering about 20 %, beside the paper's published seconds. Measured through
          the public FeatureWarper (cell 4, an image sized to give the node counts)
          and its ``timings``; the solver's symbolic-analysis cache is cleared before
          each run (a cold factorization) and one more run shows it warm.
render    The renderer alone on 12 MP at cell 4 (swirl 180 with the mask).
rewarp    The interactive case through the API: a FeatureWarper on the 1 MP photo and
          mask solves and renders a swirl once (factoring), then re-solves and
          re-renders it with other angles; each re-warp is timed, and the
          factorization must be reused (``warper.factorizations`` does not grow).
commands  Whole ``featurewarp warp`` commands (subprocess wall time, peak RSS of
          that process) for each preset on a 1 MP and a 12 MP photo with a mask,
          made by upscaling samples/astronaut.png and its mask into a temporary
          folder; 1 MP at --cell 4, 12 MP at the default cell, plus 12 MP swirl
          at --cell 4; the 1 MP stretch runs exactly as in the target (automatic
          cell, 5.9 px there). Also ``featurewarp --help`` start-up.
magick    ImageMagick's plain equivalents on the same files, each run right after
          ours (part of ``commands``), when ``convert`` is installed, and the
          ratios ours / ImageMagick.
deform    Issue 11's interactive case (benchmarks/deform_case.py): one of 10 handles moving
          on the 1 MP photo through the API's quick Deformer, median of 10 updates.
rigid     Issue 23's rigid map against libigl's converged ARAP (benchmarks/rigidity.py):
          seven handle sets at 512 x 384; area ratio, rigidity, folds, Newton steps.
drag      Issue 23's recorded drags (benchmarks/editor_drag.py): three 1-second drags at 60
          pointer events a second through a ``featurewarp edit`` server on the 1 MP photo,
          one solve in flight as the page keeps it; update p50/p95/max and the settle time.
stability Issue 21's one-ulp harness (benchmarks/stability.py): twelve hard cases on the
          512 px astronaut, W's output nudged by one ulp in two patterns; the largest node
          move and image RMSE against the un-nudged run (targets 0.01 px, RMSE 0.5).
machines  Issue 21's emulated machines (benchmarks/machines.py): the gallery and six stability
          cases run again with other BLAS kernels (OPENBLAS_CORETYPE, one thread), numpy's
          AVX2-only and SSE-only kernels (NPY_DISABLE_CPU_FEATURES) and OpenCV without AVX,
          each compared with this machine's run (RMSE per picture, node moves).
photos    Issue 22's photo acceptance (benchmarks/photo_acceptance.py): four photos whose masks
          touch the frame (portrait, close-up, pagoda, dahlia), the 14 presets at their
          defaults and three stretches, both modes, against the plain warp: blank share,
          outline, each component by the report and by keypoints on the image, warnings.
cluster   Issue 25 (benchmarks/cluster.py): 200 images of 1 MP on 2 local Dask workers
          (batch --scheduler local:2) against batch -j 2 and make -j 2, interleaved;
          the Dask batch's overhead over the fastest (target 15 %).
hard      Issue 10's hard cases (benchmarks/hard_cases.py): the 12 MP photo with a
          head + helmet mask that makes the fold guard work, swirl 180, arc 300 and
          bulge 2.95, each beside ImageMagick's -swirl / -distort Arc / -implode.
floor     Issue 21 (benchmarks/floor_ratio.py): 14 presets at defaults, 2 masks, 1 and 12 MP / floor.

Medians of 5 runs (``--quick``: 3 runs, fewer sizes, 12 MP swirl only). A figure
whose first run takes over 45 s, or any figure once the time budget (``--budget``,
570 s) is spent, is not repeated; its run count is printed and kept in the JSON.
Results: benchmarks/results/bench-<date>.json and benchmarks/results/latest.json.

Usage::

    .venv/bin/python benchmarks/run.py [--quick] [--runs N] [--only table1,render,...]
"""

from __future__ import annotations

import argparse
import compileall
import datetime as _dt
import json
import os
import platform
import shutil
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

from featurewarp_cli import blas  # noqa: E402

blas.one_thread()           # the in-process sections run as the command does (featurewarp_cli.blas)

import cv2  # noqa: E402
import numpy as np  # noqa: E402

from benchmarks import targets as tgt  # noqa: E402
from benchmarks.floor_ratio import FLOOR  # noqa: E402
from benchmarks.hard_cases import bench_hard  # noqa: E402
from benchmarks.inputs import make_photos  # noqa: E402
from samples.scenes import disc_mask  # noqa: E402

SECTIONS = ("table1", "render", "rewarp", "deform", "rigid", "drag", "commands", "magick", "hard", "floor", "stability",
            "machines", "photos", "cluster")

#: The paper's Table 1 (Pentium 4, 3.2 GHz): setup, factor, rhs setup, solve in seconds.
PAPER_TABLE1 = {
    (50, 100): (0.156, 0.110, 0.015, 0.0),
    (100, 100): (0.375, 0.250, 0.031, 0.015),
    (100, 200): (1.141, 0.562, 0.047, 0.031),
    (200, 200): (2.171, 1.407, 0.109, 0.063),
}
GRIDS = [(50, 100), (100, 100), (100, 200), (200, 200), (500, 500), (1000, 1000)]
QUICK_GRIDS = GRIDS[:5]

#: Our presets and the ImageMagick operation each is compared with.
PRESETS = {
    "swirl": (["--angle", "180"], ["-swirl", "180"]),      # one sign, one direction of turn (issue 25)
    "bulge": (["--strength", "0.5"], ["-implode", "-0.5"]),
    "arc": (["--angle", "60"], ["-distort", "Arc", "60"]),
    "stretch": (["--sx", "2"], ["-liquid-rescale", "200x100%!"]),
}


def median(values):
    return float(statistics.median(values)) if values else float("nan")


TIME = shutil.which("time") or ("/usr/bin/time" if os.path.exists("/usr/bin/time") else None)
#: A figure whose first run takes longer than this many seconds is not repeated.
SLOW_RUN_S = 45.0


def run_measured(cmd: list[str], env=None) -> tuple[float, int, int]:
    """Run ``cmd``; return (wall seconds, peak RSS in MB of that process, exit code).

    The peak comes from GNU time when it is installed (the command is then
    forked from the small ``time`` process, not from this one, whose memory a
    forked child would count), else from wait4's rusage.
    """
    with tempfile.NamedTemporaryFile("r", suffix=".rss") as rss:
        full = [TIME, "-f", "%M", "-o", rss.name, *cmd] if TIME else cmd
        t0 = time.perf_counter()
        proc = subprocess.Popen(full, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, env=env)
        _, status, usage = os.wait4(proc.pid, 0)
        wall = time.perf_counter() - t0
        code = os.waitstatus_to_exitcode(status)
        err = proc.stderr.read().decode(errors="replace")
        proc.stderr.close()
        peak_kb = usage.ru_maxrss
        if TIME:
            try:
                peak_kb = int(rss.read().strip().splitlines()[-1])
            except (ValueError, IndexError):
                pass
    if code != 0:
        sys.stderr.write(f"bench: command failed ({code}): {' '.join(cmd)}\n{err}\n")
    return wall, peak_kb // 1024, code


#: perf_counter() time after which figures stop repeating (set by main from --budget).
DEADLINE = float("inf")


def repeat(cmd, runs, env=None):
    """Run ``cmd`` ``runs`` times (fewer when one run is slow or the time budget is spent)."""
    walls, peaks, codes = [], [], []
    for _ in range(runs):
        wall, peak, code = run_measured(cmd, env)
        walls.append(wall)
        peaks.append(peak)
        codes.append(code)
        if wall > SLOW_RUN_S or time.perf_counter() + wall > DEADLINE:
            break
    return {"cmd": cmd, "seconds": walls, "runs": len(walls), "median_s": median(walls), "peak_mb": max(peaks),
            "ok": all(c == 0 for c in codes)}


# --------------------------------------------------------------------------- sections

def bench_table1(runs: int, grids) -> list[dict]:
    from featurewarp_cli.engine import solver
    from featurewarp_cli.engine.warper import FeatureWarper, load_warp

    rows = []
    print("\n(a) Table 1: seconds per stage, median of %d cold runs (paper's numbers in brackets)" % runs)
    print(f"{'grid (nodes)':>14} {'unknowns':>9} {'setup':>15} {'factor':>15} {'rhs setup':>15} "
          f"{'solve':>15} {'total':>7} {'factor warm':>11}")
    for gy, gx in grids:
        cell = 4
        width, height = (gx - 1) * cell, (gy - 1) * cell
        mask = disc_mask(width, height)
        warp = load_warp("swirl")(width, height, angle=90)
        samples = {k: [] for k in ("assemble", "factor", "rhs", "solve")}
        info = {}
        for _ in range(runs):
            if samples["factor"] and time.perf_counter() > DEADLINE:
                break
            solver._symbolic_cache.clear()
            warper = FeatureWarper(width, height, mask, cell=cell)
            mesh = warper.solve(warp)
            for k in samples:
                samples[k].append(warper.timings.get(k, 0.0))
            info = {"nodes": mesh.info["grid"]["nodes"], "factorizations": warper.factorizations,
                    "flipped_before_guard": mesh.info.get("flipped_before_guard")}
        # One more with the symbolic analysis cached (another mask of the same pattern would hit it too).
        warper = FeatureWarper(width, height, mask, cell=cell)
        warper.solve(warp)
        warm = warper.timings.get("factor", float("nan"))
        unknowns = None
        for state in getattr(warper, "_states", {}).values():
            system = getattr(state, "system", None)
            sub = getattr(system, "x", system)
            unknowns = getattr(sub, "n_unknowns", None)
        med = {k: median(v) for k, v in samples.items()}
        total = sum(med.values())
        paper = PAPER_TABLE1.get((gy, gx))
        cells = []
        for i, k in enumerate(("assemble", "factor", "rhs", "solve")):
            cells.append(f"{med[k]:7.3f} [{paper[i]:5.3f}]" if paper else f"{med[k]:7.3f}        ")
        print(f"{f'{gy}x{gx}':>14} {unknowns or '':>9} {' '.join(f'{c:>15}' for c in cells)} "
              f"{total:7.3f} {warm:11.3f}")
        rows.append({"grid": [gy, gx], "image": [width, height], "mask_fraction": float(mask.mean()),
                     "unknowns": unknowns, "runs": samples, "median": med, "total": total,
                     "factor_warm": warm, "paper": paper, **info})
    return rows


def bench_render(runs: int, photo12: Path, mask12: Path) -> dict:
    from featurewarp_cli.render import raster as rnd
    from featurewarp_cli.engine.warper import FeatureWarper, load_warp
    from featurewarp_cli.io.decode import mask_from_image, read_image

    image = read_image(str(photo12))
    mask = mask_from_image(read_image(str(mask12)))
    h, w = image.shape[:2]
    warper = FeatureWarper(w, h, mask, cell=4)
    # The plain swirl's mesh: rendering costs the same for any node positions, and this
    # skips a cell-4 factorization and fold-over guard that the render figure does not need.
    mesh = warper.solve(load_warp("swirl")(w, h, angle=180), "plain")
    result = {"size": [w, h], "cell": 4, "triangles": int(mesh.triangles.shape[0])}
    print(f"\nRender only, {w}x{h} at cell 4 (swirl 180 mesh, {mesh.triangles.shape[0]} triangles, "
          f"12 MP output), median of {runs}")
    variants = [("api (FeatureWarper.render)", lambda: warper.render(image, mesh))]
    if hasattr(rnd, "render"):
        variants.append(("render.render, antialiased", lambda: rnd.render(
            image, mesh.source, mesh.target, mesh.triangles, mesh.canvas, "cubic", None)))
        variants.append(("render.render, antialias=False", lambda: rnd.render(
            image, mesh.source, mesh.target, mesh.triangles, mesh.canvas, "cubic", None, antialias=False)))
    for name, fn in variants:
        times = []
        for _ in range(runs):
            t0 = time.perf_counter()
            fn()
            times.append(time.perf_counter() - t0)
            if time.perf_counter() > DEADLINE:
                break
        result[name] = {"seconds": times, "median_s": median(times)}
        print(f"  {name:34s} {median(times):7.3f} s   (target <= {tgt.RENDER_12MP_CELL4_S} s)")
    return result


#: Swirl angles of the re-warp figure: the first (factored) warp, then the timed re-warps,
#: cycled. Small steps, as from a slider.
REWARP_FIRST = 60.0
REWARP_ANGLES = (55.0, 65.0, 50.0, 70.0, 62.0, 58.0)


def bench_rewarp(runs: int, photo1: Path, mask1: Path) -> dict:
    """Re-solve + re-render of a 1 MP swirl with new parameters, the factorization reused."""
    from featurewarp_cli.engine.warper import FeatureWarper, load_warp
    from featurewarp_cli.io.decode import mask_from_image, read_image

    image = read_image(str(photo1))
    mask = mask_from_image(read_image(str(mask1)))
    h, w = image.shape[:2]
    swirl = load_warp("swirl")
    warper = FeatureWarper(w, h, mask)
    t0 = time.perf_counter()
    warper.render(image, warper.solve(swirl(w, h, angle=REWARP_FIRST)))
    first = time.perf_counter() - t0
    factorizations = warper.factorizations
    times, solve, render, flips = [], [], [], []
    for k in range(max(runs, 5)):
        warp = swirl(w, h, angle=REWARP_ANGLES[k % len(REWARP_ANGLES)])
        t0 = time.perf_counter()
        mesh = warper.solve(warp)
        t1 = time.perf_counter()
        warper.render(image, mesh)
        times.append(time.perf_counter() - t0)
        solve.append(t1 - t0)
        render.append(times[-1] - solve[-1])
        flips.append(mesh.info.get("flipped_before_guard", 0))
    assert warper.factorizations == factorizations, "a re-warp factored the system again"
    result = {"size": [w, h], "first_s": first, "seconds": times, "median_s": median(times),
              "solve_median_s": median(solve), "render_median_s": median(render),
              "factorizations": warper.factorizations, "flipped_before_guard": flips,
              "angles": [REWARP_FIRST, *REWARP_ANGLES]}
    print(f"\nRe-warp through the API, {w}x{h} swirl (first {REWARP_FIRST:g} deg: {first:.3f} s, "
          f"{warper.factorizations} factorization(s)), median of {len(times)}")
    print(f"  re-solve + re-render {result['median_s']:7.3f} s  (solve {result['solve_median_s']:.3f}, "
          f"render {result['render_median_s']:.3f}; target <= {tgt.REWARP_1MP_S} s)")
    return result


def ours_cmd(exe: Path, preset, photo, mask, out, extra=()):
    args, _ = PRESETS[preset]
    return [str(exe), "warp", preset, str(photo), str(out), "--mask", str(mask), *args, *extra]


def magick_cmd(preset, photo, out):
    _, args = PRESETS[preset]
    return ["convert", str(photo), *args, str(out)]


def bench_commands(runs, exe, photos, tmp, quick, with_magick) -> tuple[dict, dict]:
    """Our commands, each followed by its ImageMagick counterpart (same load conditions)."""
    results = {"startup": {}, "runs": []}
    magick = {"available": False, "runs": []}
    if with_magick and shutil.which("convert"):
        version = subprocess.run(["convert", "-version"], capture_output=True, text=True).stdout.splitlines()
        magick.update(available=True, version=version[0] if version else "")
    for name, cmd in (("--help", [str(exe), "--help"]), ("warps", [str(exe), "warps"])):
        results["startup"][name] = repeat(cmd, runs)
    print("\n(b) Whole commands: median wall seconds and peak RSS of the process")
    if magick["available"]:
        print(f"(c) each followed by ImageMagick's plain equivalent ({magick['version']})")
    elif with_magick:
        print("(c) ImageMagick: convert not found, skipped")
    for name, r in results["startup"].items():
        show(f"featurewarp {name}", r, runs)
    plan = [("1MP", preset, [] if preset == "stretch" else ["--cell", "4"]) for preset in PRESETS]
    plan += [("12MP", preset, []) for preset in (("swirl",) if quick else ("swirl", "bulge", "arc"))]
    plan.append(("12MP", "swirl", ["--cell", "4"]))     # stretch: liquid-rescale is a 1 MP comparison
    photo, mask = photos["1MP"]
    floor = [sys.executable, "-c", FLOOR, str(photo), str(mask), str(tmp / "floor.png"), "2"]   # 2: twice as wide
    results["floor"] = repeat(floor, runs)                  # issue 12's floor of a 1 MP stretch --sx 2
    show("1MP floor of stretch --sx 2 (imports, decode, encode)", results["floor"], runs)
    done = set()
    for size, preset, extra in plan:
        photo, mask = photos[size]
        r = repeat(ours_cmd(exe, preset, photo, mask, tmp / f"ours-{size}-{preset}.png", extra), runs)
        r.update(size=size, preset=preset, extra=extra)
        results["runs"].append(r)
        show(f"{size} featurewarp {preset} {' '.join(PRESETS[preset][0] + extra)}", r, runs)
        if magick["available"] and (size, preset) not in done:
            done.add((size, preset))
            m = repeat(magick_cmd(preset, photo, tmp / f"magick-{size}-{preset}.png"), runs)
            m.update(size=size, preset=preset)
            magick["runs"].append(m)
            show(f"{size} convert {' '.join(PRESETS[preset][1])}", m, runs)
    return results, magick


def show(label, r, runs):
    note = "" if r["runs"] == runs else f"  ({r['runs']} run{'s' if r['runs'] > 1 else ''}: slow or out of budget)"
    print(f"  {label:50s} {r['median_s']:7.3f} s  {r['peak_mb']:5d} MB{'' if r['ok'] else '  FAILED'}{note}")


def ratios(commands, magick) -> list[dict]:
    if not magick.get("available"):
        return []
    im = {(r["size"], r["preset"]): r for r in magick["runs"]}
    rows = []
    print("\nRatios, featurewarp (with mask) / ImageMagick (plain)")
    for r in commands["runs"]:
        ref = im.get((r["size"], r["preset"]))
        if ref is None:
            continue
        ratio = r["median_s"] / ref["median_s"]
        label = f"{r['size']} {r['preset']} {' '.join(r['extra'])}".strip()
        rows.append({"size": r["size"], "preset": r["preset"], "extra": r["extra"], "ours_s": r["median_s"],
                     "magick_s": ref["median_s"], "ratio": ratio, "ours_mb": r["peak_mb"],
                     "magick_mb": ref["peak_mb"]})
        print(f"  {label:30s} {r['median_s']:7.3f} s / {ref['median_s']:7.3f} s = {ratio:5.2f}x")
    return rows


def machine() -> dict:
    import scipy

    info = {"python": platform.python_version(), "numpy": np.__version__, "scipy": scipy.__version__,
            "opencv": cv2.__version__, "cpus": os.cpu_count(), "platform": platform.platform(),
            "loadavg_start": os.getloadavg()}
    from importlib import metadata

    from featurewarp_cli.engine import cholmod

    # CHOLMOD through scikit-sparse, or None: SciPy's splu fallback.
    info["scikit-sparse"] = metadata.version("scikit-sparse") if cholmod.AVAILABLE else None
    return info


def bench_photos(tmp: Path) -> dict:
    """Issue 22's photo acceptance (:mod:`benchmarks.photo_acceptance`, with its noise runs):
    how many runs, and those that broke a rule with their violations."""
    from benchmarks.photo_acceptance import main as photo_acceptance

    figures = tmp / "photo_acceptance.json"
    photo_acceptance(["--noise", "--json", str(figures)])
    rows = json.loads(figures.read_text())["rows"]
    return {"runs": sum(r["mode"] != "plain" for r in rows),
            "violations": [{k: r[k] for k in ("case", "setting", "mode", "violations")}
                           for r in rows if r.get("violations")]}


def compile_package() -> None:
    """Byte-compile the package and the bundled warps, as ``make install`` does, before anything is
    timed: a module edited since (or a shell with PYTHONDONTWRITEBYTECODE) would otherwise be
    compiled again by every command a benchmark starts, 70 ms of a 1 MP command's 0.8 s when all of
    them are (2026-11-28), which the floor, importing one small module of ours, does not pay."""
    for folder in ("featurewarp_cli", "warps"):
        compileall.compile_dir(str(ROOT / folder), quiet=1)


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--quick", action="store_true", help="3 runs, fewer sizes, 12 MP swirl only")
    parser.add_argument("--runs", type=int, help="runs per measurement (default 5; 3 with --quick)")
    parser.add_argument("--only", help=f"comma-separated sections: {','.join(SECTIONS)}")
    parser.add_argument("--budget", type=float, default=570.0,
                        help="seconds after which figures stop repeating (default 570)")
    parser.add_argument("--results", default=str(ROOT / "benchmarks" / "results"), help="output folder")
    args = parser.parse_args(argv)
    runs = args.runs or (3 if args.quick else 5)
    sections = SECTIONS if not args.only else tuple(s.strip() for s in args.only.split(","))
    unknown = set(sections) - set(SECTIONS)
    if unknown:
        parser.error(f"unknown section(s): {', '.join(sorted(unknown))}")
    exe = Path(sys.executable).parent / "featurewarp"
    if not exe.exists():
        exe = Path(shutil.which("featurewarp") or "featurewarp")

    compile_package()
    started = time.perf_counter()
    global DEADLINE
    DEADLINE = started + args.budget
    report = {"date": _dt.datetime.now().isoformat(timespec="seconds"), "runs": runs, "quick": args.quick,
              "machine": machine(), "targets": {}}
    print(f"featurewarp benchmark, {runs} runs per figure, {os.cpu_count()} cpus, "
          f"load average {report['machine']['loadavg_start'][0]:.2f}")
    with tempfile.TemporaryDirectory(prefix="featurewarp-bench-") as tmpdir:
        tmp = Path(tmpdir)
        photos = None
        if {"render", "rewarp", "deform", "drag", "commands", "hard", "floor"} & set(sections):
            photos = make_photos(ROOT / "samples", tmp)
        if "table1" in sections:
            report["table1"] = bench_table1(runs, QUICK_GRIDS if args.quick else GRIDS)
        if "render" in sections:
            report["render"] = bench_render(runs, *photos["12MP"])
        if "rewarp" in sections:
            report["rewarp"] = bench_rewarp(runs, *photos["1MP"])
        if "deform" in sections:
            from benchmarks.deform_case import bench_deform

            report["deform"] = bench_deform(runs, *photos["1MP"], median)
        if "rigid" in sections:
            from benchmarks.rigidity import bench_rigid

            report["rigid"] = bench_rigid()
        if "drag" in sections:
            from benchmarks.editor_drag import bench_drag, bench_other_photos

            report["drag"] = bench_drag(*photos["1MP"])
            report["drag_photos"] = bench_other_photos()
        if "commands" in sections:
            commands, magick = bench_commands(runs, exe, photos, tmp, args.quick, "magick" in sections)
            report["commands"], report["magick"] = commands, magick
            report["ratios"] = ratios(commands, magick)
        if "hard" in sections:
            report["hard"] = bench_hard(runs, exe, photos["12MP"][0], ROOT / "samples", tmp,
                                        "magick" in sections, repeat, show)
        if "floor" in sections:
            from benchmarks.floor_ratio import bench_floor

            report["floor"] = bench_floor(min(runs, 3), exe, photos, ROOT / "samples", tmp, repeat, show, args.quick)
        if "stability" in sections:
            from benchmarks.stability import bench_stability

            report["stability"] = bench_stability(512)
        if "machines" in sections:
            from benchmarks.machines import bench_machines

            report["machines"] = bench_machines(args.quick)
        if "photos" in sections:
            report["photos"] = bench_photos(tmp)
        if "cluster" in sections:
            from benchmarks.cluster import bench_cluster

            report["cluster"] = bench_cluster(200, min(runs, 3))
    report["targets"] = tgt.evaluate(report)
    report["machine"]["loadavg_end"] = os.getloadavg()
    report["seconds"] = time.perf_counter() - started
    tgt.print_targets(report["targets"])
    print(f"\nbenchmark took {report['seconds']:.0f} s")

    out_dir = Path(args.results)
    out_dir.mkdir(parents=True, exist_ok=True)
    stamp = _dt.datetime.now().strftime("%Y%m%d-%H%M%S")
    text = json.dumps(report, indent=2, default=float) + "\n"
    (out_dir / f"bench-{stamp}.json").write_text(text)
    (out_dir / "latest.json").write_text(text)
    print(f"results: {out_dir / f'bench-{stamp}.json'} (and latest.json)")
    return 0


if __name__ == "__main__":
    sys.exit(main())

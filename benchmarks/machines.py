"""Emulated machines (issue 21): do the libraries' run-time dispatch knobs move the gallery's pixels?

Another x86-64 machine picks other BLAS, numpy and OpenCV kernels at run time, and they may
round differently. This benchmark emulates such machines on this one through the libraries'
own environment variables, each machine in a fresh process, and compares every machine's
output with the default machine's (the first one):

* the gallery: the ``featurewarp compare`` lines of the Makefile's ``gallery`` target, run
  in a temporary directory; per picture the RMSE (grey levels of the decoded JPEGs, all
  channels, as tests/test_readme.py does), whether the bytes are equal, and the RMSE to the
  committed picture in docs/gallery (the test's limit is 0.5);
* a few of benchmarks/stability.py's cases at ``--size`` px, and :data:`PHOTO_CASES` (other
  photos): the largest node move (px) of the solved mesh and the RMSE of the rendered image.

Knobs (checked by hashing kernel outputs; ``OPENBLAS_CORETYPE`` acts on all three OpenBLAS
copies: numpy's and scipy's scipy_openblas and the system one CHOLMOD links):

``OPENBLAS_CORETYPE``, ``OPENBLAS_NUM_THREADS``
    Dense products and solves, and CHOLMOD's supernodal factorization (systems above
    solver._SIMPLICIAL_MAX unknowns); the simplicial one uses no BLAS. Unset, the CPU is
    detected (an AVX-512 CPU: SkylakeX, Cooperlake); an *empty* value is not "unset".
``NPY_DISABLE_CPU_FEATURES``
    numpy >= 2.4 dispatches the groups X86_V3 (AVX2), X86_V4 (AVX-512), AVX512_ICL,
    AVX512_SPR only; older names (AVX2, FMA3, AVX512F, AVX512_SKX) are ignored (a hidden
    ImportWarning). Without X86_V4, float64 exp, log, power, arctan2, tan, arcsin... (the
    AVX-512 SVML kernels) give other last bits; float64 sin, cos, sqrt do not.
``OPENCV_CPU_DISABLE``
    OpenCV's names (``AVX512-SKX``, ``AVX2``, ``FMA3``, ``AVX``, ``FP16``); float kernels
    (GaussianBlur) change, the 8-bit remap and resize used here do not.

Usage::

    .venv/bin/python benchmarks/machines.py [--quick] [--size 512] [--json PATH] [--keep DIR]
"""

from __future__ import annotations

import argparse
import json
import os
import shlex
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

#: Environment variables (and prefixes: every OPENBLAS_*) that select kernels; every machine
#: starts without them, so "default" is what the libraries detect on this CPU.
KNOBS = ("OPENBLAS_", "GOTO", "OMP_NUM_THREADS", "NPY_DISABLE_CPU_FEATURES", "NPY_ENABLE_CPU_FEATURES",
         "OPENCV_CPU_DISABLE")
NPY_X86_V2 = "X86_V3 X86_V4 AVX512_ICL AVX512_SPR"
#: (name, environment): the default machine first; "default-again" checks run-to-run repeatability.
MACHINES = [
    ("default", {}),
    ("default-again", {}),
    ("blas-haswell", {"OPENBLAS_CORETYPE": "Haswell"}),
    ("blas-prescott", {"OPENBLAS_CORETYPE": "Prescott"}),
    ("blas-sandybridge", {"OPENBLAS_CORETYPE": "Sandybridge"}),
    ("blas-skylakex", {"OPENBLAS_CORETYPE": "SkylakeX"}),
    ("blas-1-thread", {"OPENBLAS_NUM_THREADS": "1"}),
    ("numpy-x86-v3", {"NPY_DISABLE_CPU_FEATURES": "X86_V4 AVX512_ICL AVX512_SPR"}),
    ("numpy-x86-v2", {"NPY_DISABLE_CPU_FEATURES": NPY_X86_V2}),
    ("opencv-sse4", {"OPENCV_CPU_DISABLE": "AVX512-SKX,AVX2,FMA3,AVX,FP16"}),
    ("avx2-pc", {"OPENBLAS_CORETYPE": "Haswell", "NPY_DISABLE_CPU_FEATURES": "X86_V4 AVX512_ICL AVX512_SPR",
                 "OPENCV_CPU_DISABLE": "AVX512-SKX"}),
    ("old-pc", {"OPENBLAS_CORETYPE": "Sandybridge", "OPENBLAS_NUM_THREADS": "1",
                "NPY_DISABLE_CPU_FEATURES": NPY_X86_V2, "OPENCV_CPU_DISABLE": "AVX512-SKX,AVX2,FMA3"}),
]
QUICK_MACHINES = ("default", "blas-prescott", "numpy-x86-v3", "opencv-sse4")
#: Indices into stability.CASES: swirl rigid, arc similarity, cylinder, fish, stretch sy 2, inflate.
CASES = (0, 3, 5, 7, 8, 10)
QUICK_CASES = (0, 3)
#: Cases on other photos that once depended on the machine: (photo, mask, longest side px,
#: preset, parameters, mode). The coins under swirl 90 seemed to converge to one of two nearby
#: minima (0.02-0.12 px apart) depending on the BLAS kernel, until Newton directions were built
#: from the solve's linear part (one had left the solve's positions); before the plain bound had
#: EXACT_ENOUGH's headroom, the one Sandybridge's kernels reached was moved to W (24 px).
PHOTO_CASES = (("coins.png", "coins_mask.png", 256, "swirl", {"angle": 90}, "similarity"),)
#: The pictures --quick makes: two that an AVX2 machine moved (sphere past the limit) and two it did not.
QUICK_PICTURES = ("swirl.jpg", "shapes-swirl-grid.jpg", "squeeze.jpg", "sphere.jpg")
#: The gallery test's RMSE limit (tests/test_readme.py).
GALLERY_LIMIT = 0.5


def gallery_commands() -> list[str]:
    """The ``featurewarp compare`` lines of the Makefile's gallery target (as tests/test_readme.py)."""
    text = (ROOT / "Makefile").read_text()
    target = text[text.index("\ngallery:"):]
    return [line.strip().replace("$(BIN)/featurewarp ", "featurewarp ", 1)
            for line in target.splitlines()[1:] if line.startswith("\t$(BIN)/featurewarp compare")]


def picture_name(command: str) -> str:
    """The output file name of a gallery command."""
    return Path(shlex.split(command)[4]).name


def machine_env(overrides: dict) -> dict:
    """This process's environment without the knobs, with ``overrides`` and this checkout first on the path."""
    env = {key: value for key, value in os.environ.items() if not key.startswith(KNOBS)}
    env["PYTHONPATH"] = os.pathsep.join([str(ROOT)] + ([env["PYTHONPATH"]] if env.get("PYTHONPATH") else []))
    return {**env, **overrides}


def run_gallery(out: Path, commands: list[str]) -> None:
    """Run the gallery commands in-process in ``out`` (pictures land in out/docs/gallery)."""
    from featurewarp_cli.cli.main import main

    (out / "samples").symlink_to(ROOT / "samples")
    (out / "docs" / "gallery").mkdir(parents=True)
    os.chdir(out)
    for command in commands:
        try:
            main(shlex.split(command)[1:])
        except SystemExit as exit_:
            if exit_.code:
                raise RuntimeError(f"exit {exit_.code}: {command}") from None


def run_cases(out: Path, cases: tuple, size: int) -> None:
    """Solve and render stability cases and :data:`PHOTO_CASES`; save nodes (case<i>.npy,
    photo<i>.npy) and the images (case<i>.png, photo<i>.png)."""
    import cv2

    from benchmarks.stability import CASES as ALL
    from featurewarp_cli import FeatureWarper, load_warp

    samples = ROOT / "samples"
    image = cv2.cvtColor(cv2.imread(str(samples / "astronaut.png")), cv2.COLOR_BGR2RGB)
    image = cv2.resize(image, (size, size), interpolation=cv2.INTER_AREA)
    for index in cases:
        preset, params, mode, mask_name = ALL[index]
        mask = cv2.imread(str(samples / mask_name), cv2.IMREAD_GRAYSCALE)
        mask = cv2.resize(mask, (size, size), interpolation=cv2.INTER_NEAREST) >= 128
        warper = FeatureWarper(size, size, mask)
        mesh = warper.solve(load_warp(preset)(size, size, **params), mode)
        np.save(out / f"case{index}.npy", mesh.target)
        rendered = warper.render(image, mesh, background=(255, 255, 255))
        cv2.imwrite(str(out / f"case{index}.png"), cv2.cvtColor(rendered, cv2.COLOR_RGB2BGR))
    for index, (photo, mask_name, side, preset, params, mode) in enumerate(PHOTO_CASES):
        image, mask = (cv2.imread(str(samples / name), flag) for name, flag in
                       ((photo, cv2.IMREAD_COLOR), (mask_name, cv2.IMREAD_GRAYSCALE)))
        scale = side / max(image.shape[:2])
        dims = (round(image.shape[1] * scale), round(image.shape[0] * scale))
        image = cv2.resize(image, dims, interpolation=cv2.INTER_AREA)
        mask = cv2.resize(mask, dims, interpolation=cv2.INTER_NEAREST) >= 128
        warper = FeatureWarper(*dims, mask)
        mesh = warper.solve(load_warp(preset)(*dims, **params), mode)
        np.save(out / f"photo{index}.npy", mesh.target)
        cv2.imwrite(str(out / f"photo{index}.png"), warper.render(image, mesh, background=(255, 255, 255)))


def fingerprint() -> dict:
    """Hashes of kernels each knob switches (shows that a machine's knobs took effect)."""
    import hashlib

    import cv2
    import scipy.sparse as sp

    from featurewarp_cli.engine.solver import spd_solver

    rng = np.random.default_rng(0)
    a, x = rng.standard_normal((400, 400)), rng.uniform(-5, 5, 100_003)
    t = sp.diags([-1, 2.0001, -1], [-1, 0, 1], shape=(640, 640))
    grid = (sp.kron(t, sp.identity(640)) + sp.kron(sp.identity(640), t)).tocsc()   # 410 k: supernodal
    image = rng.uniform(0, 255, (300, 400)).astype(np.float32)
    made = {"numpy matmul": a @ a.T, "numpy linalg.solve": np.linalg.solve(a, a[:, :3]), "numpy exp": np.exp(x),
            "numpy arctan2": np.arctan2(x, x[::-1]),
            "CHOLMOD supernodal": spd_solver(grid)(rng.standard_normal((grid.shape[0], 2))),
            "OpenCV GaussianBlur f32": cv2.GaussianBlur(image, (0, 0), 2.3)}
    return {key: hashlib.sha1(np.ascontiguousarray(v).tobytes()).hexdigest()[:12] for key, v in made.items()}


def worker(out: Path, pictures: list[str], cases: tuple, size: int) -> None:
    """The body of one machine's process (``--worker``): kernel hashes, the cases, the gallery."""
    sys.path.insert(0, str(ROOT))
    (out / "fingerprint.json").write_text(json.dumps(fingerprint()))
    run_cases(out, cases, size)
    run_gallery(out, [c for c in gallery_commands() if picture_name(c) in pictures])


def run_machine(name: str, overrides: dict, out: Path, args) -> float:
    """Run one machine in a subprocess writing to ``out``; its wall time (s)."""
    out.mkdir(parents=True)
    command = [sys.executable, str(Path(__file__).resolve()), "--worker", str(out), "--size", str(args.size),
               "--pictures", ",".join(args.pictures), "--cases", ",".join(map(str, args.cases))]
    start = time.perf_counter()
    with open(out / "stderr.txt", "w") as log:
        done = subprocess.run(command, env=machine_env(overrides), stderr=log, stdout=log, cwd=out)
    if done.returncode:
        raise RuntimeError(f"machine {name} failed; see {out / 'stderr.txt'}")
    return time.perf_counter() - start


def rmse(a: Path, b: Path) -> float:
    """RMSE (grey levels, all channels) between two decoded images; inf when their shapes differ."""
    import cv2

    x, y = cv2.imread(str(a)).astype(float), cv2.imread(str(b)).astype(float)
    return float(np.sqrt(np.mean((x - y) ** 2))) if x.shape == y.shape else float("inf")


def compare_gallery(base: Path, other: Path, names: list[str]) -> list[dict]:
    """Per picture: RMSE and byte equality to the default machine, RMSE to the committed picture."""
    rows = []
    for name in names:
        mine, theirs = other / "docs" / "gallery" / name, base / "docs" / "gallery" / name
        rows.append({"picture": name, "rmse": rmse(theirs, mine),
                     "same_bytes": mine.read_bytes() == theirs.read_bytes(),
                     "rmse_committed": rmse(ROOT / "docs" / "gallery" / name, mine)})
    return rows


def compare_cases(base: Path, other: Path, cases: tuple) -> list[dict]:
    """Per stability case and photo case: largest node move (px), image RMSE and whether the nodes
    are bit-equal."""
    from benchmarks.stability import CASES as ALL

    named = [(f"case{index}", "{} {} {} {}".format(index, *ALL[index][:3])) for index in cases]
    named += [(f"photo{index}", f"photo{index} {case[0][:-4]} {case[3]} {case[4]} {case[5]}")
              for index, case in enumerate(PHOTO_CASES)]
    rows = []
    for stem, label in named:
        nodes, base_nodes = np.load(other / f"{stem}.npy"), np.load(base / f"{stem}.npy")
        move = float(np.abs(nodes - base_nodes).max()) if nodes.shape == base_nodes.shape else float("inf")
        rows.append({"case": label, "node_move_px": move,
                     "same_nodes": bool(nodes.shape == base_nodes.shape and np.array_equal(nodes, base_nodes)),
                     "rmse": rmse(base / f"{stem}.png", other / f"{stem}.png")})
    return rows


def print_table(results: list[dict]) -> None:
    """Per machine: what differs from the default machine, then one summary line per machine."""
    for result in results:
        moved = [r for r in result["gallery"] if not r["same_bytes"]]
        cases = [r for r in result["cases"] if not r["same_nodes"]]
        print(f"\n{result['machine']}: {result['env'] or '(no knobs)'}; kernels with other bits: "
              f"{', '.join(result['kernels_changed']) or 'none'}")
        for r in moved:
            print(f"    {r['picture']:28s} RMSE vs default {r['rmse']:7.3f}   vs committed {r['rmse_committed']:7.3f}")
        for r in cases:
            print(f"    case {r['case'][:44]:44s} node move {r['node_move_px']:9.3g} px  RMSE {r['rmse']:6.3f}")
    print(f"\n{'machine':18s} {'s':>4s} {'pictures moved':>14s} {'worst RMSE':>10s} {f'> {GALLERY_LIMIT:g} vs committed':>16s} "
          f"{'cases moved':>11s} {'worst move px':>13s} {'worst RMSE':>10s}")
    for result in results:
        gallery, cases = result["gallery"], result["cases"]
        over = [r["picture"] for r in gallery if r["rmse_committed"] > GALLERY_LIMIT]
        print(f"{result['machine']:18s} {result['seconds']:4.0f} "
              f"{sum(not r['same_bytes'] for r in gallery):7d} of {len(gallery):3d} "
              f"{max((r['rmse'] for r in gallery), default=0):10.3f} {', '.join(over) or '-':>16s} "
              f"{sum(not r['same_nodes'] for r in cases):6d} of {len(cases)} "
              f"{max((r['node_move_px'] for r in cases), default=0):13.3g} "
              f"{max((r['rmse'] for r in cases), default=0):10.3f}")


def parse(argv):
    """Command-line arguments (``--worker`` is the internal per-machine mode)."""
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--quick", action="store_true", help="4 machines, 4 pictures, 2 cases")
    parser.add_argument("--size", type=int, default=512)
    parser.add_argument("--json", type=Path)
    parser.add_argument("--keep", type=Path, help="keep every machine's outputs in this (new) directory")
    parser.add_argument("--machines", help="comma-separated names from MACHINES (default first)")
    parser.add_argument("--worker", type=Path, help=argparse.SUPPRESS)
    parser.add_argument("--pictures", help=argparse.SUPPRESS)
    parser.add_argument("--cases", help=argparse.SUPPRESS)
    args = parser.parse_args(argv)
    every = [picture_name(c) for c in gallery_commands()]
    args.pictures = (args.pictures.split(",") if args.pictures is not None
                     else [p for p in every if p in QUICK_PICTURES] if args.quick else every)
    args.cases = (tuple(int(c) for c in args.cases.split(",") if c) if args.cases is not None
                  else QUICK_CASES if args.quick else CASES)
    return args


def bench_machines(quick: bool = False) -> dict:
    """``make bench`` section ``machines``: the summary :func:`main` writes with ``--json``."""
    with tempfile.TemporaryDirectory(prefix="machines-json-") as scratch:
        path = Path(scratch) / "machines.json"
        main((["--quick"] if quick else []) + ["--json", str(path)])
        return json.loads(path.read_text())


def main(argv=None) -> int:
    """Run every emulated machine (or ``--worker``: one machine's outputs); print the table."""
    args = parse(argv)
    if args.worker:
        worker(args.worker, args.pictures, args.cases, args.size)
        return 0
    wanted = args.machines.split(",") if args.machines else QUICK_MACHINES if args.quick else [m for m, _ in MACHINES]
    machines = [(name, env) for name, env in MACHINES if name in wanted]
    names = args.pictures
    start = time.perf_counter()
    with tempfile.TemporaryDirectory(prefix="machines-") as scratch:
        top = args.keep or Path(scratch)
        results = []
        for index, (name, overrides) in enumerate(machines):
            seconds = run_machine(name, overrides, top / name, args)
            print(f"{name}: {seconds:.0f} s", file=sys.stderr, flush=True)
            base = top / machines[0][0]
            prints = [json.loads((top / m / "fingerprint.json").read_text()) for m in (machines[0][0], name)]
            results.append({"machine": name, "env": overrides, "seconds": seconds,
                            "kernels_changed": [k for k in prints[0] if prints[0][k] != prints[1][k]],
                            "gallery": compare_gallery(base, top / name, names),
                            "cases": compare_cases(base, top / name, args.cases)})
    dropped = {key: value for key, value in os.environ.items() if key.startswith(KNOBS)}
    print(f"\nknobs set here and dropped for every machine: {dropped or 'none'}")
    print(f"Emulated machines vs {machines[0][0]}: {len(names)} gallery pictures, "
          f"stability cases {list(args.cases)} at {args.size} px, {len(PHOTO_CASES)} on other photos")
    print_table(results)
    total = time.perf_counter() - start
    print(f"\nwall time {total:.0f} s")
    if args.json:
        summary = {"size": args.size, "dropped_env": dropped, "wall_seconds": total, "results": results}
        args.json.write_text(json.dumps(summary, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())

"""``make bench`` section ``cluster`` (issue 25): a batch on 2 local Dask workers against ``batch -j 2``
and ``make -j 2``.

200 images of 1 MP (the astronaut upscaled, each shifted a little, with its mask), swirl 120.
Three ways on two cores, interleaved run by run so that they see the same load:

- ``featurewarp batch ... -j 2`` (two local worker processes);
- ``featurewarp batch ... --scheduler local:2`` (a local Dask cluster of two workers,
  started by the command, so its start-up is counted);
- ``make -j 2`` of one ``featurewarp warp`` per image (one process per image).

The overhead of each is its wall time over the fastest of the three, minus 1 (target: Dask
within 15 %).

Usage::

    .venv/bin/python benchmarks/cluster.py [--images 200] [--runs 3]
"""

from __future__ import annotations

import argparse
import shutil
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import cv2
import numpy as np

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

from benchmarks.inputs import SIZES, upscale_mask  # noqa: E402

CLUSTER_OVERHEAD = 0.15


def make_images(folder: Path, count: int) -> list[Path]:
    """``count`` 1 MP photos with masks named ``{stem}_mask.png``."""
    w, h = SIZES["1MP"]
    photo = cv2.resize(cv2.imread(str(ROOT / "samples" / "astronaut.png")), (w, h), interpolation=cv2.INTER_CUBIC)
    mask_path = upscale_mask(ROOT / "samples" / "astronaut_mask.png", (w, h), folder / "mask.png")
    mask = cv2.imread(str(mask_path), cv2.IMREAD_GRAYSCALE)
    paths = []
    for i in range(count):
        path = folder / f"p{i:03d}.png"
        cv2.imwrite(str(path), np.roll(photo, i, axis=1))
        cv2.imwrite(str(folder / f"p{i:03d}_mask.png"), np.roll(mask, i, axis=1))
        paths.append(path)
    mask_path.unlink()
    return paths


def makefile(exe: Path, images: list[Path], out: Path) -> str:
    targets = " ".join(str(out / p.name) for p in images)
    return (f"all: {targets}\n{out}/%.png: {images[0].parent}/%.png\n"
            f"\t@{exe} warp swirl $< $@ -m $(<D)/$*_mask.png --angle 120 -q\n")


def bench_cluster(count: int = 200, runs: int = 3) -> dict:
    exe = Path(sys.executable).parent / "featurewarp"
    ways = {}
    with tempfile.TemporaryDirectory(prefix="featurewarp-cluster-") as tmpdir:
        tmp = Path(tmpdir)
        (tmp / "in").mkdir()
        images = make_images(tmp / "in", count)
        common = ["batch", "swirl", *map(str, images), "--angle", "120", "-q"]
        (tmp / "Makefile").write_text(makefile(exe, images, tmp / "out"))
        commands = {
            "batch -j 2": [str(exe), *common, "--out-dir", str(tmp / "out"), "-j", "2"],
            "batch --scheduler local:2": [str(exe), *common, "--out-dir", str(tmp / "out"), "--scheduler", "local:2"],
            "make -j 2": ["make", "-s", "-j", "2", "-f", str(tmp / "Makefile")],
        }
        for _ in range(runs):
            for name, cmd in commands.items():
                shutil.rmtree(tmp / "out", ignore_errors=True)
                (tmp / "out").mkdir()
                t0 = time.perf_counter()
                code = subprocess.run(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE).returncode
                ways.setdefault(name, []).append(time.perf_counter() - t0)
                if code != 0:
                    sys.stderr.write(f"bench cluster: {name} failed ({code})\n")
    medians = {name: statistics.median(seconds) for name, seconds in ways.items()}
    best = min(medians.values())
    print(f"\nCluster: {count} images of 1 MP, swirl 120, 2 workers, medians of {runs}")
    for name, seconds in medians.items():
        print(f"  {name:28s} {seconds:7.1f} s   overhead {100 * (seconds / best - 1):5.1f} %")
    return {"images": count, "runs": runs, "seconds": ways, "median_s": medians,
            "dask_overhead": medians["batch --scheduler local:2"] / best - 1.0}


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--images", type=int, default=200)
    parser.add_argument("--runs", type=int, default=3)
    args = parser.parse_args(argv)
    bench_cluster(args.images, args.runs)
    return 0


if __name__ == "__main__":
    sys.exit(main())

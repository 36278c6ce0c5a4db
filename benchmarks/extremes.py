"""Every built-in preset at the ends of its declared ranges (issue 15): seconds, peak memory,
folded triangles, on a 320x240 photo with a mask and on 1x5000 and 5000x1 images.

    python benchmarks/extremes.py            # a table; a row fails when a run takes over 60 s,
                                             # 2 GB, leaves folds, or fails other than by a
                                             # one-line refusal
"""

from __future__ import annotations

import json
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import cv2
import numpy as np

ROOT = Path(__file__).resolve().parent.parent
CASES = ["stretch --sx 100", "stretch --sy 100", "stretch --sx 100 --sy 100", "stretch --sx 0.001",
         "stretch --sx 0.01 --sy 100", "stretch --width 65535", "arc --angle 360", "arc --angle 0.001",
         "bulge --strength 2.95", "bulge --strength -0.95", "bulge --strength 2.95 --radius 10",
         "bulge --strength 2.95 --radius 0.001", "swirl --angle 720", "swirl --angle -720",
         "swirl --angle 720 --radius 10", "swirl --angle 720 --radius 0.001"]
# The design tools' styles and the wraps (issue 14): each range's ends, combined.
CASES += [f"{style} --bend {b} --hdistort {d} --vdistort {d}" for style in
          ("arch", "flag", "fish", "rise", "inflate", "squeeze", "shell") for b, d in ((100, 90), (-100, -90))]
CASES += ["flag --waves 12 --bend 100", "shell --side upper --bend 100", "arc --where lower --angle 170",
          "arc --where upper --angle 170", "perspective --tl 45%,45%", "cylinder --angle 160",
          "cylinder --angle 160 --axis horizontal", "cylinder --angle 1 --distance 1.001", "sphere --angle 120",
          "sphere --angle 1 --distance 1.001"]
MEASURE = ("import resource, subprocess, sys; r = subprocess.run(sys.argv[1:]); "
           "print(resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss, file=sys.stderr); sys.exit(r.returncode)")


def images(folder: Path) -> list[tuple[Path, Path]]:
    photo = cv2.resize(cv2.imread(str(ROOT / "samples" / "astronaut.png")), (320, 240))
    mask = np.zeros((240, 320), np.uint8)
    cv2.circle(mask, (160, 120), 40, 255, -1)
    cv2.rectangle(mask, (10, 10), (60, 60), 255, -1)
    cv2.circle(mask, (300, 230), 30, 255, -1)                 # cut by the frame
    pairs = [(photo, mask)]
    for w, h in ((1, 5000), (5000, 1)):
        strip_mask = np.zeros((h, w), np.uint8)
        strip_mask[: h // 2 + 1, : w // 2 + 1] = 255
        pairs.append((np.random.default_rng(0).integers(0, 255, (h, w, 3), np.uint8), strip_mask))
    out = []
    for image, mask in pairs:
        name = f"{image.shape[1]}x{image.shape[0]}"
        cv2.imwrite(str(folder / f"{name}.png"), image)
        cv2.imwrite(str(folder / f"{name}_mask.png"), mask)
        out.append((folder / f"{name}.png", folder / f"{name}_mask.png"))
    return out


def main() -> int:
    failures = 0
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp)
        for image, mask in images(folder):
            for case in CASES:
                preset, *args = case.split()
                command = [sys.executable, "-c", MEASURE, sys.executable, "-m", "featurewarp_cli", "warp", preset,
                           str(image), str(folder / "out.png"), "-m", str(mask), "--report", str(folder / "r.json"),
                           "-q", *args]
                t0 = time.perf_counter()
                run = subprocess.run(command, capture_output=True, text=True, timeout=600)
                seconds = time.perf_counter() - t0
                *lines, peak = run.stderr.strip().split("\n")
                flips = json.loads((folder / "r.json").read_text())["flipped_triangles"] if run.returncode == 0 else None
                (folder / "r.json").unlink(missing_ok=True)
                refused = run.returncode in (1, 2) and len(lines) == 1
                ok = seconds < 60 and int(peak) < 2 * 2**20 and (flips == 0 or (flips is None and refused))
                failures += not ok
                print(f"{image.stem:>9} {case:<48} {seconds:6.2f} s {int(peak) / 1024:7.0f} MB "
                      f"{'folds ' + str(flips) if flips is not None else 'refused: ' + (lines[0] if lines else '?')}"
                      f"{'' if ok else '   <-- FAILS'}")
    print(f"{failures} failing rows")
    return int(failures > 0)


if __name__ == "__main__":
    sys.exit(main())

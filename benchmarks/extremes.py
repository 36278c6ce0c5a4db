"""Every built-in preset at the ends of its declared ranges (issues 15 and 24): CPU seconds,
peak memory, folded triangles, on a 320x240 photo with a mask and on 1x5000 and 5000x1 images,
or on 1 MP photos with three kinds of mask.

    python benchmarks/extremes.py            # a table; a row fails when a run takes over 60 s,
                                             # 2 GB, leaves folds, or fails other than by a
                                             # one-line refusal
    python benchmarks/extremes.py --1mp      # README's bound: 30 s CPU at 1 MP, which every row
                                             # keeps (README, Limits: the slowest 22.5 s)
                                             # (1024x1024 and 1155x866), the slowest rows last
"""

from __future__ import annotations

import json
import subprocess
import sys
import tempfile
from pathlib import Path

import cv2
import numpy as np

ROOT = Path(__file__).resolve().parent.parent
CASES = ["stretch --sx 100", "stretch --sy 100", "stretch --sx 100 --sy 100", "stretch --sx 0.001",
         "stretch --sx 0.01 --sy 100", "stretch --width 65535", "arc --angle 360", "arc --angle 0.001",
         "bulge --strength 2.95", "bulge --strength -0.95", "bulge --strength 2.95 --radius 10",
         "bulge --strength 2.95 --radius 0.001", "swirl --angle 540", "swirl --angle -540",
         "swirl --angle 540 --radius 10", "swirl --angle 540 --radius 0.001", "swirl --angle 90 --radius 0.001"]
# The design tools' styles and the wraps (issue 14): each range's ends, combined.
CASES += [f"{style} --bend {b} --hdistort {d} --vdistort {d}" for style in
          ("arch", "flag", "fish", "rise", "inflate", "squeeze", "shell") for b, d in ((100, 90), (-100, -90))]
CASES += ["flag --waves 12 --bend 100", "shell --side upper --bend 100", "arc --where lower --angle 150",
          "arc --where upper --angle 150", "arc --where upper --angle 151", "perspective --tl 43%,43%",
          "perspective --tl 45%,45%",
          "cylinder --angle 160", "cylinder --angle 160 --axis horizontal", "cylinder --angle 1 --distance 1.001",
          "sphere --angle 120", "sphere --angle 1 --distance 1.001"]
# The tightest swirl each angle allows at 1 MP (warps/swirl.py), and the corners of perspective.
CASES_1MP = CASES + [f"swirl --angle {a} --radius {r}" for a, r in ((540, 0.221), (-540, 0.221), (360, 0.1),
                                                                      (180, 0.025), (90, 0.0073))]
CASES_1MP += ["perspective --tl 0%,0% --tr 100%,45% --br 100%,55% --bl 0%,100%",
              "perspective --tl 0%,50% --tr 80%,45.8% --br 100%,50% --bl 80%,54.2%",
              "stretch --sx 100 --sy 0.01", "stretch --size 65535x1"]
MEASURE = ("import resource, subprocess, sys; r = subprocess.run(sys.argv[1:]); "
           "u = resource.getrusage(resource.RUSAGE_CHILDREN); "
           "print(u.ru_utime + u.ru_stime, u.ru_maxrss, file=sys.stderr); sys.exit(r.returncode)")


def megapixel_images(folder: Path) -> list[tuple[Path, Path]]:
    """The astronaut at 1024x1024 and 1155x866 with its mask, with 0.2 % random specks, and with
    a ring of 36 squares around the centre (features where a swirl turns most)."""
    photo = cv2.imread(str(ROOT / "samples" / "astronaut.png"))
    portrait = cv2.imread(str(ROOT / "samples" / "astronaut_mask.png"), cv2.IMREAD_GRAYSCALE)
    out = []
    for w, h in ((1024, 1024), (1155, 866)):
        ring = np.zeros((h, w), np.uint8)
        for angle in np.linspace(0, 2 * np.pi, 12, endpoint=False):
            for r in (0.06, 0.15, 0.3):
                x, y = int(w / 2 + r * h * np.cos(angle)), int(h / 2 + r * h * np.sin(angle))
                ring[y - 15:y + 15, x - 15:x + 15] = 255
        specks = ((np.random.default_rng(5).random((h, w)) < 0.002) * 255).astype(np.uint8)
        cv2.imwrite(str(folder / f"{w}x{h}.png"), cv2.resize(photo, (w, h), interpolation=cv2.INTER_CUBIC))
        for name, mask in (("portrait", cv2.resize(portrait, (w, h), interpolation=cv2.INTER_NEAREST)),
                           ("specks", specks), ("ring", ring)):
            cv2.imwrite(str(folder / f"{w}x{h}_{name}.png"), mask)
            out.append((folder / f"{w}x{h}.png", folder / f"{w}x{h}_{name}.png"))
    return out


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
    megapixel = "--1mp" in sys.argv[1:]
    limit = 30.0 if megapixel else 60.0
    failures, rows = 0, []
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp)
        for image, mask in (megapixel_images if megapixel else images)(folder):
            for case in CASES_1MP if megapixel else CASES:
                preset, *args = case.split()
                command = [sys.executable, "-c", MEASURE, sys.executable, "-m", "featurewarp_cli", "warp", preset,
                           str(image), str(folder / "out.png"), "-m", str(mask), "--report", str(folder / "r.json"),
                           "-q", *args]
                run = subprocess.run(command, capture_output=True, text=True, timeout=600)
                *lines, last = run.stderr.strip().split("\n")
                seconds, peak = float(last.split()[0]), int(last.split()[1])
                flips = json.loads((folder / "r.json").read_text())["flipped_triangles"] if run.returncode == 0 else None
                (folder / "r.json").unlink(missing_ok=True)
                refused = run.returncode in (1, 2) and len(lines) == 1
                ok = seconds < limit and peak < 2 * 2**20 and (flips == 0 or (flips is None and refused))
                failures += not ok
                outcome = f"folds {flips}" if flips is not None else f"refused: {lines[0] if lines else '?'}"
                rows.append((seconds, f"{mask.stem:>18} {case:<60} {seconds:6.2f} s CPU {peak / 1024:7.0f} MB "
                                      f"{outcome}{'' if ok else '   <-- FAILS'}"))
                print(rows[-1][1], flush=True)
    print("slowest:")
    for _, row in sorted(rows)[-5:]:
        print(row)
    print(f"{failures} failing rows")
    return int(failures > 0)


if __name__ == "__main__":
    sys.exit(main())

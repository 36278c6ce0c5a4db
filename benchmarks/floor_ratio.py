"""``make bench``'s floor section (issue 21): every preset at its defaults, whole command, against its floor.

The floor is what any command on the same files must spend: a process that starts the
interpreter, imports the design card's packages, decodes the photo and the mask and encodes
an image of the photo's size with the tool's own PNG settings. Each preset runs at its
defaults (automatic cell) on the 1 MP and 12 MP photos of :mod:`benchmarks.inputs` with two
head + object masks: the astronaut's own (head, patch, shuttle) and the head + helmet mask of
:mod:`benchmarks.hard_cases` (the helmet cut by two edges: where a preset bends the edges it
gives way, and the never-worse-than-plain step works). Issue 21's target: at most
:data:`benchmarks.targets.FLOOR_RATIO` times the floor.

The floor is sampled again before each preset's runs, and every ratio divides by the median
of all the floor's samples at that size: on a shared 2-core machine the floor's runs at the
start of a section once came out at 0.435 s and, 20 minutes earlier, at 0.613 s, with the
presets' own times unchanged, moving every 1 MP ratio by up to 0.9.
"""

from __future__ import annotations

import statistics
import sys
from pathlib import Path

from benchmarks.inputs import SIZES, upscale_mask

PRESETS = ("arc", "arch", "bulge", "cylinder", "fish", "flag", "inflate", "perspective", "rise", "shell",
           "sphere", "squeeze", "stretch", "swirl")
HELMET = "astronaut_helmet_mask.png"          # the own mask comes with the photos (inputs.make_photos)

#: The floor process: imports, decode of both files, encode of an image of the photo's size
#: (argv: photo, mask, output, and optionally how many times wider the output is).
FLOOR = """
import sys
import numpy, scipy.sparse, sksparse.cholmod, cv2, click
from featurewarp_cli.io.encode import encode_image
image = cv2.imdecode(numpy.fromfile(sys.argv[1], numpy.uint8), cv2.IMREAD_UNCHANGED)
mask = cv2.imdecode(numpy.fromfile(sys.argv[2], numpy.uint8), cv2.IMREAD_UNCHANGED)
wider = int(sys.argv[4]) if len(sys.argv) > 4 else 1
out = cv2.resize(image, (wider * image.shape[1], image.shape[0]), interpolation=cv2.INTER_NEAREST)
open(sys.argv[3], "wb").write(encode_image(out, "png"))
"""


def bench_floor(runs: int, exe: Path, photos: dict, samples: Path, tmp: Path, repeat, show, quick=False) -> dict:
    """Run the floor and every preset with both masks at each size (``quick``: 1 MP only); a
    command that fails counts as infinitely slow. ``repeat(cmd, runs)`` and ``show(label,
    result, runs)`` come from run.py.

    Returns
    -------
    dict
        size -> {"floor": result (its ``seconds`` every sample, ``median_s`` theirs), "runs":
        [result with preset, mask, ratio]}.
    """
    print("\n(f) Every preset at its defaults against its floor (imports, decode, encode), "
          "median wall seconds")
    report = {}
    for size, (photo, own) in photos.items():       # own: the astronaut's mask at that size
        if quick and size != "1MP":
            continue
        masks = {"own": own, "helmet": upscale_mask(samples / HELMET, SIZES[size],
                                                     tmp / f"floor-mask-{size}-helmet.png")}
        floor_cmd = [sys.executable, "-c", FLOOR, str(photo), str(masks["own"]), str(tmp / "floor.png")]
        floor = repeat(floor_cmd, runs)
        rows = []
        for preset in PRESETS:
            for name, mask in masks.items():
                sample = repeat(floor_cmd, 1)                              # sampled all along the section
                floor.update(seconds=floor["seconds"] + sample["seconds"], ok=floor["ok"] and sample["ok"],
                             peak_mb=max(floor["peak_mb"], sample["peak_mb"]))
                r = repeat([str(exe), "warp", preset, str(photo), str(tmp / f"floor-{preset}.png"),
                            "--mask", str(mask), "-q"], runs)
                r.update(preset=preset, mask=name)
                rows.append(r)
        floor.update(runs=len(floor["seconds"]), median_s=statistics.median(floor["seconds"]))
        show(f"{size} floor, median of {floor['runs']} samples along the section", floor, floor["runs"])
        for r in rows:
            r["ratio"] = r["median_s"] / floor["median_s"] if r["ok"] else float("inf")
            show(f"{size} {r['preset']} ({r['mask']} mask): {r['ratio']:4.1f}x the floor", r, runs)
        report[size] = {"floor": floor, "runs": rows}
    return report

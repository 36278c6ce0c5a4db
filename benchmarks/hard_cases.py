"""``make bench``'s hard cases (issue 10): a 12 MP portrait whose mask makes the fold guard work.

The 12 MP photo of :mod:`benchmarks.run` (samples/astronaut.png upscaled to 4000x3000)
with samples/astronaut_helmet_mask.png upscaled alike: her head and the helmet she
holds, 22 % of the frame, the helmet cut by the bottom and right edges. The bench's
own mask (head, patch, shuttle) barely folds under these warps; this one does
(swirl 180: some 2 000 flipped triangles before the guard, about 20 Newton steps in its window).

Each featurewarp command (whole process: wall seconds, peak RSS, and its --report's
guard figures and stage seconds) runs right before ImageMagick's counterpart on the
same file, so both see the same load.
"""

from __future__ import annotations

import json
import shutil
from pathlib import Path

from benchmarks.inputs import SIZES, upscale_mask

#: preset -> (our options, ImageMagick's operation): the warps at their hard settings.
HARD = {
    "swirl": (["--angle", "180"], ["-swirl", "180"]),      # one sign, one direction of turn (issue 25)
    "arc": (["--angle", "300"], ["-distort", "Arc", "300"]),
    "bulge": (["--strength", "2.95"], ["-implode", "-2.95"]),      # the range's limit
}
MASK = "astronaut_helmet_mask.png"


def guard_figures(report_path: Path) -> dict:
    """The fold guard's work and the stage seconds from a --report file (empty if absent)."""
    try:
        report = json.loads(report_path.read_text())
    except (OSError, ValueError):
        return {}
    guard = report.get("fold_guard", {})
    return {"flipped_before": guard.get("flipped_before"), "untangle_iterations": guard.get("untangle_iterations"),
            "release_rounds": guard.get("release_rounds"), "feature_blend": guard.get("feature_blend"),
            "features_kept": report.get("features_kept"), "seconds": report.get("seconds")}


def bench_hard(runs: int, exe: Path, photo: Path, samples: Path, tmp: Path, with_magick: bool,
               repeat, show) -> dict:
    """Run the hard cases; ``repeat(cmd, runs)`` and ``show(label, result, runs)`` come from run.py.

    Returns
    -------
    dict
        ``mask``, ``runs`` (ours, with guard figures), ``magick`` and ``ratios``.
    """
    mask = upscale_mask(samples / MASK, SIZES["12MP"], tmp / "mask-12MP-portrait.png")
    magick = with_magick and shutil.which("convert") is not None
    result = {"mask": MASK, "runs": [], "magick": [], "ratios": []}
    print(f"\n(d) Hard cases: 12 MP portrait, head + helmet mask ({MASK}), median wall seconds, peak RSS"
          + ("; each followed by ImageMagick" if magick else ""))
    for preset, (ours_args, magick_args) in HARD.items():
        report = tmp / f"hard-{preset}.json"
        ours = repeat([str(exe), "warp", preset, str(photo), str(tmp / f"hard-{preset}.png"), "--mask", str(mask),
                       *ours_args, "--report", str(report)], runs)
        ours.update(preset=preset, extra=ours_args, guard=guard_figures(report))
        result["runs"].append(ours)
        show(f"12MP portrait featurewarp {preset} {' '.join(ours_args)}", ours, runs)
        g = ours["guard"]
        if g:
            print(f"    guard: {g['flipped_before']} flipped before, {g['untangle_iterations']} window steps, "
                  f"{g['release_rounds']} release rounds, feature blend {g['feature_blend']}")
        if magick:
            theirs = repeat(["convert", str(photo), *magick_args, str(tmp / f"hard-magick-{preset}.png")], runs)
            theirs.update(preset=preset)
            result["magick"].append(theirs)
            show(f"12MP portrait convert {' '.join(magick_args)}", theirs, runs)
            result["ratios"].append({"preset": preset, "ours_s": ours["median_s"], "magick_s": theirs["median_s"],
                                     "ratio": ours["median_s"] / theirs["median_s"], "ours_mb": ours["peak_mb"],
                                     "magick_mb": theirs["peak_mb"]})
    for r in result["ratios"]:
        print(f"  ratio 12MP portrait {r['preset']:6s} {r['ours_s']:7.3f} s / {r['magick_s']:7.3f} s "
              f"= {r['ratio']:5.2f}x")
    return result

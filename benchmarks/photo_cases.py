"""Issue 10's real-photo cases, measured on the output images.

Runs ``featurewarp warp`` on the two real-photo samples of issue 10 and prints one row
per run, then writes everything to JSON:

* portrait  samples/astronaut.png with astronaut_body_mask.png (head and body, one
            component cut by the bottom and left edges): stretch --sy 2, --sy 1.5,
            --sx 2, --sx 0.6, in similarity, rigid and plain mode;
* close-up  samples/closeup.png with closeup_mask.png (81 % of the frame): swirl
            --angle 180 (and 120, 240), arc --angle 300, similarity, rigid and plain.

Per run: exit status, seconds, warnings (stderr), and from the output image
(:mod:`featurewarp_cli.app.measure`, a keypoint affine fit input -> output) each mask
component's distortion sigma_max/sigma_min - 1, scale and rotation, beside the plain
warp's; the same for a "face" probe (an ellipse over the face, measured alone). From
``--save-grid``: the largest background area ratio, a background triangle's area on
the canvas over its area under the preset W (a triangle is background when its
bounding box holds no mask pixel). From ``--report``: the fold guard's figures, and
each component's reported distortion when the report has one.

Usage (from the repository; the package of this checkout runs unless --exe is given)::

    .venv/bin/python benchmarks/photo_cases.py [--exe PATH] [--only portrait|closeup]
        [--panels DIR] [--json PATH]

``--panels DIR`` writes, for each run, input with the mask tinted | plain | result.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

import cv2  # noqa: E402
import numpy as np  # noqa: E402

from featurewarp_cli import load_warp  # noqa: E402
from featurewarp_cli.app import measure  # noqa: E402
from featurewarp_cli.app.panel import as_bgr8, tint  # noqa: E402

#: sample -> (image, mask, face probe as an ellipse (centre x, centre y, half axes x, y)).
SAMPLES = {
    "portrait": ("astronaut.png", "astronaut_body_mask.png", (224, 112, 44, 58)),
    "closeup": ("closeup.png", "closeup_mask.png", (168, 208, 88, 116)),
}
MODES = ("similarity", "rigid", "plain")
#: (sample, preset, preset options); each runs in every mode of MODES.
CASES = [
    ("portrait", "stretch", {"sy": 2}),
    ("portrait", "stretch", {"sy": 1.5}),
    ("portrait", "stretch", {"sx": 2}),
    ("portrait", "stretch", {"sx": 0.6}),
    ("closeup", "swirl", {"angle": 180}),
    ("closeup", "swirl", {"angle": 120}),
    ("closeup", "swirl", {"angle": 240}),
    ("closeup", "arc", {"angle": 300}),
]


def options(params: dict) -> list[str]:
    """Command-line options of a preset's parameters: {'sy': 2} -> ['--sy', '2']."""
    return [part for name, value in params.items() for part in (f"--{name}", f"{value:g}")]


def case_name(sample: str, preset: str, params: dict) -> str:
    return f"{sample} {preset} {' '.join(options(params))}"


def run_warp(exe: list[str], sample: str, preset: str, params: dict, mode: str, folder: Path) -> dict:
    """One ``featurewarp warp`` run with --report and --save-grid; its outcome and file paths."""
    image, mask, _ = SAMPLES[sample]
    stem = folder / f"{sample}-{preset}-{'-'.join(options(params)).replace('--', '')}-{mode}"
    paths = {"output": f"{stem}.png", "report_path": f"{stem}.json", "grid": f"{stem}.npz"}
    cmd = [*exe, "warp", preset, str(ROOT / "samples" / image), paths["output"], "--mask",
           str(ROOT / "samples" / mask), "--mode", mode, "--report", paths["report_path"],
           "--save-grid", paths["grid"], *options(params)]
    env = dict(os.environ, PYTHONPATH=str(ROOT))
    t0 = time.perf_counter()
    proc = subprocess.run(cmd, capture_output=True, text=True, env=env)
    seconds = time.perf_counter() - t0
    report = None
    if proc.returncode == 0 and os.path.exists(paths["report_path"]):
        report = json.loads(Path(paths["report_path"]).read_text())
    return {"exit": proc.returncode, "seconds": seconds, "stderr": proc.stderr.strip().splitlines(),
            "report": report, **paths}


def face_probe(shape, ellipse) -> np.ndarray:
    """A boolean mask of the face ellipse (centre x, y, half axes) on an image of ``shape``."""
    probe = np.zeros(shape[:2], np.uint8)
    cx, cy, ax, ay = ellipse
    cv2.ellipse(probe, (cx, cy), (ax, ay), 0, 0, 360, 1, -1)
    return probe > 0


def measured(image, output, mask, ellipse) -> dict:
    """Per-component fits and the face probe's fit, as dictionaries."""
    fits = measure.measure(image, output, mask)
    (face,) = measure.measure(image, output, face_probe(image.shape, ellipse))
    return {"components": [f.as_dict() for f in fits], "worst": measure.worst(fits), "face": face.as_dict()}


def background_stretch(grid_path: str, mask: np.ndarray, preset: str, params: dict) -> dict:
    """Largest area ratio canvas / W over background triangles of a saved mesh.

    A triangle is background when the bounding box of its source vertices (rounded
    outwards to whole pixels) holds no mask pixel (summed-area table of the mask).
    """
    grid = np.load(grid_path)
    source, target, triangles = grid["source"], grid["target"], grid["triangles"]
    h, w = mask.shape
    under_w = load_warp(preset)(w, h, **params)(source)
    table = np.pad(mask.astype(np.int64).cumsum(0).cumsum(1), ((1, 0), (1, 0)))
    corners = source[triangles]                                    # (M, 3, 2)
    x0 = np.clip(np.floor(corners[:, :, 0].min(1)).astype(int), 0, w - 1)
    x1 = np.clip(np.ceil(corners[:, :, 0].max(1)).astype(int), 0, w - 1) + 1
    y0 = np.clip(np.floor(corners[:, :, 1].min(1)).astype(int), 0, h - 1)
    y1 = np.clip(np.ceil(corners[:, :, 1].max(1)).astype(int), 0, h - 1) + 1
    inside = table[y1, x1] - table[y0, x1] - table[y1, x0] + table[y0, x0]
    background = inside == 0

    def areas(points):
        a, b, c = (points[triangles[:, k]] for k in range(3))
        return 0.5 * ((b[:, 0] - a[:, 0]) * (c[:, 1] - a[:, 1]) - (b[:, 1] - a[:, 1]) * (c[:, 0] - a[:, 0]))

    ratio = areas(target)[background] / areas(under_w)[background]
    if ratio.size == 0:
        return {"max": None, "p99": None, "min": None, "at": None, "triangles": 0}
    worst = int(np.argmax(ratio))
    at = corners[background][worst].mean(axis=0)
    return {"max": float(ratio.max()), "p99": float(np.percentile(ratio, 99)), "min": float(ratio.min()),
            "at": [round(float(v), 1) for v in at], "triangles": int(background.sum())}


def warp_reference(mask: np.ndarray, preset: str, params: dict, most: int = 40_000) -> list[dict]:
    """What the plain warp W does to each mask component, computed from W itself.

    Per 8-connected component (as :func:`featurewarp_cli.app.measure.measure` labels
    them): the distortion of the least-squares affine fit of W over its pixels, and
    the 90th percentile and maximum over its pixels of W's local anisotropy
    sigma_max / sigma_min - 1 (Jacobian by central differences of half a pixel).
    At most ``most`` evenly spaced pixels per component are used.
    """
    h, w = mask.shape
    warp = load_warp(preset)(w, h, **params)
    n_labels, labels = cv2.connectedComponents(mask.astype(np.uint8), connectivity=8)
    out = []
    for label in range(1, n_labels):
        ys, xs = np.nonzero(labels == label)
        pick = np.linspace(0, len(xs) - 1, min(len(xs), most)).astype(int)
        points = np.column_stack([xs[pick], ys[pick]]).astype(np.float64)
        mapped = warp(points)
        design = np.column_stack([points, np.ones(len(points))])
        linear = np.linalg.lstsq(design, mapped, rcond=None)[0][:2].T
        columns = [(warp(points + step) - warp(points - step)) for step in ([0.5, 0.0], [0.0, 0.5])]
        sigma = np.linalg.svd(np.stack(columns, axis=2), compute_uv=False)
        local = sigma[:, 0] / sigma[:, 1] - 1.0
        fit = measure.describe(linear)
        out.append({"fit_distortion": fit["distortion"], "fit_scale": fit["scale"],
                    "local_p90": float(np.percentile(local, 90)), "local_max": float(local.max())})
    return out


def reported_distortions(report: dict | None) -> list | None:
    """Each component's distortion as the report gives it (worst anisotropy - 1), if it does."""
    if not report:
        return None
    for items in (report.get("components", {}).get("items"), report.get("quality", {}).get("components")):
        values = [item.get("distortion") for item in items or []]
        values = [v.get("worst", v.get("max")) if isinstance(v, dict) else v for v in values]
        if values and all(isinstance(v, (int, float)) for v in values):
            return values
    return None


def guard_figures(report: dict | None) -> dict:
    """The fold guard's work and the report's top-level verdicts, when present."""
    if not report:
        return {}
    guard = report.get("fold_guard", {})
    figures = {k: guard.get(k) for k in ("flipped_before", "untangle_iterations", "release_rounds",
                                         "released_components", "feature_blend")}
    for key in ("features_kept", "background_stretch"):
        if key in report:
            figures[key] = report[key]
    return figures


def run_case(exe, sample, preset, params, folder: Path) -> list[dict]:
    """Every mode of one case: runs, measures, background stretch; plain's figures beside each."""
    image_name, mask_name, ellipse = SAMPLES[sample]
    image = cv2.imread(str(ROOT / "samples" / image_name), cv2.IMREAD_UNCHANGED)
    mask = cv2.imread(str(ROOT / "samples" / mask_name), cv2.IMREAD_GRAYSCALE) >= 128
    reference = warp_reference(mask, preset, params)
    rows = []
    for mode in MODES:
        row = {"case": case_name(sample, preset, params), "sample": sample, "preset": preset,
               "params": params, "mode": mode, **run_warp(exe, sample, preset, params, mode, folder)}
        if row["exit"] == 0:
            output = cv2.imread(row["output"], cv2.IMREAD_UNCHANGED)
            row["measured"] = measured(image, output, mask, ellipse)
            row["background"] = background_stretch(row["grid"], mask, preset, params)
        row["warp"] = reference
        row["reported_distortion"] = reported_distortions(row["report"])
        row["guard"] = guard_figures(row["report"])
        rows.append(row)
    plain = rows[MODES.index("plain")].get("measured")
    for row in rows:
        row["plain"] = plain
        row["no_worse_than_plain"] = no_worse(row.get("measured"), plain)
    return rows


def no_worse(ours: dict | None, plain: dict | None, slack: float = 0.02) -> bool | None:
    """Every component no more distorted, locally (90th percentile), than under plain.

    None when a figure is missing on either side.
    """
    if not ours or not plain:
        return None
    pairs = [(a["local_p90"], b["local_p90"]) for a, b in zip(ours["components"], plain["components"])]
    if not pairs or any(a is None or b is None for a, b in pairs):
        return None
    return all(a <= b + slack for a, b in pairs)


def figure(value, digits=3) -> str:
    return "-" if value is None else f"{value:.{digits}f}"


def joined(items, key, digits=3) -> str:
    """One figure per component, joined by '/'."""
    return "/".join(figure(item.get(key), digits) for item in items) or "-"


def row_line(row: dict) -> str:
    """One line of the table."""
    m, plain = row.get("measured") or {}, row.get("plain") or {}
    comps, plain_comps = m.get("components", []), plain.get("components", [])
    g = row.get("guard", {})
    guard = (f"{g.get('flipped_before', '-')}/{g.get('untangle_iterations', '-')}/"
             f"{figure(g.get('feature_blend'), 2)}" if g else "-")
    verdict = {True: "yes", False: "NO", None: "-"}[row.get("no_worse_than_plain")]
    cells = [f"{row['case']:26s}", f"{row['mode']:10s}", f"{row['exit']:>2}", f"{row['seconds']:5.2f}",
             f"{joined(comps, 'distortion'):>6}",
             f"{'/'.join(figure(v) for v in row.get('reported_distortion') or []) or '-':>6}",
             f"{joined(comps, 'local_p90'):>6}",
             f"{joined(comps, 'explained', 2):>5}", f"{joined(plain_comps, 'distortion'):>6}",
             f"{joined(plain_comps, 'local_p90'):>6}", f"{joined(row.get('warp', []), 'local_p90'):>6}",
             f"{verdict:>5}", f"{figure(m.get('face', {}).get('distortion')):>6}",
             f"{figure(plain.get('face', {}).get('distortion')):>6}", f"{joined(comps, 'scale', 2):>5}",
             f"{joined(comps, 'rotation', 1):>6}", f"{figure((row.get('background') or {}).get('max'), 1):>6}",
             f"{guard:>13}", f"{len(row['stderr']):>2}"]
    return " ".join(cells)


HEADER = " ".join([f"{'case':26s}", f"{'mode':10s}", f"{'rc':>2}", f"{'sec':>5}", f"{'dist':>6}", f"{'rep':>6}",
                   f"{'loc90':>6}", f"{'expl':>5}", f"{'plain':>6}", f"{'ploc90':>6}", f"{'Wloc90':>6}",
                   f"{'<=pl':>5}", f"{'face':>6}", f"{'pface':>6}", f"{'scale':>5}", f"{'rot':>6}",
                   f"{'bg max':>6}", f"{'guard':>13}", f"{'w':>2}"])
LEGEND = """Keypoint affine fit input -> output, per mask component (joined by '/'):
  dist    distortion sigma_max/sigma_min - 1 of the fitted map;    scale, rot (degrees clockwise)
  rep     the distortion the --report gives for the component (should agree with dist within 0.02)
  loc90   90th percentile of the distortion of local fits around each match
  expl    share of locally consistent matches that the global fit explains (< 1: bent)
  plain, ploc90   dist and loc90 of the --mode plain output;  Wloc90: W's own anisotropy, 90th pct
  <=pl    loc90 <= ploc90 + 0.02 (never worse than plain)
  face, pface     the face probe (an ellipse over the face) fitted alone, ours and plain
bg max: largest background triangle area ratio canvas / W (--save-grid)
guard: fold guard flipped triangles before / window Newton steps / feature blend; w: stderr lines"""


def side_by_side(pictures: list[np.ndarray], captions: list[str], scale: float) -> np.ndarray:
    """``pictures`` scaled by one common ``scale`` (sizes stay comparable), top-aligned on
    white, each under its caption."""
    bar, gap = 26, 10
    tiles = [cv2.resize(as_bgr8(p), None, fx=scale, fy=scale, interpolation=cv2.INTER_AREA) for p in pictures]
    height = max(t.shape[0] for t in tiles) + bar
    width = sum(max(t.shape[1], 8 * len(c)) for t, c in zip(tiles, captions)) + gap * (len(tiles) - 1)
    panel = np.full((height, width, 3), 255, np.uint8)
    x = 0
    for tile, caption in zip(tiles, captions):
        cv2.putText(panel, caption, (x + 4, bar - 8), cv2.FONT_HERSHEY_SIMPLEX, 0.45, (30, 30, 30), 1, cv2.LINE_AA)
        panel[bar:bar + tile.shape[0], x:x + tile.shape[1]] = tile
        x += max(tile.shape[1], 8 * len(caption)) + gap
    return panel


def write_panel(row: dict, image_path: Path, mask: np.ndarray, folder: Path) -> str | None:
    """input (mask tinted) | plain | this run, at one common scale, as a PNG in ``folder``."""
    plain_row = row.get("plain_output")
    if row["exit"] != 0 or not plain_row:
        return None
    image = cv2.imread(str(image_path), cv2.IMREAD_UNCHANGED)
    pictures = [tint(image, mask), cv2.imread(plain_row, cv2.IMREAD_UNCHANGED),
                cv2.imread(row["output"], cv2.IMREAD_UNCHANGED)]
    m, plain = row["measured"], row["plain"]
    captions = ["input + mask",
                f"plain: {joined(plain['components'], 'distortion')} loc {joined(plain['components'], 'local_p90')}",
                f"{row['mode']}: {joined(m['components'], 'distortion')} loc {joined(m['components'], 'local_p90')}"
                f" face {figure(m['face']['distortion'])}"]
    path = folder / f"{Path(row['output']).stem}-panel.png"
    cv2.imwrite(str(path), side_by_side(pictures, captions, 360.0 / image.shape[0]))
    return str(path)


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--exe", help="featurewarp executable (default: python -m featurewarp_cli "
                                      "with this checkout on PYTHONPATH)")
    parser.add_argument("--only", choices=sorted(SAMPLES), help="run one sample's cases")
    parser.add_argument("--panels", help="folder for input | plain | result panels (created)")
    parser.add_argument("--json", default=str(ROOT / "benchmarks" / "results" / "photo_cases.json"),
                        help="where to write all figures (default benchmarks/results/photo_cases.json)")
    args = parser.parse_args(argv)
    exe = [args.exe] if args.exe else [sys.executable, "-m", "featurewarp_cli"]
    rows = []
    print(HEADER)
    with tempfile.TemporaryDirectory(prefix="featurewarp-photos-") as tmp:
        folder = Path(args.panels) if args.panels else Path(tmp)
        folder.mkdir(parents=True, exist_ok=True)
        for sample, preset, params in CASES:
            if args.only and sample != args.only:
                continue
            case_rows = run_case(exe, sample, preset, params, folder)
            image_name, mask_name, _ = SAMPLES[sample]
            mask = cv2.imread(str(ROOT / "samples" / mask_name), cv2.IMREAD_GRAYSCALE) >= 128
            for row in case_rows:
                row["plain_output"] = case_rows[MODES.index("plain")]["output"]
                if args.panels and row["mode"] != "plain":
                    row["panel"] = write_panel(row, ROOT / "samples" / image_name, mask, folder)
                print(row_line(row), flush=True)
                for line in row["stderr"]:
                    print(f"{'':30s}stderr: {line}")
            rows.extend(case_rows)
    print("\n" + LEGEND)
    out = Path(args.json)
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(json.dumps({"date": time.strftime("%Y-%m-%dT%H:%M:%S"), "exe": exe, "rows": rows},
                              indent=1, default=float) + "\n")
    print(f"\nfigures: {out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())

"""Issue 22's photo acceptance: every preset, both modes, four photos, against the plain warp.

Cases (``samples/``): ``portrait`` astronaut.png + astronaut_body_mask.png, ``closeup``
closeup.png + closeup_mask.png, ``china`` china.png + china_mask.png, ``dahlia`` dahlia.png +
dahlia_mask.png (each mask touches two or more edges). Per case: the fourteen presets at
their defaults and ``stretch --sy 2``, ``--sx 2``, ``--sx 0.6``; each in ``--mode
similarity`` and ``--mode rigid``, beside ``--mode plain`` (run once per preset, the
reference). Every run writes ``--report``; every output is measured with ``featurewarp
measure INPUT OUTPUT -m MASK --json`` (keypoints, an affine fit per mask component).

Rules checked per run (a violation names its rule):

blank        report ``blank_share`` > ``plain_blank_share`` + 0.005 (of the canvas)
blank-img    the same on the written images: share of pixels with alpha < 128
outline      report ``outline_departure`` > 1 px
outline-img  on the images: how far the covered region (alpha >= 128) reaches beyond or
             falls short of plain's, > 2 px (1 px plus 1 px of rasterisation)
dist, aniso  a component's report ``distortion`` (affine fit over it) or
             ``anisotropy_worst`` (its worst triangle) > plain's + :data:`REPORT_TOL`
kp-dist      a component's keypoint distortion > plain's keypoint distortion + tolerance
kp-local     its keypoint ``local_p90`` (the image's counterpart of the worst triangle)
             > plain's + tolerance; tolerances :func:`kp_tolerance`, from ``--noise``
unsaid-*     a visible compromise with no warning line on stderr: ``kept`` (a component
             not kept), ``blank``, ``outline``, ``streaks`` (background stretch > 8),
             ``blend`` (moved towards plain), ``border`` (a component unpinned or not
             tied), ``kp`` (keypoints show a component off its shape by more than 0.02 +
             tolerance while the report says every feature was kept)
exit         the command failed

``--noise`` also renders each plain warp with ``--interp linear`` and measures it: the map
is the same, so the keypoint figures' differences from the cubic rendering are the
measurement's own noise, summarised at the end (the tolerances below come from it).

Usage (from the repository; this checkout's package runs)::

    .venv/bin/python benchmarks/photo_acceptance.py [--only NAME] [--preset NAME]
        [--json PATH] [--panels DIR] [--noise] [--jobs N] [--recheck JSON]

``--panels DIR`` keeps every output there and writes input (mask tinted) | plain | result
for each run with a violation or a keypoint figure above plain's within noise.
``--recheck JSON`` applies the rules again to an earlier ``--json``, running nothing.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

import cv2  # noqa: E402
import numpy as np  # noqa: E402

from benchmarks.photo_cases import figure, options, side_by_side  # noqa: E402
from featurewarp_cli.app.panel import tint  # noqa: E402

CASES = {"portrait": ("astronaut.png", "astronaut_body_mask.png"),
         **{name: (f"{name}.png", f"{name}_mask.png") for name in ("closeup", "china", "dahlia")}}
PRESETS = ("stretch", "arc", "swirl", "bulge", "arch", "flag", "fish", "rise", "inflate", "squeeze", "shell",
           "perspective", "cylinder", "sphere")
#: (preset, options): the fourteen at their defaults, then issue 22's stretches.
SETTINGS = [(p, {}) for p in PRESETS] + [("stretch", {"sy": 2}), ("stretch", {"sx": 2}), ("stretch", {"sx": 0.6})]
MODES = ("similarity", "rigid")
BLANK, OUTLINE_PX, OUTLINE_IMG_PX = 0.005, 1.0, 2.0
#: Report figures are computed from the mesh, exactly: a tolerance for rounding only.
REPORT_TOL = 1e-3
#: A component counts as kept below this distortion (the engine's KEPT), and background
#: stretched beyond STREAKS must be said (the engine's thresholds, issue 22 item 3).
KEPT, STREAKS = 0.02, 8.0
#: A keypoint fit explaining less than this share of its component's matches is of a bent
#: component (``featurewarp measure``'s own threshold for "bent").
BENT_EXPLAINED = 0.9
#: So is one whose plain warp's local fits' 90th percentile exceeds its global fit's
#: distortion by more than this: one global map may explain its matches within 3 px and still
#: be bent (a cylinder across a close-up's face: local_p90 0.118 against a distortion of
#: 0.044; rigid mode, identical to the plain warp on the face, read 0.057 there by its other
#: matches). On components that moved as one map the two differ by at most 0.018 (2026-11-27's
#: 136 runs). Only the plain warp's fit counts: ours bending a component is what is checked.
BENT_LOCAL = 0.025
#: Keypoint tolerances per figure, for components that moved as one map and for bent ones
#: (:func:`kp_tolerance` gives the noise behind them).
KP_TOL = {"one map": {"distortion": 0.002, "local_p90": 0.015},
          "bent": {"distortion": 0.05, "local_p90": 0.045}}


def kp_tolerance(fits: list[dict], key: str, spread: float | None = None) -> tuple[float, str]:
    """Tolerance of keypoint figure ``key`` compared across ``fits`` (ours, plain's).

    Parameters
    ----------
    fits : list of dict
        The components' entries of ``featurewarp measure --json`` being compared.
    key : str
        ``'distortion'`` or ``'local_p90'``.
    spread : float, optional
        This case's own noise, when ``--noise`` ran: abs(cubic - linear) of plain's figure.
        The tolerance is then at least twice it (ours carries noise of its own).

    Returns
    -------
    tolerance : float
        From ``--noise``: the same plain map rendered ``--interp cubic`` and ``linear``
        (85 component pairs over the four photos and seventeen settings, 2026-11-27). Where
        both moved as one map (20 pairs) the renderings' distortions differ by at most 0.0009
        and their local_p90 by 0.0021; bent components (65 pairs) differ by up to 0.14 in
        distortion (median 0.004, 95th percentile 0.040) and 0.11 in local_p90 (95th
        percentile 0.072). The bent tolerances sit above the 95th percentiles; ``spread`` raises
        them where one case's own noise is larger, when ``--noise`` ran.
    kind : str
        ``'one map'`` or ``'bent'``, by the reference, the last fit (plain's): bent where it
        explains less than :data:`BENT_EXPLAINED` of its matches or its local figures say W bent
        it (:data:`BENT_LOCAL`). Ours alone (``unsaid-kp``: a feature the report says is kept
        moved as one similarity) is 'one map'. Ours bending a component is what the rules catch,
        so our fit never loosens them (it did, through either test).
    """
    if len(fits) == 1:                   # ours alone (unsaid-kp): a kept feature moved as one map
        return KP_TOL["one map"][key], "one map"
    reference = fits[-1]                 # plain's: W bends it; ours bending it is what is checked
    explained = reference.get("explained")
    bent_map = (reference.get("local_p90") or 0.0) > reference.get("distortion", 0.0) + BENT_LOCAL
    kind = "one map" if explained is not None and explained >= BENT_EXPLAINED and not bent_map else "bent"
    return max(KP_TOL[kind][key], 2.0 * (spread or 0.0)), kind


def run(cmd: list[str]) -> tuple[int, list[str], str, float]:
    """Run ``cmd`` with this checkout on PYTHONPATH: exit status, stderr lines, stdout, seconds."""
    t0 = time.perf_counter()
    proc = subprocess.run(cmd, capture_output=True, text=True, env=dict(os.environ, PYTHONPATH=str(ROOT)))
    return proc.returncode, proc.stderr.strip().splitlines(), proc.stdout, time.perf_counter() - t0


def warp_and_measure(case: str, preset: str, params: dict, mode: str, folder: Path, interp: str = "cubic") -> dict:
    """One ``featurewarp warp`` with ``--report``, then ``featurewarp measure --json`` on its output.

    Returns
    -------
    dict
        ``exit``, ``seconds``, ``stderr``, ``warnings`` (the stderr lines that are warnings),
        ``output``, ``report`` (parsed, or None) and ``measured`` (the components of
        measure's JSON, or None).
    """
    image, mask = (str(ROOT / "samples" / name) for name in CASES[case])
    suffix = "" if interp == "cubic" else f"-{interp}"
    stem = folder / f"{case}-{preset}{''.join(options(params)).replace('--', '-')}-{mode}{suffix}"
    output, report_path = f"{stem}.png", f"{stem}.json"
    exe = [sys.executable, "-m", "featurewarp_cli"]
    code, stderr, _, seconds = run([*exe, "warp", preset, image, output, "-m", mask, "--mode", mode, "--report",
                                    report_path, "--interp", interp, *options(params)])
    row = {"exit": code, "seconds": round(seconds, 2), "stderr": stderr,
           "warnings": [line.split("warning:", 1)[1].strip() for line in stderr if "warning:" in line],
           "output": output, "report": None, "measured": None}
    if code == 0:
        row["report"] = json.loads(Path(report_path).read_text())
        m_code, m_err, m_out, _ = run([*exe, "measure", image, output, "-m", mask, "--json"])
        row["measured"] = json.loads(m_out)["components"] if m_code == 0 else None
        row["measure_error"] = None if m_code == 0 else m_err
    return row


def coverage(path: str) -> np.ndarray | None:
    """Pixels of a written output that some source pixel covers (alpha >= 128), or None."""
    image = cv2.imread(path, cv2.IMREAD_UNCHANGED)
    opaque = image is not None and not (image.ndim == 3 and image.shape[2] == 4)
    return None if image is None else np.ones(image.shape[:2], bool) if opaque else image[:, :, 3] >= 128


def image_canvas(ours: str, plain: str) -> dict:
    """Blank shares and the outline's departure read off the written images.

    ``outline_px`` is the largest distance from a pixel covered by one image and not by the
    other to the other's covered region (both ways): how far the result's outline reaches
    beyond plain's or falls short of it.
    """
    a, b = coverage(ours), coverage(plain)
    if a is None or b is None or a.shape != b.shape:
        return {"blank": None, "plain_blank": None, "outline_px": None}
    reach = 0.0
    for inside, other in ((a & ~b, b), (b & ~a, a)):
        if inside.any():
            away = cv2.distanceTransform((~other).astype(np.uint8), cv2.DIST_L2, cv2.DIST_MASK_PRECISE)
            reach = max(reach, float(away[inside].max()))
    return {"blank": float(1 - a.mean()), "plain_blank": float(1 - b.mean()), "outline_px": reach}


def said(warnings: list[str], *words: str) -> bool:
    """Some warning line holds one of ``words``."""
    return any(word in line for line in warnings for word in words)


def violations(row: dict, plain: dict) -> list[dict]:
    """Every rule ``row`` breaks against ``plain`` (the module docstring lists them).

    Returns
    -------
    list of dict
        ``rule``, ``component`` (1-based, or None), ``ours``, ``plain`` (plain's figure, or
        the limit when the rule has no plain figure), ``limit`` and ``excess`` (ours - limit).
    """
    out = []

    def flag(rule, ours, limit, component=None, reference=None):
        """Record that ``rule`` is broken: ``ours`` against ``limit`` (and plain's ``reference``)."""
        out.append({"rule": rule, "component": component, "ours": ours, "limit": limit,
                    "plain": limit if reference is None else reference, "excess": ours - limit})

    if row["exit"] or plain["exit"]:
        return [{"rule": "exit", "component": None, "ours": row["exit"] or plain["exit"], "plain": 0, "limit": 0,
                 "excess": 1.0}]
    rep, warns, img = row["report"], row["warnings"], row["image"]
    blank_extra = rep["blank_share"] - rep["plain_blank_share"]
    if blank_extra > BLANK:
        flag("blank", rep["blank_share"], rep["plain_blank_share"] + BLANK, reference=rep["plain_blank_share"])
    if img["blank"] is not None and img["blank"] > img["plain_blank"] + BLANK:
        flag("blank-img", img["blank"], img["plain_blank"] + BLANK, reference=img["plain_blank"])
    if rep["outline_departure"] > OUTLINE_PX:
        flag("outline", rep["outline_departure"], OUTLINE_PX)
    if img["outline_px"] is not None and img["outline_px"] > OUTLINE_IMG_PX:
        flag("outline-img", img["outline_px"], OUTLINE_IMG_PX)
    items = rep["components"]["items"]
    for k, c in enumerate(items, 1):
        if c["distortion"] > c["plain_distortion"] + REPORT_TOL:
            flag("dist", c["distortion"], c["plain_distortion"] + REPORT_TOL, k, c["plain_distortion"])
        if c["anisotropy_worst"] > c["plain_anisotropy_worst"] + REPORT_TOL:
            flag("aniso", c["anisotropy_worst"], c["plain_anisotropy_worst"] + REPORT_TOL, k,
                 c["plain_anisotropy_worst"])
    ours_kp, plain_kp = row["measured"] or [], plain.get("measured") or []
    row["kp_within_noise"] = []
    linear = plain.get("linear") or []
    for k, (a, b) in enumerate(zip(ours_kp, plain_kp), 1):
        for key, rule in (("distortion", "kp-dist"), ("local_p90", "kp-local")):
            if a.get(key) is not None and b.get(key) is not None:
                other = linear[k - 1].get(key) if k <= len(linear) else None
                tol, kind = kp_tolerance([a, b], key, None if other is None else abs(other - b[key]))
                if a[key] > b[key] + tol:
                    flag(rule, a[key], b[key] + tol, k, b[key])
                elif a[key] > b[key] + KP_TOL["one map"][key]:     # worse, but within a bent fit's noise
                    row["kp_within_noise"].append({"rule": rule, "component": k, "ours": a[key], "plain": b[key],
                                                   "tolerance": tol})
    if not rep["features_kept"] and not said(warns, "not kept"):
        flag("unsaid-kept", max(c["anisotropy_worst"] for c in items), KEPT)
    if blank_extra > BLANK and not said(warns, "blank"):
        flag("unsaid-blank", rep["blank_share"], rep["plain_blank_share"] + BLANK)
    if rep["outline_departure"] > OUTLINE_PX and not said(warns, "outline"):
        flag("unsaid-outline", rep["outline_departure"], OUTLINE_PX)
    if rep["background_stretch"] > STREAKS and not said(warns, "streaks", "stretched"):
        flag("unsaid-streaks", rep["background_stretch"], STREAKS)
    # A feature that gave way but still keeps its shape (within KEPT) is no visible compromise.
    moved = rep["fold_guard"]["degraded_components"]
    lost = [k for k in moved if not items[k]["kept"]] if moved else [None]
    if rep["fold_guard"]["plain_blend"] < 1.0 and lost and not said(warns, "towards the plain warp"):
        flag("unsaid-blend", 1.0 - rep["fold_guard"]["plain_blend"], 0.0)
    loose = [k for k, c in enumerate(items, 1) if (c["unpinned"] or not c["tied"]) and not c["kept"]]
    if loose and not said(warns, "border", "outline", "relaxed"):
        flag("unsaid-border", float(len(loose)), 0.0, loose[0])
    for k, a in enumerate(ours_kp, 1):
        d = a.get("distortion")
        if (d is not None and rep["features_kept"] and d > KEPT + kp_tolerance([a], "distortion")[0]
                and not said(warns, "not kept", "towards the plain warp", "relaxed", "soft constraints")):
            flag("unsaid-kp", d, KEPT + kp_tolerance([a], "distortion")[0], k)
    return out


def setting_name(preset: str, params: dict) -> str:
    """'stretch --sy 2', or the preset alone at its defaults."""
    return f"{preset} {' '.join(options(params))}".strip()


def run_setting(case: str, preset: str, params: dict, folder: Path, noise: bool) -> list[dict]:
    """Plain (and, with ``noise``, plain rendered linear), then each mode of :data:`MODES`, of
    one case and setting: their rows, the modes' with the images' canvas figures."""
    base = {"case": case, "preset": preset, "params": params, "setting": setting_name(preset, params)}
    plain = {**base, "mode": "plain", **warp_and_measure(case, preset, params, "plain", folder)}
    if noise and plain["exit"] == 0:
        plain["linear"] = warp_and_measure(case, preset, params, "plain", folder, "linear")["measured"]
    rows = [plain]
    for mode in MODES:
        row = {**base, "mode": mode, **warp_and_measure(case, preset, params, mode, folder)}
        row["image"] = image_canvas(row["output"], plain["output"]) if row["exit"] == 0 else None
        rows.append(row)
    print(f"  {case:8s} {base['setting']:18s} {sum(r['seconds'] for r in rows):5.1f} s", file=sys.stderr, flush=True)
    return rows


def comps(values) -> str:
    """Per-component figures joined by '/'."""
    return "/".join(figure(v) for v in values) or "-"


def row_line(row: dict, plain: dict) -> str:
    """One line of the table: figures ours|plain, then the rules broken."""
    if row["exit"] or plain["exit"]:
        return f"{row['case']:8s} {row['setting']:16s} {row['mode']:10s} exit {row['exit']}: {row['stderr'][-1:]}"
    rep, img = row["report"], row["image"]
    items = rep["components"]["items"]
    kp, pkp = row["measured"] or [], plain.get("measured") or []
    rules = sorted({v["rule"] + (f"#{v['component']}" if v["component"] else "") for v in row["violations"]})
    cells = [f"{row['case']:8s}", f"{row['setting']:16s}", f"{row['mode']:10s}",
             f"{100 * rep['blank_share']:5.1f}|{100 * rep['plain_blank_share']:4.1f}",
             f"{100 * img['blank']:5.1f}|{100 * img['plain_blank']:4.1f}",
             f"{rep['outline_departure']:5.1f}|{figure(img['outline_px'], 1):>4}",
             *(f"{comps(c.get(a) for c in ours):>11}|{comps(c.get(b) for c in theirs):<11}"
               for ours, theirs, a, b in ((items, items, "distortion", "plain_distortion"),
                                          (items, items, "anisotropy_worst", "plain_anisotropy_worst"),
                                          (kp, pkp, "distortion", "distortion"), (kp, pkp, "local_p90", "local_p90"))),
             f"{'y' if rep['features_kept'] else 'n'}", f"{len(row['warnings']):>1}", " ".join(rules) or "ok"]
    if kp and len(kp) != len(items):       # per-component columns then pair nothing
        cells.append(f"(report {len(items)} components, image {len(kp)})")
    return " ".join(cells)


HEADER = " ".join([f"{'case':8s}", f"{'setting':16s}", f"{'mode':10s}", f"{'blank%':>10}", f"{'img blank%':>10}",
                   f"{'outline':>10}", f"{'rep dist|plain':>23}", f"{'rep aniso|plain':>23}", f"{'kp dist|plain':>23}",
                   f"{'kp loc90|plain':>23}", "k", "w", "violations"])
LEGEND = """blank%: report blank share ours|plain; img blank%: alpha < 128 on the written images ours|plain;
outline: report outline_departure | the images' (px); rep dist/aniso: report distortion (affine fit) and
anisotropy_worst (worst triangle) per component, ours|plain; kp dist / kp loc90: featurewarp measure's
distortion and local_p90 per component, ours|plain output; k: features_kept; w: warning lines;
violations: rule#component (module docstring)."""


def noise_summary(rows: list[dict]) -> dict:
    """Keypoint noise, abs(cubic - linear) renderings of the same plain map, per figure and
    kind of fit (:func:`kp_tolerance`): pairs, median, 95th percentile, largest."""
    found = {}
    for r in rows:
        for a, b in zip(r["measured"] or [], r.get("linear") or []):
            for key in ("distortion", "local_p90"):
                if a.get(key) is not None and b.get(key) is not None:
                    kind = kp_tolerance([a, b], key)[1]
                    found.setdefault(f"{key} {kind}", []).append(abs(a[key] - b[key]))
    return {name: {"pairs": len(d), "p50": float(np.median(d)), "p95": float(np.percentile(d, 95)),
                   "max": float(np.max(d))} for name, d in sorted(found.items())}


def write_panel(row: dict, plain: dict, folder: Path) -> str:
    """input (mask tinted) | plain | result, one common scale, captioned with the rules broken."""
    image_name, mask_name = CASES[row["case"]]
    image = cv2.imread(str(ROOT / "samples" / image_name), cv2.IMREAD_UNCHANGED)
    mask = cv2.imread(str(ROOT / "samples" / mask_name), cv2.IMREAD_GRAYSCALE) >= 128
    rules = " ".join(sorted({v["rule"] for v in row["violations"]}))
    pictures = [tint(image, mask), cv2.imread(plain["output"], cv2.IMREAD_UNCHANGED),
                cv2.imread(row["output"], cv2.IMREAD_UNCHANGED)]
    captions = ["input + mask", f"plain {row['setting']}", f"{row['mode']}: {rules}"]
    path = folder / f"{Path(row['output']).stem}-panel.png"
    cv2.imwrite(str(path), side_by_side(pictures, captions, 360.0 / image.shape[0]))
    return str(path)


def main(argv=None) -> int:
    """Run (or ``--recheck``) the sweep, print every run and the violations, write the JSON."""
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--only", choices=sorted(CASES), help="run one case")
    parser.add_argument("--preset", choices=PRESETS, help="run one preset's settings")
    parser.add_argument("--json", default=str(ROOT / "benchmarks" / "results" / "photo_acceptance.json"),
                        help="where to write every figure (default benchmarks/results/photo_acceptance.json)")
    parser.add_argument("--panels", help="folder for the outputs and the panels of runs worse than plain")
    parser.add_argument("--noise", action="store_true", help="also measure plain rendered --interp linear")
    parser.add_argument("--jobs", type=int, default=2, help="settings run at once (default 2)")
    parser.add_argument("--recheck", metavar="JSON", help="check an earlier --json's rows again, running nothing")
    args = parser.parse_args(argv)
    jobs = [(case, preset, params) for case in CASES for preset, params in SETTINGS
            if (not args.only or case == args.only) and (not args.preset or preset == args.preset)]
    t0 = time.perf_counter()
    with tempfile.TemporaryDirectory(prefix="featurewarp-acceptance-") as tmp:
        folder = Path(args.panels) if args.panels else Path(tmp)
        folder.mkdir(parents=True, exist_ok=True)
        if args.recheck:
            earlier = json.loads(Path(args.recheck).read_text())
            rows, t0 = earlier["rows"], t0 - earlier["wall_seconds"]
            groups = [rows[i:i + 1 + len(MODES)] for i in range(0, len(rows), 1 + len(MODES))]
            groups = [g for g in groups if (not args.only or g[0]["case"] == args.only)
                      and (not args.preset or g[0]["preset"] == args.preset)]
        else:
            with ThreadPoolExecutor(max(1, args.jobs)) as pool:
                groups = list(pool.map(lambda job: run_setting(*job, folder, args.noise), jobs))
        wall = time.perf_counter() - t0
        print(HEADER)
        broken = []
        for group in groups:
            plain = group[0]
            for row in group[1:]:
                row["violations"] = violations(row, plain)
                print(row_line(row, plain))
                for line in row["warnings"]:
                    print(f"{'':37s}warning: {line}")
                if row["violations"]:
                    broken.append(row)
                if args.panels and (row["violations"] or row.get("kp_within_noise")):
                    row["panel"] = write_panel(row, plain, folder)
    print("\n" + LEGEND)
    print(f"\nviolations ({sum(len(r['violations']) for r in broken)} in {len(broken)} of "
          f"{sum(len(g) - 1 for g in groups)} runs), largest excess first:")
    flat = sorted(((v, r) for r in broken for v in r["violations"]), key=lambda vr: -vr[0]["excess"])
    for v, r in flat:
        where = f"component {v['component']}" if v["component"] else ""
        print(f"  {r['case']:8s} {r['setting']:16s} {r['mode']:10s} {v['rule']:14s} {where:12s} "
              f"ours {v['ours']:.4f}  plain {v['plain']:.4f}  limit {v['limit']:.4f}  excess {v['excess']:+.4f}")
    near = [(r, v) for g in groups for r in g[1:] for v in r.get("kp_within_noise", [])]
    print(f"\nkeypoint figures above plain's + the one-map tolerance, within noise ({len(near)}, not violations):")
    for r, v in near:
        print(f"  {r['case']:8s} {r['setting']:16s} {r['mode']:10s} {v['rule']:9s} component {v['component']}  "
              f"ours {v['ours']:.4f}  plain {v['plain']:.4f}  tolerance {v['tolerance']:.3f}")
    noise = noise_summary([r for g in groups for r in g]) if (args.noise or args.recheck) else None
    if noise:
        print("\nkeypoint noise (|cubic - linear| of the same plain map):")
        for name, d in noise.items():
            print(f"  {name:20s} {d['pairs']:3d} pairs  median {d['p50']:.4f}  p95 {d['p95']:.4f}  max {d['max']:.4f}")
    print(f"\nwall time {wall:.0f} s for {len(jobs)} settings ({args.jobs} at once)")
    out = Path(args.json)
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(json.dumps({"date": time.strftime("%Y-%m-%dT%H:%M:%S"), "wall_seconds": wall, "noise": noise,
                               "rows": [r for g in groups for r in g]}, indent=1, default=float) + "\n")
    print(f"figures: {out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())

"""The JSON report of one run: what was done, how long it took, and its quality."""

from __future__ import annotations

import json
import os
import time

import numpy as np

from .. import __version__
from ..engine import barrier
from ..engine import guard as fold_guard
from ..engine import path as fold_path


#: The report's own format version (``featurewarp schema report`` prints its JSON Schema).
REPORT_SCHEMA = "featurewarp-report/3"


def image_summary(path: str, image: np.ndarray, fmt: str | None = None, transparent: bool = False) -> dict:
    """Path, size, channels and depth of an image (as ``fmt`` stores it, where given: a 16-bit
    result written as JPEG is an 8-bit file, an RGBA one as BMP has 3 channels, and as a GIF 4
    where ``transparent``)."""
    from ..io.encode import stored_form

    channels, bits = ((1 if image.ndim == 2 else int(image.shape[2]), 8 * image.dtype.itemsize) if fmt is None
                      else stored_form(image, fmt, transparent))
    return {
        "path": os.path.abspath(path) if path != "-" else "-",
        "width": int(image.shape[1]),
        "height": int(image.shape[0]),
        "channels": channels,
        "bits": bits,
    }


def build_report(input_path, output_path, image, result, warp, mesh, timings, fmt: str | None = None,
                 refused: dict | None = None, transparent: bool = False) -> dict:
    """Assemble the report dictionary (JSON-ready).

    Parameters
    ----------
    input_path, output_path : str
    image, result : ndarray
        Input and output images (``result`` None: none was written, ``refused`` says why).
    warp : warps.Warp
    mesh : featurewarp_cli.engine.mesh.Mesh
    timings : dict
        Seconds per stage.
    fmt : str, optional
        The output's format: the output is described as it stores ``result``.
    refused : dict, optional
        A run refused after its solve (``--strict``, folds): ``error`` (its one line) and
        ``warnings`` (those that caused it); ``output`` is null then.
    transparent : bool
        The output's background is transparent (a GIF keeps its alpha then).

    Returns
    -------
    dict
    """
    info = mesh.info
    stages = ("load", "grid", "factor", "scale_setup", "rhs", "solve", "guard", "quality", "render", "write")
    seconds = {k: round(float(timings.get(k, 0.0)), 6) for k in stages}
    if "total" in timings:
        seconds["total"] = round(float(timings["total"]), 6)
        seconds["other"] = round(max(0.0, seconds["total"] - sum(seconds[k] for k in stages)), 6)
    return {
        "schema": REPORT_SCHEMA,
        "version": __version__,
        "preset": warp.name,
        "params": warp.values,
        "mode": info["mode"],
        "formulation": info["formulation"],
        "boundary": info["boundary"],
        "input": image_summary(input_path, image),
        "output": None if result is None else image_summary(output_path, result, fmt, transparent),
        "refused": refused,
        "canvas": {"width": mesh.canvas[0], "height": mesh.canvas[1], "offset": list(warp.offset)},
        "grid": info["grid"],
        "components": {"count": len(info["components"]), "items": info["components"]},
        "solver": info["solver"],
        "seconds": seconds,
        "features_kept": info["features_kept"],
        "no_effect": info.get("no_effect", False),
        "background_stretch": info["background_stretch"],
        "background_stretch_at": info["background_stretch_at"],
        "blank_share": info["blank_share"],
        "plain_blank_share": info["plain_blank_share"],
        "blank_extra_box": info["blank_extra_box"],
        "outline_departure": info["outline_departure"],
        "outline_departure_at": info["outline_departure_at"],
        "grown": info["grown"],
        "warnings": info["warnings"],
        "flipped_triangles": info["flipped_triangles"],
        "fold_guard": _fold_guard(info),
        "quality": info["quality"],
    }


def _fold_guard(info: dict) -> dict:
    """The report's ``fold_guard``: the guard's figures from the solve's ``info`` and its settings."""
    return {
        "flipped_before": info.get("flipped_before_guard", 0),
        "flipped_after": info["flipped_triangles"],
        "untangle_iterations": info.get("untangle_iterations", 0),
        "window_quads": info.get("untangle_window_quads", 0),
        "window": {"margin": fold_guard.WINDOW_MARGIN, "min_margin": fold_guard.WINDOW_MIN_MARGIN,
                   "max_steps": fold_guard.WINDOW_STEPS, "continued_below": list(fold_guard.CONTINUED_BELOW),
                   "tolerance": fold_path.PATH_TOLERANCE},
        "path": {"steps": info.get("path_steps", 0), "blocked_share": fold_path.BLOCKED_SHARE,
                 "tolerance": fold_path.PATH_TOLERANCE, "max_steps": fold_path.MAX_STEPS},
        "release_rounds": info.get("release_rounds", 0),
        "released_components": info.get("released_components", []),
        "feature_blend": info.get("feature_blend", 1.0),
        "release": {"blend_steps": fold_guard.BLEND_STEPS, "thinnest": fold_guard.injectivity.CRUSHED_SHARE,
                    "trial_steps": fold_guard.TRIAL_STEPS, "cut": info.get("release_cut", False)},
        "fallback": info.get("fallback", False),
        "plain_blend": info.get("plain_blend", 1.0),
        "degraded_components": info.get("degraded_components", []),
        "barrier": {"safe_fraction": barrier.SAFE_FRACTION, "stiffness": barrier.STIFFNESS,
                    "tolerance": barrier.TOLERANCE, "max_steps": barrier.MAX_STEPS,
                    "newton_steps": info.get("newton_steps", 0),
                    "converged": info.get("barrier_converged", True)},
    }


def summary(preset: str, mode: str, input: str, out_path: str, size, mesh, t0: float,
            warnings: list) -> dict:
    """The ``--verbose`` summary of one written image (a fold-over, if any, becomes a warning;
    ``notes``: what is said on stderr beside the warnings, as where --grow-past-edge crops)."""
    from ..engine.record import grown_note

    flips = mesh.info.get("flipped_triangles", 0)
    if flips:
        warnings.append(f"{flips} triangles of the mesh fold over; the output may show folds")
    return {
        "input": "stdin" if input == "-" else input, "output": "stdout" if out_path == "-" else out_path,
        "preset": preset, "mode": mode, "size": tuple(size), "canvas": tuple(mesh.canvas),
        "solver": mesh.info["solver"], "components": len(mesh.info["components"]),
        "flipped_triangles": flips, "seconds": time.perf_counter() - t0, "warnings": warnings,
        "notes": [note for note in [grown_note(mesh.info.get("grown"))] if note],
    }


def report_bytes(input, out_path, image, result, warp, mesh, timings, t0, fmt: str | None = None,
                 refused: dict | None = None, transparent: bool = False) -> bytes:
    """The JSON report's bytes (its ``seconds.total`` is the run so far; ``refused``: see
    :func:`build_report`)."""
    timings["total"] = time.perf_counter() - t0
    report = build_report(input, out_path, image, result, warp, mesh, timings, fmt, refused, transparent)
    return (json.dumps(report, indent=2) + "\n").encode()


def refused_report(path, input, out_path, image, warp, mesh, timings, t0, fmt, error: str, causes: list) -> None:
    """Write the report of a run refused after its solve to ``path``: ``refused`` holds the ``error``
    and the warnings that ``causes`` it, ``output`` is null (no image is written)."""
    from .outputs import write_all

    timings.update(mesh.info["timings"])
    refused = {"error": error, "warnings": list(causes)}
    write_all([(path, report_bytes(input, out_path, image, None, warp, mesh, timings, t0, fmt, refused))])

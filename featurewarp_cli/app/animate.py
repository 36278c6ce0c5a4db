"""Animations: one preset parameter (or several) varied over frames, factoring once.

Writes an animated GIF, WebP or PNG (APNG), an MP4/AVI video through OpenCV's
video writer, or a numbered PNG sequence (a path with a ``%d``-style field).
"""

from __future__ import annotations

import os
import re
import time
from dataclasses import replace

import cv2
import numpy as np

from ..engine import fidelity
from ..engine.assess import STILL
from ..engine.record import LISTED_IN_REPORT
from ..io import formats, write
from ..io.colours import parse_colour
from ..io.depth import to_eight_bit
from ..io.encode import encode_image, rgb_order, webp_options
from ..plugins import ParamError
from .outputs import background_colour, check_encodable
from .pipeline import (Settings, WarpError, check_solution, load_image_and_mask, make_warper,
                       prefetch_engine, solve_within_budget)

ANIMATED = {".gif", ".webp", ".png", ".apng"}
VIDEO = {".mp4": "mp4v", ".avi": "MJPG"}
#: The frames' compromises said one by one (``frame N: ...``); beyond, one line counts the rest.
FRAME_WARNINGS = 10
#: Bytes each frame holds per canvas pixel until the animation is encoded: the 8-bit BGRA frame,
#: and as much again for the encoder's copy.
FRAME_PIXEL_BYTES = 8


def parse_vary(texts, preset) -> dict[str, tuple[float, float]]:
    """``NAME=START:END`` strings -> {name: (start, end)}, checked against the preset's parameters."""
    names = {p.cli_name: p for p in preset.params}
    ranges = {}
    for text in texts:
        match = re.fullmatch(r"\s*([\w-]+)\s*=\s*([^:]+):([^:]+)\s*", text)
        if not match:
            raise WarpError(f"{text!r} is not NAME=START:END", "--vary", usage=True)
        name, start, end = match.groups()
        if name not in names:
            raise WarpError(f"{preset.name} has no parameter {name!r} (it has: {', '.join(names)})",
                            "--vary", usage=True)
        param = names[name]
        if param.name in ranges:
            raise WarpError(f"{name} is given twice", "--vary", usage=True)
        if param.type not in (int, float):
            raise WarpError(f"{name} is not a number and cannot vary", "--vary", usage=True)
        try:
            ranges[param.name] = (param.check(start), param.check(end))
        except ParamError as err:               # named as --vary names it: NAME=START:END
            raise WarpError(err.render(lambda name: name.replace("_", "-")), "--vary", usage=True) from None
    if not ranges:
        raise WarpError("give at least one NAME=START:END", "--vary", usage=True)
    return ranges


def frame_params(settings: Settings, ranges: dict, frames: int) -> list[dict]:
    """Parameter values of each frame: linear from START to END, both included."""
    steps = np.linspace(0.0, 1.0, frames) if frames > 1 else np.zeros(1)
    out = []
    for s in steps:
        params = dict(settings.params)
        for name, (start, end) in ranges.items():
            value = start + s * (end - start)
            params[name] = round(value) if isinstance(start, int) and isinstance(end, int) else value
        out.append(params)
    return out


def check_frames_fit(settings: Settings, frames: int, canvas: tuple[int, int]) -> None:
    """WarpError when ``frames`` frames of the ``canvas`` (width, height) would not fit the memory
    limit (``--max-memory``): every frame is held until the animation is encoded."""
    from ..io.limits import size_text

    need = frames * canvas[0] * canvas[1] * FRAME_PIXEL_BYTES
    if settings.max_memory is not None and need > settings.max_memory:
        need_text = size_text(need, settings.max_memory)
        raise WarpError(f"{frames} frames of {canvas[0]}x{canvas[1]} need about {need_text}, above the "
                        f"memory limit of {size_text(settings.max_memory)} (--max-memory): fewer --frames, "
                        f"or a smaller image")


def output_kind(path: str) -> str:
    """'sequence' (a %d field in the name), 'animation' or 'video'."""
    if re.search(r"%0?\d*d", os.path.basename(path)):
        try:
            path % 0
        except (TypeError, ValueError):
            raise WarpError(f"{path}: a numbered sequence's name holds one %d field (such as %04d), and %% for "
                            f"a percent sign", "OUTPUT", usage=True) from None
        if os.path.splitext(path)[1].lower() != ".png":       # its frames are PNG files
            raise WarpError(f"{path}: a numbered sequence is of PNG frames; end its name in .png", "OUTPUT",
                            usage=True)
        return "sequence"
    ext = os.path.splitext(path)[1].lower()
    if ext in ANIMATED:
        return "animation"
    if ext in VIDEO:
        return "video"
    raise WarpError(f"cannot tell the animation format of {path}: use .gif, .webp, .png, .mp4, .avi "
                    "or a numbered sequence such as out-%04d.png", "OUTPUT", usage=True)


def centre_on(image: np.ndarray, size: tuple[int, int], fill) -> np.ndarray:
    """``image`` (8-bit BGR or BGRA) centred on a canvas of ``size`` (width, height) filled with ``fill``."""
    width, height = size
    canvas = np.empty((height, width, image.shape[2]), image.dtype)
    canvas[:] = fill[: image.shape[2]]
    y, x = (height - image.shape[0]) // 2, (width - image.shape[1]) // 2
    canvas[y : y + image.shape[0], x : x + image.shape[1]] = image
    return canvas


def to_bgr(image: np.ndarray, alpha: bool) -> np.ndarray:
    """8-bit BGR (or BGRA when ``alpha``) from any gray/BGR/BGRA 8/16-bit image."""
    image = to_eight_bit(image)
    if image.ndim == 2:
        image = cv2.cvtColor(image, cv2.COLOR_GRAY2BGR)
    if alpha and image.shape[2] == 3:
        image = cv2.cvtColor(image, cv2.COLOR_BGR2BGRA)
    if not alpha and image.shape[2] == 4:
        image = image[:, :, :3]
    return image


def animate_file(settings: Settings, input: str, output: str, mask: str | None, ranges: dict,
                 frames: int, fps: float, progress=None) -> dict:
    """Render the frames and write the animation (see the module docstring).

    Parameters
    ----------
    settings : Settings
        Warp settings; ``settings.params`` are the fixed parameter values.
    input, output, mask : str
    ranges : dict
        {parameter: (start, end)} from :func:`parse_vary`.
    frames : int
    fps : float
    progress : callable, optional
        Called with 1 after each frame.

    Returns
    -------
    dict
        Summary: frames, canvas, factorizations, seconds, flipped triangles (total).
    """
    t0 = time.perf_counter()
    kind = output_kind(output)
    check_output_paths(output_paths(output, kind, frames), formats.split_prefix(input)[1], mask)
    prefetch_engine()
    image, feature_mask, warnings = load_image_and_mask(settings, formats.split_prefix(input)[1], mask)
    height, width = image.shape[:2]
    if settings.strict and warnings:
        raise WarpError(f"--strict: {warnings[0]}; nothing written")
    per_frame = frame_params(settings, ranges, frames)
    warps, largest = [], (0, 0)
    for params in per_frame:
        warp, warper = make_warper(Settings(**{**settings.__dict__, "params": params}), width, height,
                                   feature_mask)
        warps.append(warp)
        largest = max(largest, tuple(warp.canvas), key=lambda size: size[0] * size[1])
        check_frames_fit(settings, frames, largest)      # frames share the largest canvas: refused early
    if settings.cell is None:                  # one grid fine enough for every frame: one factorization
        warper = _one_grid(settings, warps, width, height, feature_mask)
    fmt = "png" if kind != "video" else "bmp"
    background = background_colour(settings.background, fmt) if kind != "video" else (
        parse_colour(settings.background) if settings.background else (255, 255, 255))
    alpha = kind != "video" and background is None
    canvas = (max(w.canvas[0] for w in warps), max(w.canvas[1] for w in warps))
    check_frames_fit(settings, frames, canvas)
    if kind != "video":                       # refused before any frame is made, not after
        check_encodable(canvas, formats.format_name(os.path.splitext(output)[1]) or "png")
    fill = (0, 0, 0, 0) if alpha else tuple(background[::-1]) + (255,)
    rendered, flips, said, still = [], 0, [], 0
    for index, warp in enumerate(warps):
        mesh = solve_within_budget(warper, warp, settings.mode)
        flips += mesh.info["flipped_triangles"]
        check_solution(replace(settings, strict=False), mesh)
        lines = [line.replace(LISTED_IN_REPORT, "") for line in mesh.record.warnings]   # no report
        still += any(line.startswith(STILL) for line in lines)      # a frame at rest: said once, for all
        said.extend((index, line) for line in lines if not line.startswith(STILL))
        if settings.strict and said:          # nothing is written before every frame is solved
            raise WarpError(f"--strict: frame {said[0][0]}: {said[0][1]}; nothing written")
        frame = to_bgr(warper.render(image, mesh, settings.interp, background, order="bgr"), alpha)
        rendered.append(centre_on(frame, canvas, fill))
        if progress:
            progress(1)
    at_rest = ["no frame moves a pixel: every frame is the input"] * (still == frames)    # the whole animation's
    if settings.strict and at_rest:
        raise WarpError(f"--strict: {at_rest[0]}; nothing written")
    write_frames(output, kind, rendered, fps, settings.quality)
    lines = at_rest + [f"frame {index}: {line}" for index, line in said[:FRAME_WARNINGS]]
    if len(said) > FRAME_WARNINGS:
        first, last = said[FRAME_WARNINGS][0], said[-1][0]
        where = f"frame {first}" if first == last else f"frames {first} to {last}"
        lines.append(f"{len(said) - FRAME_WARNINGS} more compromises in {where} "
                     f"(featurewarp warp with a frame's values says each)")
    return {"frames": frames, "canvas": canvas, "factorizations": warper.factorizations,
            "flipped_triangles": flips, "seconds": time.perf_counter() - t0, "warnings": warnings + lines}


def _one_grid(settings: Settings, warps: list, width: int, height: int, feature_mask):
    """The warper of every frame: on the finest automatic cell the frames' warps need (sub-pixel
    too, as the rule's own), held to the memory budget as a solve holds an automatic grid."""
    cell = min(fidelity.auto_cell(width, height, w)[0] for w in warps)
    warper = make_warper(settings, width, height, feature_mask)[1]
    try:
        fidelity.check_budget(width, height, cell, warper.max_nodes)
    except fidelity.GridBudgetError as err:
        raise WarpError(str(err)) from None
    warper.cell, warper.cell_chosen_automatically = cell, True
    return warper


def output_paths(output: str, kind: str, frames: int) -> list[str]:
    """The files an animation writes: one, or a sequence's ``frames`` names (a usage error for a
    name longer than a file system allows, before anything is made: ``%0200000000d``)."""
    if kind != "sequence":
        return [output]
    widths = [int(width or 0) for width in re.findall(r"%0?(\d*)d", os.path.basename(output))]
    last = "" if max(widths, default=0) > 255 else output % max(frames - 1, 0)      # formatted when bounded
    if not last or len(os.fsencode(last)) > 4096 or len(os.fsencode(os.path.basename(last))) > 255:
        raise WarpError(f"{output[:80]}{'...' if len(output) > 80 else ''}: its frames' names would be longer "
                        "than a file system allows (255 bytes a name)", "OUTPUT", usage=True)
    return [output % index for index in range(frames)]


def check_output_paths(paths: list[str], input: str, mask: str | None) -> None:
    """Usage error unless every frame file can be written and none is the mask (a sequence's
    frame named like it replaced it) or, in a sequence, INPUT (one animation file may be INPUT,
    as warp's OUTPUT may: it is read first)."""
    from .outputs import check_distinct

    probed = set()
    for path in paths:                    # a sequence's names differ by their numbers
        folder = os.path.dirname(os.path.abspath(path))
        try:
            if folder not in probed or os.path.lexists(path):    # a folder is probed once, not per frame
                write.check_writable(path)
        except ValueError as err:
            raise WarpError(str(err), "OUTPUT", usage=True) from None
        probed.add(folder)
        check_distinct([(path, "OUTPUT")], [(input, "INPUT"), (mask, "--mask")], output_may_be_input=len(paths) == 1)


def write_frames(output: str, kind: str, frames: list[np.ndarray], fps: float, quality: int | None = None) -> None:
    """Write ``frames`` all or nothing: a sequence's frames as :func:`featurewarp_cli.io.encode.encode_image`
    PNG bytes, staged together (:func:`featurewarp_cli.io.write.write_outputs`); an animated WebP
    by Pillow, lossless (every pixel kept) unless ``quality`` is given, as a still WebP (OpenCV
    wrote it lossy whatever --quality said); another animation or a video as OpenCV encodes it
    into a hidden temporary file (removed on a signal too), whose bytes are then put in place."""
    if kind == "sequence":
        write.write_outputs([(output % index, encode_image(frame, "png")) for index, frame in enumerate(frames)])
        return
    directory = os.path.dirname(os.path.abspath(output))
    ext = os.path.splitext(output)[1].lower()
    if kind == "animation" and ext == ".webp":
        write.write_atomic(output, _webp_animation(frames, max(1, round(1000.0 / fps)), quality))
        return
    with write.temporary_file(directory, ext) as tmp:
        if kind == "animation":
            animation = cv2.Animation()
            animation.frames = frames
            animation.durations = [max(1, round(1000.0 / fps))] * len(frames)
            written = cv2.imwriteanimation(tmp, animation)
        else:
            size = (frames[0].shape[1], frames[0].shape[0])
            writer = cv2.VideoWriter(tmp, cv2.VideoWriter_fourcc(*VIDEO[ext]), fps, size)
            written = writer.isOpened()
            for frame in frames:
                writer.write(frame)
            writer.release()
        if not written or os.path.getsize(tmp) == 0:
            raise WarpError(f"OpenCV could not write {output}")
        with open(tmp, "rb") as encoded:         # renamed into place with the usual permissions
            write.write_atomic(output, encoded.read())


def _webp_animation(frames: list[np.ndarray], duration: int, quality: int | None) -> bytes:
    """Animated WebP bytes of BGR(A) ``frames``, each shown ``duration`` ms, looping: lossless in
    libwebp's exact mode (the colour under transparent pixels kept too), or lossy at ``quality``."""
    import io

    from PIL import Image

    images = [Image.fromarray(rgb_order(frame)) for frame in frames]
    buffer = io.BytesIO()
    images[0].save(buffer, "WEBP", save_all=True, append_images=images[1:], duration=duration, loop=0,
                   **webp_options(quality))
    return buffer.getvalue()

"""Animations: one preset parameter (or several) varied over frames, factoring once.

Writes an animated GIF, WebP or PNG (APNG, :mod:`featurewarp_cli.io.animation`), an MP4/AVI
video through OpenCV's video writer (its sides padded to even with the background), or a
numbered PNG sequence (a path with a ``%d``-style field). The background and the metadata kept
are a still output's of the format (GIF: white unless transparent; video: white, no alpha).
"""

from __future__ import annotations

import os
import re
import time
from dataclasses import replace

import cv2
import numpy as np

from .. import plugins
from ..engine import fidelity
from ..engine.assess import STILL
from ..engine.record import LISTED_IN_REPORT
from ..io import ImageError, animation, formats, profiles, write
from ..io.animation import GIF_MAX_FPS
from ..io.colours import TRANSPARENT
from ..io.depth import to_eight_bit
from ..io.encode import encode_image, flatten
from ..io.metadata import Metadata
from ..plugins import ParamError, did_you_mean
from .outputs import background_colour, check_encodable, kept_metadata, rendered
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
    numeric = [name for name, p in names.items() if p.type in (int, float)]
    ranges = {}
    for text in texts:
        match = re.fullmatch(r"\s*([\w-]+)\s*=\s*([^:]+):([^:]+)\s*", text)
        if not match:
            raise WarpError(f"{text!r} is not NAME=START:END", "--vary", usage=True)
        name, start, end = match.groups()
        if name not in names:
            hint = did_you_mean(name, numeric) + _can_vary(preset.name, numeric)
            raise WarpError(f"{preset.name} has no parameter {name!r}; {hint}", "--vary", usage=True)
        param = names[name]
        if param.name in ranges:
            raise WarpError(f"{name} is given twice", "--vary", usage=True)
        if param.type not in (int, float):
            others = f"it can: {', '.join(numeric)}" if numeric else _can_vary(preset.name, numeric)
            raise WarpError(f"{name} is not a number and cannot vary ({others})", "--vary", usage=True)
        try:
            ranges[param.name] = (param.check(start), param.check(end))
        except ParamError as err:               # named as --vary names it: NAME=START:END
            raise WarpError(err.render(lambda name: name.replace("_", "-")), "--vary", usage=True) from None
    if not ranges:
        raise WarpError("give at least one NAME=START:END", "--vary", usage=True)
    return ranges


def _can_vary(preset: str, numeric: list) -> str:
    """What ``--vary`` can take of ``preset``: ``it can vary: angle, radius``, or that nothing can."""
    return f"it can vary: {', '.join(numeric)}" if numeric else f"{preset} has no parameter that can vary"


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
    """'sequence' (a %d field in the name), 'animation' or 'video'; a usage error for stdout or a
    ``gif:``-style prefix (one was taken into the file's name)."""
    if path == "-" or formats.split_prefix(path)[0] or write.descriptor_of(path) is not None:
        raise WarpError(f"{path}: an animation is written to a file, its format from its extension (not to "
                        "stdout, nor with a format prefix)", "OUTPUT", usage=True)
    name = os.path.basename(path).replace("%%", "")
    if re.search(r"%[-#0 +]*\d*[siuxX](?![A-Za-z])", name):     # %s, %05i: meant as a frame number
        raise WarpError(f"{path}: a numbered sequence's name holds one %d field (such as %04d), and %% for a "
                        "percent sign", "OUTPUT", usage=True)
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


def to_bgr(image: np.ndarray, alpha: bool, background=(255, 255, 255)) -> np.ndarray:
    """8-bit BGR (or BGRA when ``alpha``) from any gray/BGR/BGRA 8/16-bit image; without
    ``alpha``, an image's own alpha is laid over ``background`` (r, g, b) as a still output's
    (the colour under its transparent pixels came out)."""
    image = to_eight_bit(image)
    if image.ndim == 2:
        image = cv2.cvtColor(image, cv2.COLOR_GRAY2BGR)
    if alpha and image.shape[2] == 3:
        image = cv2.cvtColor(image, cv2.COLOR_BGR2BGRA)
    if not alpha and image.shape[2] == 4:
        image = flatten(image, background[:3])
    return image


def frame_background(text: str | None, kind: str, ext: str):
    """The frames' background from ``--background`` (usage errors before any work): as a still
    output of the format has it (:func:`featurewarp_cli.app.outputs.background_colour`: white
    for GIF and video, transparent for PNG and WebP; a translucent colour laid over white where
    the format has no alpha). A GIF may be transparent too (its pixels cut at half alpha); a
    video cannot."""
    transparent = text is not None and text.strip().lower() in TRANSPARENT
    if kind == "video" and transparent:
        raise WarpError(f"{text}: {ext[1:].upper()} video has no alpha channel; give a colour (default white)",
                        "--background", usage=True)
    if ext == ".gif" and transparent:
        return None
    return background_colour(text, "jpg" if kind == "video" else "gif" if ext == ".gif" else "png")


def fill_of(background, alpha: bool) -> tuple:
    """The BGR(A) sample of ``background`` ((r, g, b), (r, g, b, a) or None: transparent)."""
    if background is None:
        return (0, 0, 0, 0)
    bgr = tuple(background[2::-1])
    return bgr + ((background[3] if len(background) == 4 else 255),) if alpha else bgr


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
    kind, ext = output_kind(output), os.path.splitext(output)[1].lower()
    check_output_paths(output_paths(output, kind, frames), formats.split_prefix(input)[1], mask)
    background = frame_background(settings.background, kind, ext)
    prefetch_engine()
    image, feature_mask, warnings, header = load_with_header(settings, formats.split_prefix(input)[1], mask)
    warnings += left_after(output, kind, frames)
    kept = output_metadata(settings.strip, header, kind, ext, warnings)
    if ext == ".gif" and kind == "animation" and fps > GIF_MAX_FPS:
        warnings.append(f"--fps {fps:g}: a GIF plays at most {GIF_MAX_FPS:g} frames a second (its delays are in "
                        f"1/100 s, and browsers show one under 2/100 s for 1/10 s): written at {GIF_MAX_FPS:g}")
    if image.dtype == np.uint16:
        warnings.append("the input has 16 bits a sample; the animation's frames have 8 (GIF, WebP and video hold no "
                        "more, and APNG and PNG frames are written as the animation's: warp keeps 16 bits)")
    height, width = image.shape[:2]
    if settings.strict and warnings:
        raise WarpError(f"--strict: {warnings[0]}; nothing written")
    per_frame = frame_params(settings, ranges, frames)
    warps, warper = frame_warps(settings, per_frame, ranges, width, height, feature_mask)
    check_vary_moves(settings, ranges, warps, width, height)
    if settings.cell is None:                  # one grid fine enough for every frame: one factorization
        warper = _one_grid(settings, warps, width, height, feature_mask)
    alpha = background is None or (kind != "video" and ext != ".gif" and (
        len(background) == 4 or (image.ndim == 3 and image.shape[2] in (2, 4))))
    canvas = (max(w.canvas[0] for w in warps), max(w.canvas[1] for w in warps))
    if kind == "video":                       # codecs take even sides: padded, not cropped
        canvas = (canvas[0] + canvas[0] % 2, canvas[1] + canvas[1] % 2)
    check_frames_fit(settings, frames, canvas)
    if kind != "video":                       # refused before any frame is made, not after
        check_encodable(canvas, formats.format_name(ext) or "png")
    rendered_frames, flips, said, still, folds = [], 0, [], 0, []
    for index, warp in enumerate(warps):
        try:
            mesh = solve_within_budget(warper, warp, settings.mode)
            check_solution(replace(settings, strict=False), mesh)
        except WarpError as err:
            raise WarpError(f"{frame_name(index, per_frame[index], ranges)}: {err}", usage=err.usage) from None
        flipped = mesh.info["flipped_triangles"]
        flips += flipped
        lines = [line.replace(LISTED_IN_REPORT, "") for line in mesh.record.warnings]   # no report
        still += any(line.startswith(STILL) for line in lines)      # a frame at rest: said once, for all
        said.extend((index, line) for line in lines if not line.startswith(STILL))
        if settings.strict and said:          # nothing is written before every frame is solved
            raise WarpError(f"--strict: frame {said[0][0]}: {said[0][1]}; nothing written")
        if flipped:                           # --allow-folds wrote it: said as warp says it (not refused)
            folds.append((index, f"{flipped} triangles of the mesh fold over; the frame may show folds"))
        frame = to_bgr(rendered(warper, image, mesh, settings.interp, background), alpha, background or ())
        rendered_frames.append(centre_on(frame, canvas, fill_of(background, alpha)))
        if progress:
            progress(1)
    at_rest = ["no frame moves a pixel: every frame is the input"] * (still == frames)    # the whole animation's
    if settings.strict and at_rest:
        raise WarpError(f"--strict: {at_rest[0]}; nothing written")
    write_frames(output, kind, rendered_frames, fps, settings.quality, kept, transparent=background is None)
    return {"frames": frames, "canvas": canvas, "factorizations": warper.factorizations,
            "flipped_triangles": flips, "seconds": time.perf_counter() - t0,
            "warnings": warnings + at_rest + frame_lines(sorted(said + folds, key=lambda pair: pair[0]))}


def frame_lines(said: list[tuple[int, str]]) -> list[str]:
    """The frames' compromises ((frame, line) pairs) as warnings: ``frame N: ...`` for the first
    :data:`FRAME_WARNINGS`, then one line counting the rest."""
    lines = [f"frame {index}: {line}" for index, line in said[:FRAME_WARNINGS]]
    if len(said) > FRAME_WARNINGS:
        first, last = said[FRAME_WARNINGS][0], said[-1][0]
        where = f"frame {first}" if first == last else f"frames {first} to {last}"
        lines.append(f"{len(said) - FRAME_WARNINGS} more warning lines in {where} (one may count several "
                     f"features; featurewarp warp with a frame's values says each)")
    return lines


def frame_name(index: int, params: dict, ranges: dict) -> str:
    """``frame 12 (angle 85 of --vary angle=10:160)``: a frame and its varied values."""
    values = ", ".join(f"{name.replace('_', '-')} {params[name]:g} of --vary {name.replace('_', '-')}="
                       f"{start:g}:{end:g}" for name, (start, end) in ranges.items())
    return f"frame {index} ({values})"


def frame_warps(settings: Settings, per_frame: list[dict], ranges: dict, width: int, height: int, feature_mask):
    """Each frame's warp and a warper (any frame's: they differ only in the warp). A frame's
    refused values are a usage error naming the frame and its varied values, the varied
    parameters by name (their options cannot be given beside --vary); the memory limit is
    checked as the canvases grow."""
    warps, largest, warper = [], (0, 0), None
    for index, params in enumerate(per_frame):
        try:
            warp = plugins.load(settings.preset)(width, height, **params) if settings.warp_factory is None \
                else settings.warp_factory(width, height, feature_mask)
        except plugins.ParamError as err:
            detail = err.render(lambda name: name.replace("_", "-") if name in ranges else plugins.option_flag(name))
        except ValueError as err:
            detail = str(err)
        else:
            detail = None
        if detail is not None:
            raise WarpError(f"{frame_name(index, params, ranges)}: {detail}", usage=True) from None
        warp, warper = make_warper(replace(settings, params=params, warp_factory=lambda *_, made=warp: made),
                                   width, height, feature_mask)
        warps.append(warp)
        largest = max(largest, tuple(warp.canvas), key=lambda size: size[0] * size[1])
        check_frames_fit(settings, len(per_frame), largest)      # frames share the largest canvas: refused early
    return warps, warper


def check_vary_moves(settings: Settings, ranges: dict, warps: list, width: int, height: int) -> None:
    """Usage error when the varied values change no frame though they vary: another option given
    overrides them (stretch's --size or --width over a varied sx wrote a still animation). Frames
    that are all the input are left to the at-rest warning."""
    if len(warps) < 2 or all(start == end for start, end in ranges.values()):
        return
    points = np.stack(np.meshgrid(np.linspace(0, width - 1, 5), np.linspace(0, height - 1, 5)), -1).reshape(-1, 2)
    first = warps[0].forward(points)
    if np.allclose(first, points) or any(tuple(w.canvas) != tuple(warps[0].canvas)
                                         or not np.array_equal(w.forward(points), first) for w in warps[1:]):
        return
    varied = ", ".join(name.replace("_", "-") for name in ranges)
    given = _overriding(settings, ranges, warps, points)
    verb = "override" if " and " in given else "overrides"
    raise WarpError(f"the varied {varied} changes no frame: {given} {verb} it; drop {given} to vary {varied}",
                    "--vary", usage=True)


def _overriding(settings: Settings, ranges: dict, warps: list, points: np.ndarray) -> str:
    """The flags of the options given (not default, not varied) without which the first and last
    frames differ: those that override the varied values (stretch's --size over sx, not --sy);
    where no one alone frees them (--width and --size over sx), those that declare overriding
    them (:attr:`plugins.Param.overrides`), together; else 'an option given'."""
    if settings.warp_factory is not None:       # not the preset's warps: nothing to try without
        return "an option given"
    preset = plugins.load(settings.preset)
    first, last = dict(warps[0].values), dict(warps[-1].values)
    width, height = warps[0].width, warps[0].height

    def moves(name, default):
        try:
            a, b = (preset(width, height, **(values | {name: default})) for values in (first, last))
        except ValueError:                       # refused without it: it does not free the varied ones
            return False
        return tuple(a.canvas) != tuple(b.canvas) or not np.array_equal(a.forward(points), b.forward(points))

    given = [p for p in preset.params if p.name not in ranges and settings.params.get(p.name, p.default) != p.default]
    alone = [plugins.option_flag(p.name) for p in given if moves(p.name, p.default)]
    together = [plugins.option_flag(p.name) for p in given if set(p.overrides) & set(ranges)]
    return " or ".join(alone) or " and ".join(together) or "an option given"


def load_with_header(settings: Settings, input: str, mask: str | None):
    """:func:`featurewarp_cli.app.pipeline.load_image_and_mask`, and INPUT's header (None where
    it cannot be read): the metadata an output keeps (:func:`featurewarp_cli.app.outputs.kept_metadata`)."""
    from ..io import decode
    from .pipeline import input_bytes

    data = input_bytes(settings, input)
    image, feature_mask, warnings = load_image_and_mask(settings, input, mask, data)
    return image, feature_mask, warnings, decode.read_header(data) if data else None


def output_metadata(strip: bool, header, kind: str, ext: str, warnings: list) -> Metadata:
    """What of the input's metadata the animation keeps (:func:`featurewarp_cli.app.outputs.kept_metadata`):
    all of it in PNG frames and APNG, the profile, EXIF and XMP in WebP, none in GIF and video
    (said in ``warnings`` unless ``strip``)."""
    if kind == "video":
        said = []
        kept_metadata(strip, header, "bmp", said)
        warnings.extend(line.replace("BMP output", f"{ext[1:].upper()} video") for line in said)
        return Metadata()
    return kept_metadata(strip, header, {".gif": "gif", ".webp": "webp"}.get(ext, "png"), warnings)


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


def left_after(output: str, kind: str, frames: int) -> list[str]:
    """The warning for numbered files that follow a sequence's last frame (left by a longer run:
    a reader of the sequence takes them as its frames too); [] for none and for one file."""
    if kind != "sequence":
        return []
    left = 0
    while left < 1_000_000 and os.path.lexists(output % (frames + left)):
        left += 1
    if left == 0:
        return []
    if left == 1:
        return [f"{output % frames} (1 file) follows this sequence's last frame, left from another run: "
                f"whatever reads {output} takes it as a frame too"]
    return [f"{output % frames} to {output % (frames + left - 1)} ({left} files) follow this sequence's last "
            f"frame, left from another run: whatever reads {output} takes them as frames too"]


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


def write_frames(output: str, kind: str, frames: list[np.ndarray], fps: float, quality: int | None = None,
                 kept: Metadata | None = None, transparent: bool = False) -> None:
    """Write ``frames`` all or nothing, with the metadata ``kept`` where the format holds it.

    A sequence's frames are :func:`featurewarp_cli.io.encode.encode_image` PNGs, staged together
    (:func:`featurewarp_cli.io.write.write_outputs`); a GIF, APNG or WebP is encoded by
    :mod:`featurewarp_cli.io.animation` (WebP lossless unless ``quality`` is given; a GIF
    ``transparent`` where alpha is under half); a video is written by OpenCV into a hidden
    temporary file (removed on a signal too), whose bytes are then put in place.
    """
    kept = kept or Metadata()
    try:
        if kind == "sequence":
            write.write_outputs([(output % index, encode_image(frame, "png", **kept.keywords()))
                                 for index, frame in enumerate(frames)])
            return
        ext = os.path.splitext(output)[1].lower()
        if kind == "animation":
            if ext == ".gif":
                data = animation.gif_bytes(frames, fps, transparent)
            elif ext == ".webp":
                data = animation.webp_bytes(frames, fps, quality, profiles.for_pixels(kept.icc, frames[0].shape[2]),
                                            kept.exif, kept.xmp)
            else:
                data = animation.apng_bytes(frames, fps, **kept.keywords())
            write.write_atomic(output, data)
            return
    except ImageError as err:
        raise WarpError(f"cannot write {output}: {err}") from err
    _write_video(output, ext, frames, fps)


def _write_video(output: str, ext: str, frames: list[np.ndarray], fps: float) -> None:
    """An MP4 or AVI video of 8-bit BGR ``frames`` by OpenCV's video writer (:data:`VIDEO` codecs)."""
    with write.temporary_file(os.path.dirname(os.path.abspath(output)), ext) as tmp:
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

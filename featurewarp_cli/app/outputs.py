"""A command's outputs: their formats and background, the rendered result, and checks that they
name no input nor each other."""

from __future__ import annotations

import os
import stat
from dataclasses import replace

import numpy as np

from ..io import ImageError, colours, decode, encode, formats, metadata, write


def format_of(path: str) -> str | None:
    """The output format name of an image file's own format (its header), or None."""
    try:
        with open(path, "rb") as handle:
            header = decode.read_header(handle.read(1 << 16))
    except OSError:
        return None
    return formats.format_name(header.format) if header is not None else None


def file_identity(path: str):
    """What a path names, for comparing two: (device, inode) of an existing file, else the
    absolute path with links resolved."""
    try:
        info = os.stat(path)
    except OSError:
        return os.path.realpath(path)
    return (info.st_dev, info.st_ino) if stat.S_ISREG(info.st_mode) else None


def check_encodable(canvas, fmt: str) -> None:
    """Usage error, before any work, for a canvas larger than ``fmt``'s encoder writes (a stretch
    of a wide strip failed after the solve: "cannot encode the result as png")."""
    from .pipeline import WarpError

    largest = formats.FORMATS[fmt].largest_side
    if largest is not None and max(canvas) > largest:
        raise WarpError(f"the result would be {canvas[0]}x{canvas[1]} pixels; {fmt} holds at most {largest} a "
                        "side (another --format, or a smaller result)", "OUTPUT", usage=True)


def writable(path: str, param: str) -> None:
    """Usage error (WarpError naming ``param``) unless ``path`` can be written (:func:`write.check_writable`)."""
    from .pipeline import WarpError

    try:
        write.check_writable(path)
    except ValueError as err:
        raise WarpError(str(err), param, usage=True) from None


def check_outputs(settings, output: str, *extra: tuple[str | None, str], like: str | None = None):
    """Resolve OUTPUT's path and format and check that it and ``extra`` (path, option) can be written.

    ``-`` as OUTPUT without ``--format`` or a prefix takes the format of the file ``like``
    (INPUT), read from its first bytes."""
    from .pipeline import WarpError

    fmt = settings.fmt
    if fmt is None and output == "-" and like not in (None, "-"):
        fmt = format_of(like)
    try:
        out_path, fmt = formats.output_target(output, fmt)
    except ValueError as err:
        raise WarpError(str(err), "OUTPUT", usage=True) from None
    if out_path != "-":
        writable(out_path, "OUTPUT")
    for path, param in extra:
        if path and path != "-":
            writable(path, param)
    if getattr(settings, "quality", None) is not None and fmt not in QUALITY_FORMATS:
        from .. import stages

        name = fmt.upper()
        stages.notice(f"--quality does nothing for a {name} output (it sets the quality of JPEG and WebP; "
                      f"{name} is {'lossless' if fmt != 'gif' else 'a 256-colour palette'})", once=True)
    return out_path, fmt


#: The output formats that take ``--quality``; a notice says it does nothing for the others.
QUALITY_FORMATS = ("jpg", "webp")


def check_grid_name(save_grid: str | None) -> None:
    """--save-grid names one of the two forms it writes (another name silently got an npz)."""
    from .pipeline import WarpError

    if save_grid and save_grid != "-" and not save_grid.lower().endswith((".npz", ".obj")):
        raise WarpError(f"{save_grid} names neither an .npz nor an .obj file (the two forms it writes)",
                        "--save-grid", usage=True)


def check_distinct(outputs: list[tuple[str | None, str]], inputs: list[tuple[str | None, str]],
                   output_may_be_input: bool = True) -> None:
    """Usage error unless the outputs ((path, option) pairs; the first is OUTPUT) name neither an
    input nor each other, OUTPUT = INPUT excepted where ``output_may_be_input`` (the input is
    read before anything is written), and at most one of them is stdout. Devices and FIFOs may
    repeat."""
    from .pipeline import WarpError

    named = [(p, o) for p, o in outputs if p]
    streams = {}
    for path, option in named:                # '-', /dev/stdout, /dev/fd/1: one stream
        streams.setdefault(write.descriptor_of(path), []).append(option)
    for descriptor, options in streams.items():
        if descriptor is not None and len(options) > 1:
            where = "stdout ('-')" if descriptor == 1 else f"descriptor {descriptor}"
            raise WarpError(f"only one output can go to {where}: {', '.join(options)}", usage=True)
    files = [(p, o, file_identity(p)) for p, o in named if p != "-"]
    sources = [(p, o, file_identity(p)) for p, o in inputs if p and p != "-"]
    for k, (path, option, ident) in enumerate(files):
        if ident is None:
            continue
        exempt = k == 0 and output_may_be_input
        for other, other_option, other_ident in files[:k] + [s for s in sources if not (exempt and s[1] == "INPUT")]:
            if ident == other_ident:
                raise WarpError(f"{path} is also {other_option} ({other}); it would be overwritten",
                                option, usage=True)


#: The most EXIF bytes a JPEG holds (one APP1 segment, as Pillow writes it).
JPEG_EXIF_BYTES = 65533


def kept_metadata(strip: bool, header, fmt: str, warnings: list) -> metadata.Metadata:
    """What of the input's metadata to write with the output, said before any work.

    Parameters
    ----------
    strip : bool
        ``--strip``: keep nothing.
    header : featurewarp_cli.io.decode.Header or None
        INPUT's header (None where it could not be read: nothing is kept).
    fmt : str
        The output format name.
    warnings : list of str
        Appended to, so that stderr, the report and ``--strict`` see them: what ``fmt`` cannot
        keep and a CMYK input without a usable profile (:func:`featurewarp_cli.io.metadata.unkept`,
        under ``strip`` too), and an EXIF block larger than a JPEG holds, which is left out
        (the whole run failed after the solve: "EXIF data is too long").

    Returns
    -------
    featurewarp_cli.io.metadata.Metadata
        ICC profile, EXIF, XMP and resolution; every field None with ``strip``.
    """
    warnings.extend(metadata.unkept(header, fmt, strip))
    kept = metadata.Metadata() if strip else metadata.Metadata.of(header)
    if fmt == "jpg" and kept.exif and len(kept.exif) > JPEG_EXIF_BYTES:
        warnings.append(f"the input's EXIF ({len(kept.exif)} bytes) is more than a JPEG holds "
                        f"({JPEG_EXIF_BYTES}): left out")
        kept = replace(kept, exif=None)
    return kept


def depth_lost(image, fmt: str) -> list[str]:
    """A warning where ``fmt`` holds fewer bits a sample than the decoded ``image`` has (16-bit
    to JPEG, WebP...), as compare and animate say of their 8-bit outputs; [] otherwise."""
    if image.dtype.itemsize == 1 or not formats.FORMATS[fmt].eight_bit:
        return []
    name = {"jpg": "JPEG", "webp": "WebP"}.get(fmt, fmt.upper())
    return [f"the input has 16 bits a sample; {name} holds 8 (PNG and TIFF keep 16)"]


def encoded(out_path: str, fmt: str, image, background, quality: int | None = None,
            kept: metadata.Metadata | None = None) -> bytes:
    """``image`` encoded as ``fmt``, with a quality and the metadata to keep (:func:`kept_metadata`;
    None: none); failures are WarpError naming ``out_path``."""
    from .pipeline import WarpError

    try:
        return encode.encode_image(image, fmt, background, quality, **(kept or metadata.Metadata()).keywords())
    except ImageError as err:
        raise WarpError(f"cannot write {out_path}: {err}") from err


def write_image(out_path: str, fmt: str, image, background) -> None:
    """Encode and write atomically (``-``: stdout); failures are WarpError."""
    write_all([(out_path, encoded(out_path, fmt, image, background))])


def write_all(outputs: list[tuple[str, bytes]]) -> None:
    """Write every (path, bytes) or none (:func:`featurewarp_cli.io.write.write_outputs`);
    failures are WarpError naming the path."""
    from .pipeline import WarpError

    try:
        write.write_outputs(outputs)
    except OSError as err:
        path = err.filename or next((p for p, _ in outputs if p), "")
        raise WarpError(f"cannot write {path}: {err.strerror or err}") from err


def background_colour(text: str | None, fmt: str):
    """(r, g, b) fill for uncovered pixels, (r, g, b, a) for a translucent one, or None
    (transparent), for output format ``fmt`` (without alpha: a translucent colour over white)."""
    from .pipeline import WarpError

    has_alpha = formats.FORMATS[fmt].alpha
    if text is None:
        return None if has_alpha else (255, 255, 255)
    try:
        rgb = colours.parse_colour(text, alpha=True)
    except ValueError as err:
        raise WarpError(str(err), "--background", usage=True) from None
    if rgb is not None and len(rgb) == 4 and not has_alpha:
        return tuple(round(c * rgb[3] / 255 + 255 * (1 - rgb[3] / 255)) for c in rgb[:3])
    if rgb is None and not has_alpha and fmt != "gif":       # a GIF: transparent below half alpha
        raise WarpError(f"{fmt} has no alpha channel; use a colour or a png, webp, tiff or gif output",
                        "--background", usage=True)
    return rgb


#: Pillow's modes of gray pixels decoded to 8 bits (a header's ``mode``): alone (``1``: bilevel,
#: decoded as 0/255 gray), and with straight or premultiplied alpha.
GRAY_MODES = ("1", "L", "LA", "La")


def rendered(warper, image, mesh, interp: str, background, header=None, grid: bool = False):
    """The BGR(A) image through ``mesh``; a translucent (r, g, b, a) background is laid under a
    transparent render. A gray image under a colour that is not gray is rendered in colour (the
    fill came out as its luma). With INPUT's ``header``, a gray + alpha input's result in its
    own form (:func:`gray_alpha_form`); with ``grid``, the mesh's lines drawn over it
    (:func:`featurewarp_cli.app.panel.draw_grid`, in colour)."""
    if background is not None and len(set(background[:3])) > 1 and image.ndim == 2:
        import cv2

        image = cv2.cvtColor(image, cv2.COLOR_GRAY2BGR)
    if background is None or len(background) == 3:
        result = warper.render(image, mesh, interp, background, order="bgr")
    else:
        from ..render.raster import under_colour

        result = under_colour(warper.render(image, mesh, interp, None, order="bgr"), background)
    result = gray_alpha_form(result, header)
    if grid:
        from .panel import draw_grid

        result = draw_grid(result, mesh)
    return result


def gray_alpha_form(image, header):
    """A BGRA result as (h, w, 2) gray + alpha where INPUT is gray (its ``header``'s mode,
    :data:`GRAY_MODES`: decoding made gray + alpha BGRA, and a gray canvas that gains
    transparency is rendered BGRA) and its three colour channels are equal (not under a coloured
    ``--background``): the encoder then keeps that form where the format has it
    (:func:`featurewarp_cli.io.encode.keeps_gray_alpha`), as ImageMagick does. Else ``image``."""
    if (header is None or header.mode not in GRAY_MODES or image.ndim != 3 or image.shape[2] != 4
            or not (np.array_equal(image[:, :, 0], image[:, :, 1]) and np.array_equal(image[:, :, 0], image[:, :, 2]))):
        return image
    return np.ascontiguousarray(image[:, :, [0, 3]])

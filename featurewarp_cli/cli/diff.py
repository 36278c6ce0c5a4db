"""``featurewarp diff A B``: compare two images within a tolerance (golden files in CI)."""

from __future__ import annotations

import io
import os
from dataclasses import dataclass

import click

from .options import MAX_PIXELS_OFF, MAX_RMSE, MIN_PSNR, TOLERANCE, option
from .presets import click_error


@click.command("diff")
@click.argument("a", type=click.Path(dir_okay=False, allow_dash=True))
@click.argument("b", type=click.Path(dir_okay=False, allow_dash=True))
@option(MAX_RMSE)
@option(MIN_PSNR)
@option(MAX_PIXELS_OFF)
@option(TOLERANCE)
@click.option("--diff-image", type=click.Path(dir_okay=False), metavar="PATH",
              help="Write A in faded gray with the pixels off in red.")
@click.option("-q", "--quiet", is_flag=True, help="Print no metrics; only the exit status tells.")
@click.option("--json", "as_json", is_flag=True,
              help="Print the metrics as one JSON object (a, b: the two paths; rmse, psnr: null when "
                   "identical, max_abs, pixels_off, pixels, tolerance, within, failures; for animations "
                   "and multi-page files also frames and frames_off, the frames with a pixel off, from 1) "
                   "instead of text; images that cannot be compared (sizes, frame counts) give null figures "
                   "and the reason.")
def diff_command(a, b, max_rmse, min_psnr, max_pixels_off, tolerance, diff_image, quiet, as_json):
    """Compare images A and B (e.g. an output with its golden file).

    Prints RMSE, PSNR, the largest absolute difference and the pixels off, on
    the 0..255 scale (16-bit samples divided by 257), every channel and alpha
    included (colour premultiplied by alpha: what it adds over any background,
    so the colour under fully transparent pixels counts as 0). Gray is
    compared as R = G = B and no alpha as opaque. Animations and multi-page files
    are compared frame by frame; differing frame counts or frame durations fail.
    Exit 0 within tolerance, 1 beyond it or when the sizes or frame counts differ,
    2 when A or B cannot be read, the results cannot be written (as cmp and diff) or
    the command is misused.
    Without --max-rmse, --min-psnr or --max-pixels-off, or with --tolerance and no
    --max-pixels-off, the images must match within --tolerance everywhere. One of
    A and B may be '-' (stdin).

    \b
    Example:
      featurewarp diff out.png golden.png --max-rmse 0.5 --diff-image diff.png
    """
    context = click.get_current_context()
    quiet = quiet or bool(context.meta.get("featurewarp.quiet"))
    tolerance_given = context.get_parameter_source("tolerance") == click.core.ParameterSource.COMMANDLINE
    from ..app import diff
    from ..app.pipeline import WarpError

    if a == "-" and b == "-":
        raise click.UsageError("only one of A and B can be '-' (stdin)")
    target = _diff_target(diff_image, a, b, quiet) if diff_image else None
    try:
        first, second = (_read_within_budget(path, name) for path, name in ((a, "A"), (b, "B")))
        result, reason = _compare(first, second, tolerance)
    except WarpError as err:            # trouble, as cmp and diff say it: 2, never "differ" (1)
        error = click_error(err)
        error.exit_code = 2
        raise error from err
    if reason:
        if as_json and not quiet:         # a CI job parses the failure as it parses any other
            _echo(_as_json(a, b, None, [f"cannot be compared: {reason}"], tolerance))
        unwritten = f"; {diff_image} not written" if diff_image else ""
        _differ(quiet, f"{a} and {b} cannot be compared: {reason}{unwritten}")
    for note in result.notes if not quiet else ():
        click.echo(f"featurewarp: note: {note}", err=True)
    broken = diff.failures(result, max_rmse, min_psnr, max_pixels_off, tolerance_given)
    broken += _durations_differ(first.durations, second.durations)
    if as_json and not quiet:
        _echo(_as_json(a, b, result, broken))
    elif not quiet:
        _echo("\n".join(result.lines()))
    if target:
        _write_highlight(target, diff.highlight(first.image, result.off))
    if broken:
        _differ(quiet, f"{a} and {b} differ beyond tolerance: {'; '.join(broken)}")


def _differ(quiet: bool, message: str):
    """Exit 1, "differ", saying why unless ``quiet`` (as ``cmp -s``: trouble, 2, is still said)."""
    if quiet:
        raise click.exceptions.Exit(1)
    raise click.ClickException(message)


def _diff_target(diff_image: str, a: str, b: str, quiet: bool) -> tuple[str, str]:
    """(path, format) of ``--diff-image``, checked: not A or B, not stdout while the metrics go
    there, writable."""
    from ..io import formats, write

    for path, name in ((a, "A"), (b, "B")):
        if path != "-" and os.path.exists(diff_image) and os.path.exists(path) and os.path.samefile(diff_image, path):
            raise click.BadParameter(f"{diff_image} is also {name}; it would be overwritten",
                                     param_hint="'--diff-image'")
    try:
        if diff_image == "-":
            raise ValueError("cannot be '-' (stdout holds the metrics)")
        if diff_image == os.devnull:
            return os.devnull, "png"
        path, fmt = formats.output_target(diff_image, other=f"a prefix: png:{diff_image}")
        if not quiet and _is_stdout(path):
            raise ValueError(f"{path} is stdout, which holds the metrics (with -q it does not)")
        write.check_writable(path)
    except ValueError as err:
        raise click.BadParameter(str(err), param_hint="'--diff-image'") from None
    return path, fmt


#: Names of stdout, recognised where its file cannot be compared (a stdout that is no file).
STDOUT_NAMES = ("/dev/stdout", "/dev/fd/1", "/proc/self/fd/1")


def _is_stdout(path: str) -> bool:
    """Whether ``path`` names the file stdout writes to (``-`` too: ``png:-``)."""
    import sys

    if path == "-":
        return True
    try:
        shown, there = os.fstat(sys.stdout.fileno()), os.stat(path)
    except (OSError, ValueError, AttributeError, io.UnsupportedOperation):
        return os.path.normpath(path) in STDOUT_NAMES
    return (shown.st_dev, shown.st_ino) == (there.st_dev, there.st_ino)


def _write_highlight(target: tuple[str, str], picture) -> None:
    """Write the ``--diff-image`` picture."""
    from ..io import ImageError, encode, write

    path, fmt = target
    try:
        write.write_atomic(path, encode.encode_image(picture, fmt))
    except (ImageError, OSError) as err:
        raise _trouble(f"cannot write {path}: {getattr(err, 'strerror', None) or err}") from err


def _echo(text: str) -> None:
    """The figures on stdout; not written is trouble (2), not "differ" (1). A reader that went away
    (a closed pipe) is the command line's, as for every command."""
    try:
        click.echo(text)
    except BrokenPipeError:
        raise
    except OSError as err:
        raise _trouble(f"cannot write stdout: {err.strerror or err}") from err


def _trouble(message: str) -> click.ClickException:
    """An error of the comparison itself, not of the images: exit 2, as cmp and diff."""
    error = click.ClickException(message)
    error.exit_code = 2
    return error


def _as_json(a: str, b: str, result, broken: list[str], tolerance: float | None = None) -> str:
    """The metrics as one JSON line (infinite PSNR, identical images, as null); ``result`` None:
    images that cannot be compared, every figure null and ``broken`` saying why."""
    import json
    import math

    if result is None:
        figures = dict.fromkeys(("rmse", "psnr", "max_abs", "pixels_off", "pixels"), None)
        figures["tolerance"] = tolerance
    else:
        figures = {"rmse": result.rmse, "psnr": result.psnr if math.isfinite(result.psnr) else None,
                   "max_abs": result.max_abs, "pixels_off": result.pixels_off, "pixels": result.pixels,
                   "tolerance": result.tolerance}
        if result.frames > 1:
            figures.update(frames=result.frames, frames_off=list(result.frames_off))
    return json.dumps({"a": a, "b": b, **figures, "within": not broken, "failures": broken})


#: Peak bytes per pixel of a diff (both images as read, their float differences, the
#: highlight image), measured: two 14142^2 16-bit RGBA images took 15.3 GB.
DIFF_PIXEL_BYTES = 80

#: Bytes per pixel per page of a multi-page TIFF, whose pages OpenCV decodes all at once.
PAGE_PIXEL_BYTES = 8


@dataclass
class Source:
    """A or B as read: its bytes, its still image (the first frame of several), its frame count,
    format (Pillow's name) and frame durations in ms (animations; None for stills and TIFF)."""

    path: str
    name: str
    data: bytes
    image: object
    frames: int = 1
    format: str | None = None
    durations: list | None = None


def _compare(first: Source, second: Source, tolerance: float):
    """(the Comparison of A and B, None) or (None, why they cannot be compared)."""
    from ..app import diff

    if first.frames != second.frames:
        return None, f"frame counts differ: {first.frames} vs {second.frames}"
    try:
        if first.frames == 1:
            return diff.compare(first.image, second.image, tolerance), None
        return diff.compare_frames(zip(_frames(first), _frames(second)), tolerance), None
    except ValueError as err:
        return None, str(err)


def _durations_differ(a: list | None, b: list | None) -> list[str]:
    """The failure of frames shown for different times (the first such frame), or none."""
    for index, (x, y) in enumerate(zip(a or [], b or []), 1):
        if x != y:
            shown = ("unset" if t is None else f"{t:g} ms" for t in (x, y))
            return [f"frame {index} is shown for {' vs '.join(shown)}"]
    return []


def _frame_info(data: bytes) -> tuple[int, str | None, list | None]:
    """(frame count, format, frame durations in ms or None) by Pillow; (1, None, None) where
    Pillow cannot read the file (OpenCV may: a still image then)."""
    import warnings

    from PIL import Image

    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            with Image.open(io.BytesIO(data)) as image:
                count = int(getattr(image, "n_frames", 1))
                durations = None
                if count > 1 and image.format != "TIFF":
                    durations = []
                    for index in range(count):
                        image.seek(index)
                        image.load()              # WebP's duration is set by loading its frame
                        durations.append(image.info.get("duration"))
                return count, image.format, durations
    except Exception:  # not Pillow's to judge: OpenCV decodes it or says why not
        return 1, None, None


def _frames(source: Source):
    """The frames of an animation or multi-page file, one at a time: TIFF pages by OpenCV
    (depth kept), GIF, PNG and WebP frames by Pillow, composited on the canvas as 8-bit BGRA,
    or BGR where the frame is opaque (so that RMSE does not depend on the container: an
    opaque APNG read as BGRA averaged a fourth channel of zeros in)."""
    import cv2
    import numpy as np
    from PIL import Image, ImageSequence

    from ..app.pipeline import WarpError
    from ..io import tiff
    from ..io.decode import gray_alpha_to_bgra, lab_error

    if source.format == "TIFF":
        lab = tiff.lab_pages(source.data, source.frames)
        if lab:                                   # the first page's was refused as it was read
            raise WarpError(str(lab_error(source.path, f" (page {lab[0] + 1})")), source.name)
        ok, pages = cv2.imdecodemulti(np.frombuffer(source.data, np.uint8), cv2.IMREAD_UNCHANGED)
        if not ok or len(pages) != source.frames:
            raise WarpError(f"{source.path}: its {source.frames} pages cannot be decoded", source.name)
        alpha = tiff.extra_samples(source.data) in (tiff.ASSOCIATED, tiff.UNASSOCIATED)
        for index, page in enumerate(pages):      # libtiff's RGBA reading premultiplied 8-bit alpha
            straight = alpha and page.dtype == np.uint8 and page.ndim == 3 and page.shape[2] == 4
            yield gray_alpha_to_bgra(_pillow_page(source.data, index, page) if straight else page)
        return
    try:
        with Image.open(io.BytesIO(source.data)) as image:
            for frame in ImageSequence.Iterator(image):
                bgra = cv2.cvtColor(np.asarray(frame.convert("RGBA")), cv2.COLOR_RGBA2BGRA)
                yield np.ascontiguousarray(bgra[:, :, :3]) if bgra[:, :, 3].min() == 255 else bgra
    except (OSError, ValueError) as err:
        raise WarpError(f"{source.path}: a frame cannot be decoded: {err}", source.name) from None


def _pillow_page(data: bytes, index: int, premultiplied):
    """Page ``index`` of a TIFF as straight-alpha BGRA by Pillow, or ``premultiplied`` (OpenCV's
    reading of it) divided back where Pillow cannot read it."""
    from ..io import tiff

    straight = tiff.pillow_rgba(data, index, upright=False)
    return straight if straight is not None and straight.shape == premultiplied.shape else (
        tiff.unpremultiplied(premultiplied))


def _read_within_budget(path: str, name: str) -> Source:
    """Read A or B, and decode it after its header passed the pixel limit and the memory budget."""
    from ..app.pipeline import WarpError, read_input
    from ..io import ImageError, decode, limits

    if path != "-" and not os.path.isfile(path):
        read_input(path, name, limits.MAX_PIXELS)        # says what is wrong with the path
    try:
        data = decode.read_bytes(path)
    except ImageError as err:
        raise WarpError(str(err), name) from None
    header = decode.read_header(data)
    count, fmt, durations = _frame_info(data) if header is not None and header.animated else (1, None, None)
    if header is not None:
        need = header.width * header.height * (DIFF_PIXEL_BYTES + (PAGE_PIXEL_BYTES * count if fmt == "TIFF" else 0))
        if need > limits.MAX_MEMORY:
            raise WarpError(f"{path} is {header.width}x{header.height}"
                            f"{f' with {count} pages' if fmt == 'TIFF' and count > 1 else ''}: comparing it needs "
                            f"about {limits.size_text(need, limits.MAX_MEMORY)}, above the memory limit of "
                            f"{limits.size_text(limits.MAX_MEMORY)}")
    image = read_input(path, name, limits.MAX_PIXELS, data)
    return Source(path, name, data, image, count, fmt, durations)

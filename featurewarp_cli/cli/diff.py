"""``featurewarp diff A B``: compare two images within a tolerance (golden files in CI)."""

from __future__ import annotations

import os

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
                   "identical, max_abs, pixels_off, pixels, tolerance, within, failures) instead of text; images that "
                   "cannot be compared (sizes or channel counts) give null figures and the reason.")
def diff_command(a, b, max_rmse, min_psnr, max_pixels_off, tolerance, diff_image, quiet, as_json):
    """Compare images A and B (e.g. an output with its golden file).

    Prints RMSE, PSNR, the largest absolute difference and the pixels off, on
    the 0..255 scale (16-bit samples divided by 257), every channel and alpha
    included. Exit 0 within tolerance, 1 beyond it or when the sizes or channel
    counts differ. Without --max-rmse, --min-psnr or --max-pixels-off the images
    must match within --tolerance everywhere. One of A and B may be '-' (stdin).

    \b
    Example:
      featurewarp diff out.png golden.png --max-rmse 0.5 --diff-image diff.png
    """
    quiet = quiet or bool(click.get_current_context().meta.get("featurewarp.quiet"))
    from ..app import diff
    from ..app.pipeline import WarpError
    from ..io import ImageError, encode, formats, write

    if a == "-" and b == "-":
        raise click.UsageError("only one of A and B can be '-' (stdin)")
    if diff_image:
        for path, name in ((a, "A"), (b, "B")):
            if path != "-" and os.path.exists(diff_image) and os.path.exists(path) and os.path.samefile(diff_image, path):
                raise click.BadParameter(f"{diff_image} is also {name}; it would be overwritten",
                                         param_hint="'--diff-image'")
        try:
            if diff_image == "-":
                raise ValueError("cannot be '-' (stdout holds the metrics)")
            path, fmt = formats.output_target(diff_image)
            write.check_writable(path)
        except ValueError as err:
            raise click.BadParameter(str(err), param_hint="'--diff-image'") from None
    try:
        first, second = (_read_within_budget(path, name) for path, name in ((a, "A"), (b, "B")))
    except WarpError as err:
        raise click_error(err) from err
    reason = diff.mismatch(first, second)
    if reason:
        if as_json and not quiet:         # a CI job parses the failure as it parses any other
            click.echo(_as_json(a, b, None, [f"cannot be compared: {reason}"], tolerance))
        unwritten = f"; {diff_image} not written" if diff_image else ""
        raise click.ClickException(f"{a} and {b} cannot be compared: {reason}{unwritten}")
    result = diff.compare(first, second, tolerance)
    broken = diff.failures(result, max_rmse, min_psnr, max_pixels_off)
    if as_json and not quiet:
        click.echo(_as_json(a, b, result, broken))
    elif not quiet:
        click.echo("\n".join(result.lines()))
    if diff_image:
        try:
            write.write_atomic(path, encode.encode_image(diff.highlight(first, result.off), fmt))
        except (ImageError, OSError) as err:
            raise click.ClickException(f"cannot write {path}: {err}") from err
    if broken:
        raise click.ClickException(f"{a} and {b} differ beyond tolerance: {'; '.join(broken)}")


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
    return json.dumps({"a": a, "b": b, **figures, "within": not broken, "failures": broken})


#: Peak bytes per pixel of a diff (both images as read, their float differences, the
#: highlight image), measured: two 14142^2 16-bit RGBA images took 15.3 GB.
DIFF_PIXEL_BYTES = 80


def _read_within_budget(path: str, name: str):
    """Decode A or B after its header passed the pixel limit and the memory budget."""
    from ..app.pipeline import WarpError, read_input
    from ..io import ImageError, decode, limits

    if path != "-" and not os.path.isfile(path):
        return read_input(path, name, limits.MAX_PIXELS)        # says what is wrong with the path
    try:
        data = decode.read_bytes(path)
    except ImageError as err:
        raise WarpError(str(err), name) from None
    header = decode.read_header(data)
    if header is not None and header.width * header.height * DIFF_PIXEL_BYTES > limits.MAX_MEMORY:
        raise WarpError(f"{path} is {header.width}x{header.height}: comparing it needs about "
                        f"{limits.size_text(header.width * header.height * DIFF_PIXEL_BYTES, limits.MAX_MEMORY)}, "
                        f"above the memory limit of {limits.size_text(limits.MAX_MEMORY)}")
    return read_input(path, name, limits.MAX_PIXELS, data)

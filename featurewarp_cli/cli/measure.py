"""``featurewarp measure INPUT OUTPUT -m MASK``: each masked region's distortion, read off the output.

The figures come from :mod:`featurewarp_cli.app.measure` (keypoints matched inside each
connected component of the mask, an affine map fitted input -> output); the numeric
modules load only when the command runs.
"""

from __future__ import annotations

import os

import click

from ..plugins import Param
from .options import max_memory_option, max_pixels_option, option


def component_line(fit) -> str:
    """One line of text for a :class:`featurewarp_cli.app.measure.ComponentFit`."""
    x, y, w, h = fit.bbox
    where = (f"component {fit.label} ({fit.pixels} px around ({fit.centre[0]:.0f}, {fit.centre[1]:.0f}), "
             f"{w}x{h} at {x},{y})")
    if fit.distortion is None:
        return f"{where}: not measured: {fit.reason}"
    mirrored = ", mirrored" if fit.reflected else ""
    local = ("" if fit.local_p90 is None else
             f"; locally {fit.local_p90:.4f} (90th percentile), {100 * fit.explained:.0f} % explained")
    return (f"{where}: distortion {fit.distortion:.4f} (noise {fit.noise:.4f}), scale {fit.scale:.4f}, rotation "
            f"{round(fit.rotation, 2) + 0.0:.2f} deg{mirrored}; {fit.inliers} of {fit.matches} matches, rms "
            f"{fit.rms_px:.2f} px, covering {100 * fit.coverage:.0f} %{local}")


@click.command("measure", params=[max_pixels_option(), max_memory_option(
    "an image that would need more memory than SIZE (bytes, or with K, M, G, T) once decoded")])
@click.argument("input", type=click.Path(dir_okay=False, allow_dash=True))
@click.argument("output", type=click.Path(dir_okay=False, allow_dash=True))
@click.option("-m", "--mask", required=True, type=click.Path(dir_okay=False, allow_dash=True),
              metavar="PATH|alpha", help="The feature mask INPUT was warped with (as for warp: alpha is "
                                         "INPUT's own alpha).")
@click.option("--json", "as_json", is_flag=True,
              help="Print machine-readable JSON: input, output, mask, worst_distortion and per component "
                   "its figures (label, pixels, bbox, centre, distortion, noise, scale, rotation, rms_px, "
                   "local_p90, explained, ...; null where not measured, with the reason).")
@option(Param("max_distortion", float, None,
             "A check for CI: exit 1 when a region's distortion is above D (0.02: the report's 'kept'), or a "
             "region could not be measured or landed on another's place (each named on stderr); the figures "
             "are printed all the same.", min=0.0, metavar="D"))
def measure_command(input, output, mask, as_json, max_distortion, max_pixels, max_memory):
    """Measure how each masked region of INPUT came out in OUTPUT.

    SIFT keypoints inside each connected component of the mask are matched with
    the output's (RANSAC keeps the true matches), and the affine map input ->
    output that fits all locally consistent matches best (least squares) is the
    component's: the image's counterpart of the report's distortion. Printed per
    component, after its size and place ('around (x, y)', as the report's 'at'):
    distortion = sigma_max/sigma_min - 1 of its linear part (0: the shape is kept,
    1: stretched 2x along one axis) and its noise (the distortion the scatter of
    the matches alone gives), scale, rotation (degrees, clockwise on
    screen), the matches the map was fitted to out of all matches, rms (their
    root mean square distance from the map, in output pixels: large for a bent
    region) and the share of the component they span; where enough matches are
    locally consistent, also the 90th percentile of the distortion of local fits
    (around each match) and the share of those matches the component's map
    explains (below 100 %: the region was bent, not moved as one map). A
    component with too few matches, or whose matches fix its shape too loosely
    (noise above 0.005, with a distortion within 3 times it or too few matches
    confirmed by their neighbourhoods), is reported as not measured, with the reason. Two regions whose maps put them on one
    spot of OUTPUT (one matched the other's likeness: the same subject twice) are named on
    stderr. One of INPUT, OUTPUT and MASK may be '-' (stdin).

    \b
    Example:
      featurewarp measure photo.png out.png -m mask.png --json
    """
    from ..app import measure
    from ..app.pipeline import Settings, WarpError, _check_paths, frames_warning, load_image_and_mask, read_input
    from ..io import ImageError, decode
    from .presets import click_error

    if [input, output, mask].count("-") > 1:
        raise click.UsageError("only one of INPUT, OUTPUT and --mask can be '-' (stdin)")
    settings = Settings("measure", max_pixels=max_pixels, max_memory=max_memory)
    try:                                   # INPUT and its mask as warp reads them (-m alpha too)
        _check_paths(input, None)              # INPUT named first, as warp does
        data = decode.read_bytes(output, max_memory) if output == "-" or os.path.isfile(output) else None
        warnings = [f"OUTPUT {output} has several frames (animated or multi-page); the first is measured"] * bool(
            data is not None and frames_warning(decode.read_header(data)))
        result = read_input(output, "OUTPUT", max_pixels, data, max_memory)
        image, feature_mask, loaded = load_image_and_mask(settings, input, mask)
        warnings = loaded + warnings
    except ImageError as err:
        raise click_error(WarpError(str(err), "OUTPUT")) from err
    except WarpError as err:
        raise click_error(err) from err
    _warn([line.replace("the input has several frames", f"INPUT {input} has several frames")
           .replace("; the first is used", "; the first is measured")
           .replace(": plain warp", ": nothing to measure") for line in warnings])
    try:
        fits = measure.measure(image, result, feature_mask)
    except ValueError as err:
        raise click.BadParameter(str(err), param_hint="'--mask'") from None
    if as_json:
        import json

        click.echo(json.dumps({"input": input, "output": output, "mask": mask,
                               "worst_distortion": measure.worst(fits),
                               "components": [f.as_dict() for f in fits]}, indent=2))
    else:
        if not fits:
            click.echo("the mask is empty: nothing to measure")
        for fit in fits:
            click.echo(component_line(fit))
    _warn_and_gate(fits, max_distortion)


def _warn(lines) -> None:
    """Each line as a warning on stderr, unless -q."""
    from .. import stages
    from .progress import say

    for line in [] if stages.quiet else lines:
        say(f"featurewarp: warning: {line}")


def _warn_and_gate(fits, max_distortion: float | None) -> None:
    """A warning per region that landed on another's place; with ``max_distortion``, exit 1
    where a region is more distorted, could not be measured, or landed on another's place
    (a check cannot pass what it could not see), or where the mask marks nothing."""
    _warn([f"component {fit.label} lands where component{'s' * (len(fit.lands_on) > 1)} "
           f"{', '.join(str(label) for label in fit.lands_on)} went: one of them was matched to the other's "
           f"likeness (the same subject twice?); their figures are doubtful" for fit in fits if fit.lands_on])
    if max_distortion is None:
        return
    failed = ["the mask marks no region"] if not fits else []
    for fit in fits:
        where = f"component {fit.label} (around ({fit.centre[0]:.0f}, {fit.centre[1]:.0f}))"
        if fit.distortion is None:
            failed.append(f"{where} could not be measured ({fit.reason})")
        elif fit.lands_on:
            failed.append(f"{where} landed where another region went: its figures are doubtful")
        elif fit.distortion > max_distortion:
            failed.append(f"{where} has distortion {fit.distortion:.4f}, above {max_distortion:g}")
    for line in failed:
        click.echo(f"featurewarp: error: --max-distortion: {line}", err=True)
    if failed:
        raise SystemExit(1)

"""The ``featurewarp`` command line: parses, checks and prints; the numerics live elsewhere.

Numeric modules are imported inside the commands so that ``--help`` stays fast.
"""

from __future__ import annotations

import json
import math
import os
import sys
import time

import click

from . import __version__, plugins

MODES = ("similarity", "rigid", "plain")
INTERPOLATIONS = ("linear", "cubic", "lanczos")


class PresetValue(click.ParamType):
    """A click type that validates a preset parameter through its declaration."""

    def __init__(self, param):
        self.param = param
        self.name = param.type.__name__

    def convert(self, value, option, ctx):
        try:
            return self.param.check(value)
        except ValueError as err:
            self.fail(str(err).split(": ", 1)[-1], option, ctx)


class Number(click.ParamType):
    """A finite number with an optional lower bound (rejects nan and inf)."""

    def __init__(self, kind=float, minimum=None, open_min=False):
        self.kind, self.minimum, self.open_min = kind, minimum, open_min
        self.name = kind.__name__

    def convert(self, value, option, ctx):
        try:
            number = float(value)
        except (TypeError, ValueError):
            self.fail(f"{value!r} is not a number", option, ctx)
        if not math.isfinite(number):
            self.fail(f"{value!r} is not a finite number", option, ctx)
        if self.kind is int:
            if number != int(number):
                self.fail(f"{value!r} is not a whole number", option, ctx)
            number = int(number)
        if self.minimum is not None and (number < self.minimum or (self.open_min and number == self.minimum)):
            self.fail(f"{value!r} must be {'>' if self.open_min else '>='} {self.minimum}", option, ctx)
        return number


def shared_options() -> list[click.Option]:
    """Options every preset command takes (built fresh for each command)."""
    return [
        click.Option(["-m", "--mask"], type=click.Path(dir_okay=False), metavar="PATH",
                     help="Feature mask: pixels with gray value >= 128 keep their shape. "
                          "Same width and height as INPUT. Without it the plain warp is produced."),
        click.Option(["--mode"], type=click.Choice(MODES), default="similarity", show_default=True,
                     help="similarity: features rotate and scale uniformly with the warp; "
                          "rigid: features also keep their size; plain: the standard warp, mask ignored."),
        click.Option(["--cell"], type=Number(int, 2), metavar="PX",
                     help="Grid cell size in pixels (>= 2). Default: 4 px, or larger on big images "
                          "so that the grid keeps about 250 000 nodes (ceil(sqrt(w*h/250000))).  "),
        click.Option(["--feature-weight"], type=Number(float, 0, open_min=True), default=10.0,
                     show_default=True, metavar="W",
                     help="w_F: each side of the feature equations is multiplied by W, so their "
                          "squared error counts W^2 times."),
        click.Option(["--decay"], type=Number(float, 0, open_min=True), default=2.0, show_default=True,
                     metavar="CELLS", help="Width of the band around features where the weight "
                                           "falls smoothly from W to 1 (the paper's rho), in cells."),
        click.Option(["--formulation"], type=click.Choice(("exact", "paper")), default="exact",
                     show_default=True,
                     help="exact: each feature moves as one similarity, held exactly; paper: the "
                          "paper's soft per-quad targets (w_F-weighted), for comparison."),
        click.Option(["--background"], metavar="COLOR",
                     help="Fill where no source pixel lands: #rrggbb, a colour name, or transparent. "
                          "Default: transparent for PNG, WebP and TIFF output, white otherwise."),
        click.Option(["--interp"], type=click.Choice(INTERPOLATIONS), default="cubic", show_default=True,
                     help="Resampling filter."),
        click.Option(["--report"], type=click.Path(dir_okay=False), metavar="PATH",
                     help="Write a JSON report: sizes, grid, feature components and their scale, "
                          "solver, seconds per stage, flipped triangles."),
    ]


def fail_usage(message: str, param: str | None = None):
    """Raise a usage error (exit 2) that names the offending parameter."""
    if param:
        raise click.BadParameter(message, param_hint=param)
    raise click.UsageError(message)


class PresetGroup(click.Group):
    """``featurewarp warp``: one subcommand per registered preset, built from its declaration."""

    def list_commands(self, ctx):
        return list(plugins.names())

    def get_command(self, ctx, name):
        if name not in plugins.names():
            return None
        try:
            preset = plugins.load(name)
        except plugins.UnknownPreset as err:
            message = str(err)

            @click.command(name, help=f"(broken plugin) {message}")
            def broken():
                raise click.ClickException(message)

            return broken
        return preset_command(preset)

    def resolve_command(self, ctx, args):
        try:
            return super().resolve_command(ctx, args)
        except click.UsageError:
            if args and args[0] not in plugins.names():
                raise click.UsageError(
                    f"unknown preset {args[0]!r}; available: {', '.join(plugins.names())} "
                    "(see 'featurewarp warps')", ctx) from None
            raise


def preset_command(preset) -> click.Command:
    """Build the click command for one preset class."""
    options = [click.Argument(["input"], type=click.Path(dir_okay=False)),
               click.Argument(["output"], type=click.Path(dir_okay=False))]
    options += shared_options()
    for p in preset.params:
        default_text = "unset" if p.default is None else f"{p.default:g}"
        options.append(click.Option(
            [f"--{p.cli_name}"], type=PresetValue(p), default=p.default, metavar=p.metavar,
            help=f"{p.help} [default: {default_text}; {p.range_text()}]"))
    doc = (preset.__doc__ or preset.summary).strip()

    def callback(input, output, **kwargs):
        shared = {k: kwargs.pop(k) for k in
                  ("mask", "mode", "cell", "feature_weight", "decay", "formulation", "background",
                   "interp", "report")}
        run_warp(preset, input, output, preset_params=kwargs, **shared)

    return click.Command(preset.name, params=options, callback=callback, help=doc,
                         short_help=preset.summary, no_args_is_help=True)


def check_output_path(path: str, param: str, image: bool = True) -> None:
    """Fail with a usage error unless ``path`` can be written (with a known image format)."""
    from .imageio import output_format

    if image:
        try:
            output_format(path)
        except ValueError as err:
            fail_usage(str(err), param)
    directory = os.path.dirname(os.path.abspath(path))
    if not os.path.isdir(directory):
        fail_usage(f"directory {directory} does not exist", param)
    if not os.access(directory, os.W_OK):
        fail_usage(f"directory {directory} is not writable", param)
    if os.path.isdir(path):
        fail_usage(f"{path} is a directory", param)


def run_warp(preset, input, output, *, mask, mode, cell, feature_weight, decay, formulation,
             background, interp, report, preset_params):
    """Load, warp, render and write one image (the body of ``featurewarp warp PRESET``)."""
    from . import imageio
    from .api import FeatureWarper

    timings = {}
    t0 = time.perf_counter()
    if not os.path.isfile(input):
        fail_usage(f"{input} does not exist" if not os.path.exists(input) else f"{input} is not a file", "INPUT")
    check_output_path(output, "OUTPUT")
    if report:
        check_output_path(report, "--report", image=False)
    _, has_alpha, _ = imageio.output_format(output)
    if background is None:
        background_rgb = None if has_alpha else (255, 255, 255)
    else:
        try:
            background_rgb = imageio.parse_colour(background)
        except ValueError as err:
            fail_usage(str(err), "--background")
        if background_rgb is None and not has_alpha:
            fail_usage(f"{os.path.splitext(output)[1]} has no alpha channel; "
                       "use a colour or a PNG, WebP or TIFF output", "--background")

    try:
        image = imageio.read_image(input)
    except imageio.ImageError as err:
        raise click.ClickException(str(err)) from None
    height, width = image.shape[:2]
    feature_mask = None
    if mask is not None and mode != "plain":
        if not os.path.isfile(mask):
            fail_usage(f"{mask} does not exist", "--mask")
        try:
            feature_mask = imageio.mask_from_image(imageio.read_image(mask))
        except imageio.ImageError as err:
            raise click.ClickException(f"mask: {err}") from None
        if feature_mask.shape != (height, width):
            fail_usage(f"mask is {feature_mask.shape[1]}x{feature_mask.shape[0]} but "
                       f"{input} is {width}x{height}", "--mask")
    timings["load"] = time.perf_counter() - t0

    try:
        warp = preset(width, height, **preset_params)
    except ValueError as err:
        fail_usage(str(err))
    warper = FeatureWarper(width, height, feature_mask, cell=cell, feature_weight=feature_weight,
                           decay=decay, formulation=formulation)
    mesh = warper.solve(warp, mode)
    result = warper.render(image, mesh, interp, background_rgb)
    timings.update(mesh.info["timings"])

    t1 = time.perf_counter()
    try:
        data = imageio.encode_image(result, output)
        imageio.write_atomic(output, data)
    except (imageio.ImageError, OSError) as err:
        raise click.ClickException(f"cannot write {output}: {err}") from None
    timings["write"] = time.perf_counter() - t1

    if report:
        from .report import build_report

        doc = build_report(input, output, image, result, warp, mesh, timings)
        try:
            imageio.write_atomic(report, (json.dumps(doc, indent=2) + "\n").encode())
        except OSError as err:
            raise click.ClickException(f"cannot write report {report}: {err}") from None


@click.group(context_settings={"help_option_names": ["-h", "--help"], "max_content_width": 100})
@click.version_option(__version__, "-V", "--version", prog_name="featurewarp")
@click.option("--debug", is_flag=True, help="Show a traceback on unexpected errors.")
@click.pass_context
def cli(ctx, debug):
    """Warp images while the features marked in a mask keep their shape.

    Features (faces, people, logos, products) only rotate and scale uniformly;
    the background absorbs the rest of the warp.

    \b
    Examples:
      featurewarp warp stretch banner.jpg wide.jpg --mask banner_mask.png --sx 2
      featurewarp warp swirl in.png out.png -m mask.png --angle 120 --report r.json
      featurewarp warps            # presets, their options, defaults and ranges
    """
    ctx.obj = {"debug": debug}


@cli.group(cls=PresetGroup, context_settings={"help_option_names": ["-h", "--help"]},
           subcommand_metavar="PRESET INPUT OUTPUT [OPTIONS]")
def warp():
    """Warp INPUT with PRESET into OUTPUT, keeping masked features in shape.

    The output format follows OUTPUT's extension (png, jpg, webp, tif, bmp).
    Run 'featurewarp warp PRESET --help' for a preset's own options.
    """


@cli.command("warps")
@click.option("--json", "as_json", is_flag=True, help="Print machine-readable JSON.")
def list_warps(as_json):
    """List every registered preset with its options, defaults and ranges."""
    entries = []
    for name in plugins.names():
        try:
            preset = plugins.load(name)
        except plugins.UnknownPreset as err:
            entries.append({"name": name, "broken": str(err), "params": []})
            continue
        entries.append({"name": name, "summary": preset.summary, "params": [p.as_dict() for p in preset.params]})
    if as_json:
        click.echo(json.dumps(entries, indent=2))
        return
    for entry in entries:
        if "broken" in entry:
            click.echo(f"{entry['name']}  (broken: {entry['broken']})\n")
            continue
        click.echo(f"{entry['name']}  {entry['summary']}")
        preset = plugins.load(entry["name"])
        for p in preset.params:
            default = "unset" if p.default is None else f"{p.default:g}"
            click.echo(f"  --{p.cli_name:<10} {p.type.__name__:<6} default {default:<6} {p.range_text():<18} {p.help}")
        click.echo()


def main(argv=None):
    """Console-script entry point.

    Every error is one line on stderr: exit 2 for usage errors, 1 for processing
    failures (and for anything unexpected; ``--debug`` shows its traceback).
    """
    argv = sys.argv[1:] if argv is None else list(argv)
    try:
        code = cli.main(args=argv, prog_name="featurewarp", standalone_mode=False)
    except click.exceptions.NoArgsIsHelpError as err:
        err.show()
        code = err.exit_code
    except click.ClickException as err:
        click.echo(f"featurewarp: error: {err.format_message()}", err=True)
        code = err.exit_code
    except click.exceptions.Abort:
        click.echo("featurewarp: aborted", err=True)
        code = 1
    except Exception as err:  # anything the commands did not anticipate
        if "--debug" in argv:
            raise
        click.echo(f"featurewarp: error: {type(err).__name__}: {err} (--debug shows a traceback)", err=True)
        code = 1
    sys.exit(code if isinstance(code, int) else 0)


if __name__ == "__main__":
    main()

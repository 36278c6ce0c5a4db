"""The ``featurewarp`` command line: parses, checks and prints; the work lives elsewhere.

``warp`` and ``batch`` run :func:`featurewarp_cli.app.pipeline.warp_file`; ``diff`` uses
:mod:`featurewarp_cli.diff`. Numeric modules are imported inside the commands so
that ``--help`` stays fast. Only image bytes ever go to stdout when OUTPUT is ``-``;
every message goes to stderr.
"""

from __future__ import annotations

import inspect
import math
import os
import sys
import warnings

import click

from .. import __version__, plugins
from ..io import limits
from ..io.formats import NAMES as FORMAT_NAMES
from ..io.limits import MAX_PIXELS

MODES = ("similarity", "rigid", "plain")
INTERPOLATIONS = ("linear", "cubic", "lanczos")
#: Keyword arguments of the commands that are engine or output settings, not preset parameters.
SETTINGS = ("mode", "cell", "feature_weight", "decay", "formulation", "boundary", "scale_prior", "strict",
            "background",
            "interp", "fmt", "max_pixels")


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


def limit_decoders(ctx, param, value):
    """``--max-pixels`` callback: OpenCV reads its decoders' limit once, when it loads (the
    commands load it later), and applies it to the formats whose header Pillow cannot read."""
    limits.limit_opencv_decoders(value)
    return value


def engine_options() -> list[click.Option]:
    """Options ``warp`` and ``batch`` share (built fresh for each command)."""
    return [
        click.Option(["--mode"], type=click.Choice(MODES), default="similarity", show_default=True,
                     help="similarity: features rotate and scale uniformly with the warp; "
                          "rigid: features also keep their size; plain: the standard warp, mask ignored."),
        click.Option(["--cell"], type=Number(float, 1), metavar="PX",
                     help="Grid cell size in pixels (>= 1). Default: automatic: 4 px, or "
                          "sqrt(w*h/250000) on big images; then divided by sqrt(2) until the "
                          "grid is within 0.5 px of the analytic warp and the warp folds none of "
                          "its triangles (sub-pixel allowed, at most 4 million nodes)."),
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
        click.Option(["--boundary"], type=click.Choice(("fixed", "slide")),
                     help="fixed: border nodes stay where the warp puts them (the paper). slide: "
                          "on a side the warp maps onto an axis-parallel straight line they may "
                          "slide along it, so features cut by the border keep their shape and the "
                          "canvas stays exact. Default: slide (for stretch; it amounts to fixed for "
                          "swirl and bulge, whose border stays put, and for arc, whose sides are "
                          "curves and oblique rays)."),
        click.Option(["--scale-prior"], type=Number(float, 0), default=1.0, show_default=True,
                     metavar="P",
                     help="Similarity mode: how firmly each feature's scale and rotation are pulled "
                          "towards the warp's own (its best-fit rotation and the scale the mode "
                          "picks). 1 holds them as firmly as the feature's own shape equations; "
                          "smaller values let features that fill a row or column grow or shrink "
                          "uniformly so the background is not streaked; 0 leaves them free."),
        click.Option(["--strict"], is_flag=True,
                     help="Exit 1 and write nothing when a feature could not be kept, features "
                          "were relaxed to avoid fold-overs, or the output would equal the input "
                          "(each is otherwise a warning)."),
        click.Option(["--background"], metavar="COLOR",
                     help="Fill where no source pixel lands: #rrggbb, a colour name, or transparent. "
                          "Default: transparent for PNG, WebP and TIFF output, white otherwise "
                          "(formats without alpha also get transparent input pixels flattened on it)."),
        click.Option(["--interp"], type=click.Choice(INTERPOLATIONS), default="cubic", show_default=True,
                     help="Resampling filter."),
        click.Option(["--format", "fmt"], type=click.Choice(FORMAT_NAMES, case_sensitive=False),
                     help="Output format; overrides the extension (needed for '-' unless a "
                          "prefix such as png:- is given)."),
        click.Option(["--max-pixels"], type=Number(int, 1), default=MAX_PIXELS, show_default=True,
                     callback=limit_decoders,
                     metavar="N", help="Refuse inputs with more than N pixels (checked in the file "
                                       "header, before decoding)."),
        click.Option(["-q", "--quiet"], is_flag=True, help="Print nothing but errors."),
        click.Option(["-v", "--verbose"], is_flag=True,
                     help="Print a one-line summary per image on stderr (sizes, solver, seconds)."),
    ]


def preset_options(preset) -> list[click.Option]:
    """One option per declared parameter of ``preset``."""
    options = []
    for p in preset.params:
        default_text = "unset" if p.default is None else f"{p.default:g}"
        options.append(click.Option(
            [f"--{p.cli_name}"], type=PresetValue(p), default=p.default, metavar=p.metavar,
            help=f"{p.help} [default: {default_text}; {p.range_text()}]"))
    return options


def settings_from(preset, kwargs: dict):
    """Split a preset command's keyword arguments into Settings, quiet and verbose."""
    from ..app.pipeline import Settings

    quiet, verbose = kwargs.pop("quiet"), kwargs.pop("verbose")
    if quiet and verbose:
        raise click.UsageError("--quiet and --verbose exclude each other")
    params = {p.name: kwargs.pop(p.name) for p in preset.params}
    return Settings(preset.name, params, **{k: kwargs.pop(k) for k in SETTINGS}), quiet, verbose


def click_error(err) -> click.ClickException:
    """The click exception for a :class:`featurewarp_cli.app.pipeline.WarpError` (usage: exit 2, else 1)."""
    if err.usage:
        if err.param:
            return click.BadParameter(err.message, param_hint=f"'{err.param}'")
        return click.UsageError(err.message)
    return click.ClickException(str(err))


def summary_line(s: dict) -> str:
    """The ``--verbose`` line of one warped image."""
    (w, h), (cw, ch) = s["size"], s["canvas"]
    return (f"{s['input']} {w}x{h} -> {s['output']} {cw}x{ch}: {s['preset']} ({s['mode']}), "
            f"{s['components']} feature components, solver {s['solver']}, "
            f"{s['flipped_triangles']} flipped triangles, {s['seconds']:.2f} s")


def report_warnings(summary: dict, quiet: bool, verbose: bool) -> None:
    """Print an image's warnings (unless quiet) and its summary line (if verbose) on stderr."""
    if not quiet:
        for warning in summary["warnings"]:
            click.echo(f"featurewarp: warning: {summary['input']}: {warning}", err=True)
    if verbose:
        click.echo(f"featurewarp: {summary_line(summary)}", err=True)


def warp_command(preset) -> click.Command:
    """``featurewarp warp PRESET INPUT OUTPUT``."""
    params = [click.Argument(["input"], type=click.Path(dir_okay=False, allow_dash=True)),
              click.Argument(["output"], type=click.Path(dir_okay=False, allow_dash=True)),
              click.Option(["-m", "--mask"], type=click.Path(dir_okay=False, allow_dash=True), metavar="PATH",
                           help="Feature mask: pixels with gray value >= 128 (transparent ones count "
                                "as black) keep their shape. Same width and height as INPUT. "
                                "Without it the plain warp is produced."),
              click.Option(["--report"], type=click.Path(dir_okay=False), metavar="PATH",
                           help="Write a JSON report: sizes, grid, feature components (scale, "
                                "rotation, residual from a similarity), background deviation from "
                                "the warp, triangle area ratios, fold-overs before and after the "
                                "guard, solver, seconds per stage."),
              click.Option(["--save-grid"], type=click.Path(dir_okay=False), metavar="PATH.npz",
                           help="Save the mapping: arrays source (N x 2 source pixel positions of "
                                "the grid nodes), target (N x 2 on the output canvas), triangles "
                                "(M x 3 node indices, counter-clockwise in source coordinates)."),
              click.Option(["--grid", "draw_grid"], is_flag=True,
                           help="Draw the deformed grid over the result.")]
    params += engine_options() + preset_options(preset)

    def callback(input, output, mask, report, save_grid, draw_grid, **kwargs):
        from ..app.pipeline import WarpError, warp_file

        settings, quiet, verbose = settings_from(preset, kwargs)
        try:
            summary = warp_file(settings, input, output, mask, report, save_grid, draw_grid)
        except WarpError as err:
            raise click_error(err) from err
        report_warnings(summary, quiet, verbose)

    doc = (preset.__doc__ or preset.summary).strip()
    return click.Command(preset.name, params=params, callback=callback, help=doc,
                         short_help=preset.summary, no_args_is_help=True)


def batch_command(preset) -> click.Command:
    """``featurewarp batch PRESET INPUT... --out-dir DIR``."""
    params = [click.Argument(["inputs"], nargs=-1, required=True, metavar="INPUT...",
                             type=click.Path(dir_okay=False)),
              click.Option(["-o", "--out-dir"], required=True, metavar="DIR",
                           type=click.Path(file_okay=False), help="Folder for the outputs (must exist)."),
              click.Option(["--mask-pattern"], default="{stem}_mask.png", show_default=True,
                           metavar="PATTERN",
                           help="Mask file of each input; {stem} is the input's name without "
                                "extension; relative to the input's folder unless absolute. "
                                "A missing mask fails that file. Inputs that are another "
                                "input's mask are skipped, so 'photos/*.png' works."),
              click.Option(["--suffix"], default="", metavar="S",
                           help="Appended to each output's stem: DIR/{stem}S.{ext}."),
              click.Option(["-j", "--jobs"], type=Number(int, 1), default=1, show_default=True,
                           metavar="N", help="Worker processes; results are byte-identical to N=1.")]
    params += engine_options() + preset_options(preset)

    def callback(inputs, out_dir, mask_pattern, suffix, jobs, **kwargs):
        from ..app.pipeline import WarpError, plan, run_batch
        from ..io.formats import format_name

        settings, quiet, verbose = settings_from(preset, kwargs)
        try:
            fmt = format_name(settings.fmt) if settings.fmt else None
            todo = plan(inputs, out_dir, suffix, fmt, None if settings.mode == "plain" else mask_pattern)
        except WarpError as err:
            raise click_error(err) from err
        failed = 0
        with click.progressbar(length=len(todo), label="warping", file=sys.stderr,
                               hidden=quiet or not sys.stderr.isatty()) as bar:
            for job, error, summary in run_batch(settings, todo, jobs):
                bar.update(1)
                if error:
                    failed += 1
                    click.echo(f"featurewarp: error: {job.input}: {error}", err=True)
                else:
                    report_warnings(summary, quiet, verbose)
        if failed:
            raise click.ClickException(f"{failed} of {len(todo)} files failed")

    doc = (f"Warp every INPUT with {preset.name} into --out-dir, each with its own mask.\n\n"
           + inspect.cleandoc(preset.__doc__ or preset.summary))
    return click.Command(preset.name, params=params, callback=callback, help=doc,
                         short_help=preset.summary, no_args_is_help=True)


class PresetGroup(click.Group):
    """A group with one subcommand per registered preset, built from its declaration."""

    make_command = staticmethod(warp_command)

    def list_commands(self, ctx):
        return list(plugins.names())

    def get_command(self, ctx, name):
        if not plugins.known(name):
            return None
        try:
            preset = plugins.load(name)
        except plugins.UnknownPreset as err:
            message = str(err)

            @click.command(name, help=f"(broken plugin) {message}")
            def broken():
                raise click.ClickException(message)

            return broken
        return self.make_command(preset)

    def resolve_command(self, ctx, args):
        try:
            return super().resolve_command(ctx, args)
        except click.UsageError:
            if args and args[0] not in plugins.names():
                raise click.UsageError(
                    f"unknown preset {args[0]!r}; available: {', '.join(plugins.names())} "
                    "(see 'featurewarp warps')", ctx) from None
            raise


def compare_command(preset) -> click.Command:
    """``featurewarp compare PRESET INPUT OUTPUT``: the labelled four-way panel."""
    params = [click.Argument(["input"], type=click.Path(dir_okay=False, allow_dash=True)),
              click.Argument(["output"], type=click.Path(dir_okay=False, allow_dash=True)),
              click.Option(["-m", "--mask"], type=click.Path(dir_okay=False, allow_dash=True),
                           metavar="PATH", help="Feature mask (as for warp)."),
              click.Option(["--grid", "draw_grid"], is_flag=True,
                           help="Draw the deformed grid over the three results.")]
    params += [o for o in engine_options() if o.name != "mode"] + preset_options(preset)

    def callback(input, output, mask, draw_grid, **kwargs):
        from ..app.pipeline import WarpError, compare_file

        kwargs["mode"] = "similarity"
        settings, quiet, verbose = settings_from(preset, kwargs)
        try:
            summary = compare_file(settings, input, output, mask, draw_grid)
        except WarpError as err:
            raise click_error(err) from err
        report_warnings(summary, quiet, verbose)

    doc = (f"Write one labelled panel: input with the mask tinted | plain | rigid | similarity "
           f"({preset.name}).\n\n" + inspect.cleandoc(preset.__doc__ or preset.summary))
    return click.Command(preset.name, params=params, callback=callback, help=doc,
                         short_help=preset.summary, no_args_is_help=True)


def animate_command(preset) -> click.Command:
    """``featurewarp animate PRESET INPUT OUTPUT --vary NAME=START:END``."""
    params = [click.Argument(["input"], type=click.Path(dir_okay=False, allow_dash=True)),
              click.Argument(["output"], type=click.Path(dir_okay=False)),
              click.Option(["-m", "--mask"], type=click.Path(dir_okay=False, allow_dash=True),
                           metavar="PATH", help="Feature mask (as for warp)."),
              click.Option(["--vary"], multiple=True, required=True, metavar="NAME=START:END",
                           help="A numeric option of the preset to vary linearly over the frames, "
                                "e.g. angle=0:360 (repeat for several)."),
              click.Option(["--frames"], type=Number(int, 1), default=24, show_default=True, metavar="N",
                           help="Number of frames (START and END included)."),
              click.Option(["--fps"], type=Number(float, 0, open_min=True), default=12.0,
                           show_default=True, metavar="F", help="Frames per second.")]
    params += [o for o in engine_options() if o.name != "fmt"] + preset_options(preset)

    def callback(input, output, mask, vary, frames, fps, **kwargs):
        from ..app.animate import animate_file, parse_vary
        from ..app.pipeline import WarpError

        kwargs["fmt"] = None
        settings, quiet, verbose = settings_from(preset, kwargs)
        try:
            ranges = parse_vary(vary, preset)
            with click.progressbar(length=frames, label="frames", file=sys.stderr,
                                   hidden=quiet or not sys.stderr.isatty()) as bar:
                summary = animate_file(settings, input, output, mask, ranges, frames, fps, bar.update)
        except WarpError as err:
            raise click_error(err) from err
        if not quiet:
            for warning in summary["warnings"]:
                click.echo(f"featurewarp: warning: {input}: {warning}", err=True)
        if verbose:
            click.echo(f"featurewarp: {output}: {summary['frames']} frames "
                       f"{summary['canvas'][0]}x{summary['canvas'][1]}, {summary['factorizations']} "
                       f"factorization(s), {summary['seconds']:.2f} s", err=True)

    doc = (f"Animate {preset.name}: vary its options over frames, factoring once. OUTPUT: .gif, "
           f".webp or .png (animated), .mp4 or .avi (video), or a numbered PNG sequence "
           f"such as out-%04d.png.\n\n" + inspect.cleandoc(preset.__doc__ or preset.summary))
    return click.Command(preset.name, params=params, callback=callback, help=doc,
                         short_help=preset.summary, no_args_is_help=True)


class AnimateGroup(PresetGroup):
    """``featurewarp animate``: the same presets, each as an animation command."""

    make_command = staticmethod(animate_command)


class CompareGroup(PresetGroup):
    """``featurewarp compare``: the same presets, each as a comparison panel."""

    make_command = staticmethod(compare_command)


class BatchGroup(PresetGroup):
    """``featurewarp batch``: the same presets, each as a batch command."""

    make_command = staticmethod(batch_command)


EPILOG = """\b
Shell completion (bash; use zsh_source or fish_source for zsh or fish):
  eval "$(_FEATUREWARP_COMPLETE=bash_source featurewarp)"
"""


@click.group(context_settings={"help_option_names": ["-h", "--help"], "max_content_width": 100},
             epilog=EPILOG)
@click.version_option(__version__, "-V", "--version", prog_name="featurewarp")
@click.option("--debug", is_flag=True, help="Show a traceback with processing errors.")
def cli(debug):
    """Warp images while the features marked in a mask keep their shape.

    Features (faces, people, logos, products) only rotate and scale uniformly;
    the background absorbs the rest of the warp. Exit status: 0 success,
    1 processing failure (or images that differ, for diff), 2 usage error.

    \b
    Examples:
      featurewarp warp stretch banner.jpg wide.jpg --mask banner_mask.png --sx 2
      featurewarp warp swirl in.png out.png -m mask.png --angle 120 --report r.json
      cat in.jpg | featurewarp warp bulge - png:- -m mask.png > out.png
      featurewarp batch swirl photos/*.jpg --out-dir out --jobs 8 --angle 90
      featurewarp compare arc photo.jpg panel.png -m mask.png --angle 120 --grid
      featurewarp animate swirl photo.jpg swirl.gif -m mask.png --vary angle=0:360 --frames 36
      featurewarp diff out.png golden.png --max-rmse 0.5
      featurewarp warps            # presets, their options, defaults and ranges
    """


@cli.group(cls=PresetGroup, context_settings={"help_option_names": ["-h", "--help"]},
           subcommand_metavar="PRESET INPUT OUTPUT [OPTIONS]")
def warp():
    """Warp INPUT with PRESET into OUTPUT, keeping masked features in shape.

    The output format follows OUTPUT's extension (png, jpg, webp, tif, bmp), an
    ImageMagick-style prefix (png:out.bin) or --format. '-' as INPUT reads stdin,
    '-' as OUTPUT writes stdout. Run 'featurewarp warp PRESET --help' for a preset's
    own options.
    """


@cli.group(cls=BatchGroup, context_settings={"help_option_names": ["-h", "--help"]},
           subcommand_metavar="PRESET INPUT... --out-dir DIR [OPTIONS]")
def batch():
    """Warp many images with PRESET, each with its mask, into one folder.

    One line on stderr per failed file; the others are still written; exit 1
    if any failed. A progress bar is shown when stderr is a terminal.
    """


@cli.group(cls=CompareGroup, context_settings={"help_option_names": ["-h", "--help"]},
           subcommand_metavar="PRESET INPUT OUTPUT [OPTIONS]")
def compare():
    """Show what featurewarp does: input with the mask tinted | plain | rigid | similarity.

    One factorization serves the three warps. Run 'featurewarp compare PRESET --help'
    for the options.
    """


@cli.group(cls=AnimateGroup, context_settings={"help_option_names": ["-h", "--help"]},
           subcommand_metavar="PRESET INPUT OUTPUT --vary NAME=START:END [OPTIONS]")
def animate():
    """Animate a preset: vary its options over frames, factoring once.

    Writes an animated GIF, WebP or PNG, an MP4/AVI video, or a numbered PNG
    sequence (out-%04d.png). A progress bar is shown when stderr is a terminal.
    """


@cli.command("diff")
@click.argument("a", type=click.Path(dir_okay=False, allow_dash=True))
@click.argument("b", type=click.Path(dir_okay=False, allow_dash=True))
@click.option("--max-rmse", type=Number(float, 0), metavar="X", help="Pass if RMSE <= X.")
@click.option("--min-psnr", type=Number(float), metavar="DB", help="Pass if PSNR >= DB.")
@click.option("--max-pixels-off", type=Number(int, 0), metavar="N",
              help="Pass if at most N pixels differ by more than --tolerance in some channel.")
@click.option("--tolerance", type=Number(float, 0), default=0.0, show_default=True, metavar="T",
              help="Per-sample difference (0..255 scale) that still counts as equal.")
@click.option("--diff-image", type=click.Path(dir_okay=False), metavar="PATH",
              help="Write A in faded gray with the pixels off in red.")
@click.option("-q", "--quiet", is_flag=True, help="Print no metrics; only the exit status tells.")
def diff_command(a, b, max_rmse, min_psnr, max_pixels_off, tolerance, diff_image, quiet):
    """Compare images A and B (e.g. an output with its golden file).

    Prints RMSE, PSNR, the largest absolute difference and the pixels off, on
    the 0..255 scale (16-bit samples divided by 257), every channel and alpha
    included. Exit 0 within tolerance, 1 beyond it or when the sizes or channel
    counts differ. Without --max-rmse, --min-psnr or --max-pixels-off the images
    must match within --tolerance everywhere. One of A and B may be '-' (stdin).
    """
    from ..app import diff
    from ..app.pipeline import WarpError, read_input
    from ..io import ImageError, encode, formats, write

    if a == "-" and b == "-":
        raise click.UsageError("only one of A and B can be '-' (stdin)")
    if diff_image:
        try:
            if diff_image == "-":
                raise ValueError("cannot be '-' (stdout holds the metrics)")
            path, fmt = formats.output_target(diff_image)
            write.check_writable(path)
        except ValueError as err:
            raise click.BadParameter(str(err), param_hint="'--diff-image'") from None
    try:
        first, second = read_input(a, "A", None), read_input(b, "B", None)
    except WarpError as err:
        raise click_error(err) from err
    reason = diff.mismatch(first, second)
    if reason:
        raise click.ClickException(f"{a} and {b} cannot be compared: {reason}")
    result = diff.compare(first, second, tolerance)
    if not quiet:
        click.echo("\n".join(result.lines()))
    if diff_image:
        try:
            write.write_atomic(path, encode.encode_image(diff.highlight(first, result.off), fmt))
        except (ImageError, OSError) as err:
            raise click.ClickException(f"cannot write {path}: {err}") from err
    broken = diff.failures(result, max_rmse, min_psnr, max_pixels_off)
    if broken:
        raise click.ClickException(f"{a} and {b} differ beyond tolerance: {'; '.join(broken)}")


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
        import json

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


from .measure import measure_command  # noqa: E402  (its own file: numerics load when it runs)

cli.add_command(measure_command)


def one_line_warning(message, category, filename, lineno, file=None, line=None):
    """Show a Python warning (e.g. numpy's overflow) as one line on stderr."""
    click.echo(f"featurewarp: warning: {message} ({os.path.basename(filename)}:{lineno})", err=True)


def main(argv=None):
    """Console-script entry point.

    Every error is one line on stderr: exit 2 for usage errors, 1 for processing
    failures (and for anything unexpected). ``featurewarp --debug ...`` also
    prints the traceback of processing failures.
    """
    argv = sys.argv[1:] if argv is None else list(argv)
    leading = []
    for arg in argv:                       # global options come before the command
        if not arg.startswith("-"):
            break
        leading.append(arg)
    debug = "--debug" in leading
    try:
        with warnings.catch_warnings():
            if not debug:
                warnings.showwarning = one_line_warning
            code = cli.main(args=argv, prog_name="featurewarp", standalone_mode=False)
    except click.exceptions.NoArgsIsHelpError as err:
        err.show()
        code = err.exit_code
    except click.UsageError as err:
        click.echo(f"featurewarp: error: {err.format_message()}", err=True)
        code = err.exit_code
    except click.exceptions.Abort:
        click.echo("featurewarp: aborted", err=True)
        code = 1
    except BrokenPipeError:                # the reader of stdout went away: nothing to report
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        code = 1
    except Exception as err:  # ClickException (processing) and anything unanticipated
        if debug:
            import traceback

            traceback.print_exception(err, file=sys.stderr)
        if isinstance(err, click.ClickException):
            message, code = err.format_message(), err.exit_code
        else:
            message, code = f"{type(err).__name__}: {err} (--debug shows a traceback)", 1
        click.echo(f"featurewarp: error: {message}", err=True)
    sys.exit(code if isinstance(code, int) else 0)


if __name__ == "__main__":
    main()

"""Options the commands share, and the one click type that checks numbers.

Every numeric option is declared as a :class:`featurewarp_cli.plugins.Param`,
the declaration a preset gives its parameters, and checked by
:meth:`Param.check` through :class:`ParamValue`: the engine's settings come from
:mod:`featurewarp_cli.engine.defaults`, the presets' from their classes, and the
few that only the command line has (``--jobs``, ``--frames``, the diff
thresholds) are declared below. Nothing here imports numpy or OpenCV.
"""

from __future__ import annotations

from dataclasses import replace

import click

from ..engine import defaults
from ..io import limits
from ..io.formats import NAMES as FORMAT_NAMES
from ..plugins import Param, ParamError, option_flag

#: Keyword arguments of the commands that are engine or output settings, not preset parameters.
SETTINGS = ("mode", "cell", "feature_weight", "decay", "formulation", "boundary", "scale_prior", "grow_past_edge",
            "strict",
            "background", "interp", "fmt", "max_pixels", "max_memory", "allow_folds", "quality", "strip")

MAX_PIXELS_PARAM = Param("max_pixels", int, limits.MAX_PIXELS,
                         "Refuse inputs with more than N pixels (checked in the file header, before decoding).",
                         min=1, max=limits.MAX_PIXELS_LIMIT, metavar="N")
QUALITY = Param("quality", int, None, "JPEG and WebP quality (WebP becomes lossy when it is given; "
                "default: JPEG 95, WebP lossless); other formats ignore it.", min=1, max=100, metavar="N")
PANEL_WIDTH = Param("panel_width", int, None, "Scale the panel to this many pixels across (default: every "
                    "view at the input's resolution).", min=28, max=32766, metavar="PX")   # 4 views of 1 px, 3 gaps
JOBS = Param("jobs", int, 1, "Worker processes, each with an Nth of --max-memory; results are byte-identical "
             "to N=1.", min=1, max=1024, metavar="N")
FRAMES = Param("frames", int, 24, "Number of frames (START and END included; at most 10 000).", min=1, max=10_000,
               metavar="N")
FPS = Param("fps", float, 12.0, "Frames per second, 0.01 to 100; a GIF plays at most 50 (its delays are in "
            "1/100 s, and browsers slow one under 2/100 s to 1/10 s): faster is written at 50, with a warning.",
            min=0.01, max=100.0)
MAX_RMSE = Param("max_rmse", float, None, "Pass if RMSE <= X.", min=0.0, metavar="X")
MIN_PSNR = Param("min_psnr", float, None, "Pass if PSNR >= DB.", metavar="DB")
MAX_PIXELS_OFF = Param("max_pixels_off", int, None,
                       "Pass if at most N pixels differ by more than --tolerance in some channel.",
                       min=0, metavar="N")
TOLERANCE = Param("tolerance", float, 0.0, "Per-sample difference (0..255 scale, 16-bit samples scaled to it) that "
                  "still counts as equal; at most 255, where every sample would pass.", min=0.0, max=255.0, metavar="T")

#: ``-m/--mask``'s help (warp, deform, edit; compare and animate say "as for warp").
MASK_HELP = ("Feature mask: an image of INPUT's width and height whose pixels with gray value >= 128 "
             "(transparent ones count as black) keep their shape; or 'alpha': INPUT's own alpha channel, "
             "opaque (>= 128) where the features are, as a cut-out's subject (a file called alpha: "
             "./alpha). A feature with a pixel on the image's edge is cut by it; one that stops short of "
             "an edge stays inside the frame. Without it the plain warp is produced. To make one: paint "
             "it in 'featurewarp edit INPUT --save-mask MASK.png' (the brush, then Save), or with "
             "ImageMagick, e.g. 'convert "
             "INPUT -alpha extract MASK.png' or 'convert -size WxH xc:black -fill white -draw \"ellipse "
             "X,Y RX,RY 0,360\" MASK.png'.")


class ByteSize(click.ParamType):
    """A size in bytes: a number with an optional K, M, G or T suffix (``--max-memory``)."""

    name = "size"

    def convert(self, value, option, ctx):
        if isinstance(value, int):
            return value
        try:
            return limits.parse_size(value)
        except ValueError as err:
            self.fail(str(err), option, ctx)


class ParamValue(click.ParamType):
    """A click type that converts and checks a value through its :class:`Param` declaration."""

    def __init__(self, param: Param):
        self.param = param
        self.name = param.type_name

    def convert(self, value, option, ctx):
        try:
            return self.param.check(value)
        except ParamError as err:               # click's message names the option already
            self.fail(err.detail(option_flag), option, ctx)


def declared(param: Param) -> dict:
    """click's option settings for ``param``: its type, default, metavar, help with default and range."""
    default = "" if param.default is None else f"default: {param.default_text()}; "
    return dict(type=ParamValue(param), default=param.default, metavar=param.metavar,
                help=f"{param.help} [{default}{param.range_text()}]")


def param_option(param: Param, *names: str) -> click.Option:
    """The option ``--NAME`` (or ``names``) declared by ``param``."""
    return click.Option(list(names) or [f"--{param.cli_name}"], **declared(param))


def option(param: Param, *names: str):
    """The ``@click.option`` decorator of :func:`param_option`."""
    return click.option(*(names or [f"--{param.cli_name}"]), **declared(param))


def limit_decoders(ctx, param, value):
    """``--max-pixels`` callback: OpenCV reads its decoders' limit once, when it loads (the
    commands load it later), and applies it to the formats whose header Pillow cannot read."""
    limits.limit_opencv_decoders(value)
    return value


def max_pixels_option() -> click.Option:
    """``--max-pixels``: the decoders' limit on an image's pixels."""
    return click.Option(["--max-pixels"], callback=limit_decoders, **declared(MAX_PIXELS_PARAM))


def max_memory_option(what: str = "work whose images and grid would need more memory than SIZE (bytes, or "
                                  "with K, M, G, T); it never makes the grid coarser (the same command gives "
                                  "the same result on any machine)") -> click.Option:
    """``--max-memory``: the memory budget, which refuses ``what`` and never changes a result."""
    return click.Option(["--max-memory"], type=ByteSize(), default=limits.MAX_MEMORY, metavar="SIZE",
                        help=f"Refuse, before allocating, {what}. [default: half of this machine's memory, "
                             f"{limits.MAX_MEMORY / 2**30:.1f}G]")


#: What ``--strict`` refuses: any warning; these are the ones a warp can have (README, ``--strict``).
STRICT = ("a feature not kept (relaxed to avoid fold-overs or moved towards the plain warp), every feature "
          "moved towards it, streaks, blank canvas or an outline beyond the plain warp's, an output that "
          "equals the input (the mask covers what the warp moves), a grid more than 0.5 px from the warp, "
          "a mask that marks nothing (a plain warp), an input of several frames of which the first is used, "
          "a CMYK JPEG without a usable profile, metadata the output cannot keep")


def boundary_option(preset) -> click.Option:
    """``--boundary``; its default is ``preset``'s own (``Warp.boundary``), resolved by the engine."""
    default = f"[default for {preset.name}: {getattr(preset, 'boundary', 'slide')}]"
    return click.Option(
        ["--boundary"], type=click.Choice(defaults.BOUNDARIES),
        help="fixed: border nodes stay where the warp puts them (the paper). slide: on a side the warp maps "
             "onto an axis-parallel straight line they may slide along it, so features cut by that side keep "
             "their shape and the canvas stays exact; other sides stay fixed. Either way the outline is the "
             "warp's: a feature cut by a border it cannot follow as one similarity (an arc's curved side) "
             "gives way, and a warning says so. release: the preset's own conditions, but such a feature "
             "keeps its shape and lets go of that border (the outline leaves the warp's there). The report's "
             f"'boundary' says what was used. {default}")


#: The engine's numeric options in plain words for --help (their declarations, which the API
#: documents, use the paper's terms: w_F, rho, double precision).
PLAIN_HELP = {
    "feature_weight": "How firmly features keep their shape against the background: their shape equations "
                      "count W^2 times the background's (the paper's w_F). Between 0.0001 and 10 000: "
                      "beyond, the solve's arithmetic cannot tell the two apart (and below, --formulation "
                      "paper cannot be solved).",
    "decay": "Width of the band around each feature, in grid cells, over which the feature's weight fades "
             "to the background's (the paper's rho); at least 0.001.",
    "scale_prior": "Similarity mode: how firmly each feature's scale and rotation are pulled towards the "
                   "warp's own there. 1 holds them as firmly as the feature's shape; smaller values let "
                   "features that fill a row or column grow or shrink uniformly so the background is not "
                   "streaked; 0 leaves them free. At most 10 000 (beyond, the solve's arithmetic cannot "
                   "tell it from infinite).",
}


def plain_option(param: Param) -> click.Option:
    """:func:`param_option` of an engine setting, with its help from :data:`PLAIN_HELP`."""
    return param_option(replace(param, help=PLAIN_HELP.get(param.name, param.help)))


def engine_options(preset=None, strict_also: str = "") -> list[click.Option]:
    """Options ``warp``, ``batch``, ``compare`` and ``animate`` share (built fresh for each command):
    ``--boundary`` shows ``preset``'s default, ``--strict`` lists ``strict_also`` after :data:`STRICT`."""
    return [
        click.Option(["--mode"], type=click.Choice(defaults.MODES), default=defaults.MODE, show_default=True,
                     help="similarity: features rotate and scale uniformly with the warp; "
                          "rigid: features also keep their size; plain: the standard warp, mask ignored."),
        param_option(defaults.CELL_PARAM),
        plain_option(defaults.FEATURE_WEIGHT_PARAM),
        plain_option(defaults.DECAY_PARAM),
        click.Option(["--formulation"], type=click.Choice(defaults.FORMULATIONS), default=defaults.FORMULATION,
                     show_default=True,
                     help="exact: each feature moves as one similarity, held exactly; paper: soft "
                          "targets for each grid cell of a feature, weighted by --feature-weight, as in "
                          "the paper the method comes from, for comparison."),
        *([boundary_option(preset)] if preset is not None else []),     # only a preset's command has it
        plain_option(defaults.SCALE_PRIOR_PARAM),
        click.Option(["--grow-past-edge"], is_flag=True,
                     help="Similarity mode: where the background would streak (stretched over "
                          "8x beyond the warp, as the strip above a bust cut by the bottom edge "
                          "under stretch --sy 2), let features cut by the frame grow past the "
                          "edges that cut them, cropped there, just enough that it does not; "
                          "background the warp does not stretch is not squeezed. Where that "
                          "cannot be done (no room, folds, rigid mode), nothing grows and a "
                          "warning says why."),
        click.Option(["--strict"], is_flag=True,
                     help=f"Exit 1 and write no image if the run has any warning (each is otherwise "
                          f"printed and the output written; a --report is written all the same, marked "
                          f"refused): {STRICT}{strict_also}."),
        click.Option(["--background"], metavar="COLOR",
                     help="Fill where no source pixel lands: #rrggbb or #rgb, a colour name, rgb(r,g,b), "
                          "hsl(h,s%,l%), rgba(r,g,b,a) or #rrggbbaa (translucent), or transparent. "
                          "Default: transparent for PNG, WebP and TIFF output, white otherwise "
                          "(formats without alpha also get transparent input pixels flattened on it)."),
        click.Option(["--interp"], type=click.Choice(defaults.INTERPOLATIONS), default=defaults.INTERPOLATION, show_default=True,
                     help="Resampling filter."),
        click.Option(["--format", "fmt"], type=click.Choice(FORMAT_NAMES, case_sensitive=False),
                     help="Output format; overrides the extension (needed for '-' unless a "
                          "prefix such as png:- is given)."),
        max_pixels_option(),
        param_option(QUALITY),
        click.Option(["--strip"], is_flag=True,
                     help="Drop the input's metadata: its ICC colour profile, EXIF, XMP and resolution (by "
                          "default all are kept, EXIF and XMP with their orientation reset, for JPEG, PNG, WebP "
                          "and TIFF output, 8- and 16-bit; BMP keeps the resolution only, GIF nothing: said in a "
                          "warning)."),
        max_memory_option(),
        click.Option(["--allow-folds"], is_flag=True,
                     help="Write a result even if triangles are still folded over (they never are "
                          "within the presets' declared ranges); without it that is an error."),
        click.Option(["-q", "--quiet"], is_flag=True, help="Print nothing but errors."),
        click.Option(["-v", "--verbose"], is_flag=True,
                     help="Print a one-line summary per image on stderr (sizes, solver, seconds)."),
    ]


def preset_options(preset) -> list[click.Option]:
    """One option per declared parameter of ``preset``."""
    return [param_option(p) for p in preset.params]


def input_output_mask(mask_help: str, output_dash: bool = True) -> list[click.Parameter]:
    """INPUT, OUTPUT ('-' for stdin and stdout) and ``-m/--mask``."""
    return [click.Argument(["input"], type=click.Path(dir_okay=False, allow_dash=True)),
            click.Argument(["output"], type=click.Path(dir_okay=False, allow_dash=output_dash)),
            click.Option(["-m", "--mask"], type=click.Path(dir_okay=False, allow_dash=True), metavar="PATH|alpha",
                         help=mask_help)]


def settings_from(preset, kwargs: dict):
    """Split a preset command's keyword arguments into Settings, quiet and verbose."""
    from ..app.pipeline import Settings

    meta = click.get_current_context().meta          # -q / -v given before the command
    quiet = kwargs.pop("quiet") or bool(meta.get("featurewarp.quiet"))
    verbose = kwargs.pop("verbose") or bool(meta.get("featurewarp.verbose"))
    if quiet and verbose:
        raise click.UsageError("--quiet and --verbose exclude each other")
    from .. import stages

    stages.quiet = quiet
    params = {p.name: kwargs.pop(p.name) for p in preset.params}
    settings = Settings(preset.name, params, **{k: kwargs.pop(k) for k in SETTINGS})
    _note_unused(settings, preset.params)
    return settings, quiet, verbose


#: The options that solve for the features, and the modes in which each does nothing.
UNUSED_IN = {"feature_weight": ("plain",), "decay": ("plain",), "formulation": ("plain",),
             "scale_prior": ("plain", "rigid"), "grow_past_edge": ("plain",)}


def _note_unused(settings, params=()) -> None:
    """A notice for each option given on the command line that ``settings.mode`` leaves unused
    (--scale-prior under rigid: features keep their size there), or that another given one of
    the preset's ``params`` overrides (:attr:`plugins.Param.overrides`: --sx under --width)."""
    from .. import stages

    context = click.get_current_context(silent=True)
    if context is None:                       # called outside a command
        return
    source = context.get_parameter_source
    maskless = "mask" in context.params and context.params["mask"] is None      # the plain warp, too
    for name, modes in UNUSED_IN.items():
        if source(name) != click.core.ParameterSource.COMMANDLINE:
            continue
        if settings.mode in modes:
            stages.notice(f"{option_flag(name)} does nothing with --mode {settings.mode}")
        elif maskless:
            stages.notice(f"{option_flag(name)} does nothing without --mask (the plain warp)")
    given = {param.name: param for param in params if source(param.name) == click.core.ParameterSource.COMMANDLINE}
    for name in given:
        over = [other for other in given.values() if name in other.overrides]
        last = [other.name for other in over if not any(other.name in top.overrides for top in over)]
        if last:                              # --sx under --width and --size: --size is what wins
            stages.notice(f"{option_flag(name)} does nothing with {' and '.join(map(option_flag, last))}, "
                          f"which {'override' if len(last) > 1 else 'overrides'} it")

"""``featurewarp deform``: the interactive mode from the shell (handles file, --move, --pin)."""

from __future__ import annotations

import json
import math
import re
import sys
from dataclasses import replace

import click

from .options import engine_options, input_output_mask
from .presets import MASK_HELP, warp_one


class Deform:
    """What :func:`settings_from` needs of a preset: a name and no parameters of its own."""

    name = "deform"
    params = ()


class PointPair(click.ParamType):
    """``X,Y`` (a pin) or, with ``move``, ``X,Y:X2,Y2`` (a handle dragged from X,Y to X2,Y2); each
    part pixels or a percentage of the image, as ``--center`` takes them (:func:`pixels`)."""

    def __init__(self, move: bool):
        self.move = move
        self.name = "move" if move else "point"

    def convert(self, value, option, ctx):
        from ..plugins import Param, ParamError

        if not isinstance(value, str):
            return value
        parts = value.split(":")
        point = Param(self.name, tuple, None, "", metavar="X,Y")
        try:
            if len(parts) != (2 if self.move else 1):
                raise ValueError
            points = [point.check(part) for part in parts]
        except ParamError as err:
            if "out of range" in err.reason:            # '1e9,5' is out of range (each part within ...)
                self.fail(err.detail(), option, ctx)
            self.fail(f"{value!r} is not {self.form()}", option, ctx)
        except ValueError:
            self.fail(f"{value!r} is not {self.form()}", option, ctx)
        return tuple(points) if self.move else points[0]

    def form(self) -> str:
        """What a value must look like, for the error."""
        return ("X,Y:X2,Y2 (from and to, " if self.move else "X,Y (") + \
            "pixels or percentages of the image: 50%,50% is its centre)"


def pixels(point: tuple[str, str], width: int, height: int) -> tuple[float, float]:
    """A ``--pin`` or ``--move`` point in pixels of a ``width`` x ``height`` image: percentages span
    the first to the last pixel centre, as ``--center``'s (:func:`featurewarp_cli.plugins.resolve_pair`)."""
    from ..plugins import resolve_pair

    return resolve_pair(point, width, height, position=True)


def shown(point) -> str:
    """A point as its flag gives it: ``20,10`` (pixels as numbers), ``50%,50%``."""
    return ",".join(part if str(part).endswith("%") else f"{float(part):g}" for part in point)


def load_handles(path: str | None) -> dict | None:
    """The parsed handles file, ``-`` for stdin (a usage error naming the file when it cannot be
    read or parsed, or holds no JSON object)."""
    if path is None:
        return None
    name = "stdin" if path == "-" else path
    try:
        if path == "-":
            text = sys.stdin.buffer.read(16 * 2**20 + 1)
        else:
            with open(path, "rb") as file:
                text = file.read(16 * 2**20 + 1)
    except OSError as err:
        raise click.BadParameter(f"cannot read {name}: {err.strerror or err}", param_hint="'--handles'") from None
    if len(text) > 16 * 2**20:
        raise click.BadParameter(f"{name} is larger than 16 MiB; not a handles file", param_hint="'--handles'")
    try:
        data = json.loads(text)
    except (ValueError, UnicodeDecodeError, RecursionError) as err:
        reason = "nested too deeply" if isinstance(err, RecursionError) else str(err) if isinstance(
            err, (json.JSONDecodeError, UnicodeDecodeError)) else "a number is too long"   # CPython's digit limit
        raise click.BadParameter(f"{name} is not valid JSON ({reason})", param_hint="'--handles'") from None
    if not isinstance(data, dict):
        raise click.BadParameter(f"{name} must hold a JSON object ({{\"version\": 1, \"points\": [...]}})",
                                 param_hint="'--handles'")
    return data


def merged_handles(data, moves, pins, canvas: str | None):
    """The handles file's content with ``--move`` and ``--pin`` added and ``--canvas`` applied
    (points that are not a list stay as they are: the schema's check names them)."""
    merged = {"version": 1} if data is None else dict(data)      # load_handles gives a dict or None
    points = merged.get("points", [])
    if (moves or pins) and isinstance(points, list):
        merged["points"] = points + [{"from": list(a), "to": list(b)} for a, b in moves] + [
            {"from": list(p), "to": list(p)} for p in pins]
    if canvas:
        merged["canvas"] = canvas
    return merged


def given_names(merged: dict, moves, pins, source: str | None) -> list[str] | None:
    """How each point handle of ``merged`` was given, for the warnings: ``--move X,Y:X2,Y2``,
    ``--pin X,Y``, or its place in the handles file ``source`` with its coordinates (None when
    the points are not a list: the schema's check names them)."""
    points = merged.get("points")
    if not isinstance(points, list):
        return None
    flags = [f"--move {shown(a)}:{shown(b)}" for a, b in moves] + [f"--pin {shown(p)}" for p in pins]
    file = f"{'stdin' if source == '-' else source}: " if source is not None and flags else ""
    named = []
    for k, point in enumerate(points[:len(points) - len(flags)]):
        try:
            (x, y), (tx, ty) = point["from"], point["to"]
            named.append(f"{file}points[{k}] ({x:g},{y:g} -> {tx:g},{ty:g})")
        except (TypeError, KeyError, ValueError):        # refused by the schema's check before any warning
            named.append(f"{file}points[{k}]")
    return named + flags


#: A place in the handles file at the start of an error (the point's index in group 1).
FILE_PLACE = re.compile(r"^(?:points(?:\[(\d+)\])?|curves\b|border\b|radius\b|canvas\b|version\b)")
POINT_PLACE = re.compile(r"points\[(\d+)\](?:\.(from|to))?")


def named_places(make, merged: dict, moves, pins, source: str | None):
    """``make`` whose errors say where the problem is: the ``--move`` or ``--pin`` that added
    a point, or the handles file ``source`` ('-': stdin) before a place in it."""
    points = merged.get("points")
    first = len(points) - len(moves) - len(pins) if isinstance(points, list) and (moves or pins) else math.inf
    flags = [f"--move {shown(a)}:{shown(b)} ({{}})" for a, b in moves] + [f"--pin {shown(p)}" for p in pins]

    def name(match):
        k = int(match.group(1))
        return match.group(0) if k < first else flags[k - first].format(match.group(2) or "from")

    def named(width: int, height: int, mask=None):
        try:
            return make(width, height, mask)
        except ValueError as err:
            message = str(err)
            place = FILE_PLACE.match(message)
            in_file = source is not None and place is not None and int(place.group(1) or -1) < first
            message = POINT_PLACE.sub(name, message)
            raise ValueError(f"{'stdin' if source == '-' else source}: {message}" if in_file else message) from None

    return named


#: What ``--strict`` also refuses in ``deform``: the handles' own warnings.
STRICT_DEFORM = ("; and the handles' warnings: a handle or curve that ends over 3 px from its target, a fold the "
                 "handles ask for, a crease, an image shrunk to under 1 % of its area or off the canvas, a handles file's "
                 "unknown key or version-1 angle, a handle on a feature it cannot carry")


def deform_command() -> click.Command:
    """``featurewarp deform INPUT OUTPUT --handles H.json``."""
    params = input_output_mask(MASK_HELP) + [
        click.Option(["--handles"], type=click.Path(dir_okay=False, allow_dash=True), metavar="H.json",
                     help="Handles file (JSON; see README, 'The handles file'): points dragged "
                          "from -> to, pins, curves, the border, the canvas. '-' reads stdin."),
        click.Option(["--move"], type=PointPair(move=True), multiple=True, metavar="X,Y:X2,Y2",
                     help="A handle dragged from X,Y to X2,Y2, in pixels or percentages of the "
                          "image (50%,50%: its centre) (repeatable; added to --handles)."),
        click.Option(["--pin"], type=PointPair(move=False), multiple=True, metavar="X,Y",
                     help="A point that stays where it is, in pixels or percentages of the image "
                          "(repeatable). At least two places must be held in all: a pin counts."),
        click.Option(["--canvas"], type=click.Choice(["fit", "input"]),
                     help="fit: the deformed image's bounding box (default); input: the input's "
                          "size and coordinates. Overrides the file's."),
        click.Option(["--report"], type=click.Path(dir_okay=False), metavar="PATH",
                     help="Write a JSON report (as for warp; also of a refused run, marked refused)."),
        click.Option(["--save-grid"], type=click.Path(dir_okay=False), metavar="PATH.npz|PATH.obj",
                     help="Save the solved mesh (as for warp)."),
        click.Option(["--grid", "draw_grid"], is_flag=True, help="Draw the deformed grid over the result."),
    ] + [o for o in engine_options(strict_also=STRICT_DEFORM) if o.name not in ("boundary", "grow_past_edge")]

    def callback(input, output, mask, handles, move, pin, canvas, report, save_grid, draw_grid, **kwargs):
        from .options import settings_from

        if handles is None and not move and not pin:
            raise click.UsageError("give the handles: --handles H.json, or --move X,Y:X2,Y2 with --pin X,Y")
        if handles == "-" and input == "-":   # before stdin is read as the handles
            raise click.BadParameter("cannot be '-' when INPUT is '-' (stdin holds the image)",
                                     param_hint="'--handles'")
        data = load_handles(handles)
        kwargs.update(boundary=None, grow_past_edge=False)
        settings, quiet, verbose = settings_from(Deform, kwargs)
        from ..engine.deform import handles_factory

        merged = merged_handles(data, move, pin, canvas)          # the points as given: names and places
        names, source = given_names(merged, move, pin, handles), "stdin" if handles == "-" else handles or "handles"
        decay = settings.decay

        def factory(width: int, height: int, mask=None):           # percentages of this image in pixels
            def at(point):
                return pixels(point, width, height)
            sized = merged_handles(data, [(at(a), at(b)) for a, b in move], [at(p) for p in pin], canvas)
            return handles_factory(sized, decay, names, source)(width, height, mask)

        settings = replace(settings, warp_factory=named_places(factory, merged, move, pin, handles))
        warp_one(settings, quiet, verbose, input, output, mask, report, save_grid, draw_grid,
                 also_read=((handles, "--handles"),) if handles else ())

    doc = """Deform INPUT by handles into OUTPUT, keeping masked features in shape.

    The handles (points dragged from one place to another, pins, curves, the
    border's outline) define an as-rigid-as-possible map of the image
    (converged ARAP, kept fold-free); the features marked in the mask then
    keep their shape under it, as with warp. Handles that describe one
    similarity give exactly that similarity. Coordinates are pixels, pixel
    centres at whole numbers; --pin and --move also take percentages of the
    image, as --center does (50%,50%: its centre; 0% and 100%: the first and
    last pixel centres). Design a handles file live with 'featurewarp edit'.

    \b
    Examples:
      featurewarp deform in.jpg out.jpg -m mask.png --handles h.json
      featurewarp deform in.jpg out.jpg -m mask.png --pin 20,20 --pin 620,20 \\
          --move 320,400:360,460 --canvas input
    """
    return click.Command("deform", params=params, callback=callback, help=doc, no_args_is_help=True,
                         short_help="Deform by handles (points, curves, border), features kept.")

"""The plugin protocol (:class:`Warp`, :class:`Param`) and the preset registry.

A preset is a subclass of :class:`Warp` registered under the entry-point group
``featurewarp.warps``; the built-ins (in the installed package
``featurewarp_warps``, the repository's ``warps/`` folder) are registered in this
package's metadata exactly as a third-party package registers its own. A preset
declares its parameters with :class:`Param` so that the command line builds
options and help from them, and it maps points: ``warp(points)`` takes an
``(N, 2)`` array of source pixel positions (x, y; pixel centres at integer
coordinates) and returns their ``(N, 2)`` positions on the output canvas, whose
size is ``warp.canvas``. Plugins import the protocol from here::

    from featurewarp_cli.plugins import Param, Warp

A plugin that fails to import is reported as broken instead of breaking the
command line. Naming or loading a built-in preset does not scan the entry
points: importing :mod:`importlib.metadata` and scanning costs about 25 ms of
every command's start-up. The built-ins therefore always win over a
third-party entry point of the same name.

Examples
--------
>>> import numpy as np
>>> from featurewarp_cli.plugins import load
>>> w = load("swirl")(640, 480, angle=120)
>>> w.canvas
(640, 480)
>>> w(np.array([[319.5, 239.5]]))      # the centre does not move
array([[319.5, 239.5]])
"""

from __future__ import annotations

import importlib
import math
import re
from dataclasses import dataclass
from functools import lru_cache
from typing import TYPE_CHECKING, ClassVar

if TYPE_CHECKING:                   # numpy is imported on first use: --help needs none of it
    import numpy as np

__all__ = ["Param", "ParamError", "option_flag", "Warp", "load", "names", "known", "shadowing", "resolve_pair",
           "UnknownPreset", "GROUP", "BUILTIN"]


def option_flag(name: str) -> str:
    """The command line's flag of parameter ``name``: ``--inner-radius`` for ``inner_radius``."""
    return "--" + name.replace("_", "-")


def number_text(number: float) -> str:
    """A number as short as it reads back exactly: 100.0000001 stays so (``:g`` showed 100, out
    of a range that ends at 100), 100.0 is 100."""
    text = repr(float(number))
    return text[:-2] if text.endswith(".0") else text


class ParamError(ValueError):
    """A refused parameter value, naming the parameters as its caller names them.

    The message is written once, with the parameters' Python names: that is what the API
    (:func:`featurewarp_cli.warp`, a preset's constructor, :meth:`Param.check`) raises,
    ``angle: 900 is out of range (-540 <= DEG <= 540)``. The command line renders the
    same error with its flags, ``--angle: 900 is out of range ...``, through
    :meth:`render` and :func:`option_flag`.

    Parameters
    ----------
    names : str or tuple of str
        The parameter(s) at fault, by Python name: ``"angle"``, or ``("tl", "tr", "br", "bl")``.
    reason : str
        What is wrong. A parameter it names is written between backquotes (```where```) and
        is one of ``names`` or ``mentions``, so that each caller names it its own way too.
    mentions : tuple of str
        Other parameters the reason names.

    Examples
    --------
    >>> err = ParamError("angle", "171 is out of range when `where` is lower", mentions=("where",))
    >>> str(err)
    'angle: 171 is out of range when where is lower'
    >>> err.render(option_flag)
    '--angle: 171 is out of range when --where is lower'
    """

    def __init__(self, names: str | tuple[str, ...], reason: str, mentions: tuple[str, ...] = ()):
        self.names = (names,) if isinstance(names, str) else tuple(names)
        self.reason, self.mentions = reason, tuple(mentions)
        super().__init__(self.render())

    def __reduce__(self):                   # crosses process boundaries (batch workers) whole
        return type(self), (self.names, self.reason, self.mentions)

    def detail(self, name_of=str) -> str:
        """The reason, each parameter it names written as ``name_of(name)``."""
        named = set(self.names) | set(self.mentions)
        return re.sub(r"`(\w+)`", lambda m: name_of(m[1]) if m[1] in named else m[0], self.reason)

    def render(self, name_of=str) -> str:
        """The whole message, each parameter written as ``name_of(name)`` (default: its Python name)."""
        return f"{'/'.join(map(name_of, self.names))}: {self.detail(name_of)}"


@dataclass(frozen=True)
class Param:
    """Declaration of one preset parameter.

    Parameters
    ----------
    name : str
        Python name; the option is ``--name`` (underscores become dashes).
    type : type
        ``float`` or ``int``; or ``tuple`` for a pair such as a point ``X,Y`` or a size
        ``WxH``, each part pixels or a percentage of the image's width and height
        (:func:`resolve_pair` turns it into pixels); or ``str`` for one word of ``choices``.
    default : float or int or str or tuple of str or None
        Value when the option is not given. None means "not set".
    help : str
        One line for ``--help``.
    min, max : float, optional
        Allowed range; None means unbounded on that side.
    min_open, max_open : bool
        True when the bound itself is excluded.
    metavar : str
        Placeholder shown in help.
    percent : bool
        Also accept a percentage: ``150%`` is 1.5 (scale factors).
    choices : tuple of str
        The words a ``str`` parameter takes (``lower``, ``upper``), matched without regard to case.
    overrides : tuple of str
        Parameters this one replaces when both are given (``width`` overrides ``sx``): the
        command line says so rather than drop one silently.
    """

    name: str
    type: type
    default: float | int | None
    help: str
    min: float | None = None
    max: float | None = None
    min_open: bool = False
    max_open: bool = False
    metavar: str = "F"
    percent: bool = False
    choices: tuple[str, ...] = ()
    overrides: tuple[str, ...] = ()

    def range_text(self) -> str:
        """Human-readable range, e.g. ``0 < F <= 360``."""
        if self.type is tuple:
            return f"{self.metavar}: pixels or percentages"
        if self.type is str:
            return "|".join(self.choices)
        show = (lambda n: str(int(n))) if self.type is int else (lambda n: f"{n:g}")
        lo = "" if self.min is None else f"{show(self.min)} {'<' if self.min_open else '<='} "
        hi = "" if self.max is None else f" {'<' if self.max_open else '<='} {show(self.max)}"
        return f"{lo}{self.metavar}{hi}" if lo or hi else "any real number"

    def default_text(self) -> str:
        """The default as help shows it: ``unset``, ``24`` or ``0.5``."""
        if self.default is None:
            return "unset"
        if self.type is tuple:
            return ",".join(self.default)
        return str(self.default) if self.type in (int, str) else f"{self.default:g}"

    def check(self, value):
        """Convert and validate ``value``; raise :class:`ParamError` naming the problem."""
        if value is None:
            if self.default is None:
                return None
            raise ParamError(self.name, "a value is needed")
        if self.type is tuple:
            return self._check_pair(value)
        if self.type is str:
            return self._check_choice(value)
        if isinstance(value, bool):
            raise ParamError(self.name, f"{value!r} is not a number")
        text = value.strip() if isinstance(value, str) else None
        try:
            number = _decimal(text[:-1]) / 100.0 if self.percent and text and text.endswith("%") else _decimal(value)
        except (TypeError, ValueError):
            raise ParamError(self.name, f"{value!r} is not a number") from None
        if not math.isfinite(number):
            raise ParamError(self.name, f"{value!r} is not a finite number")
        if self.type is int:
            if number != int(number):
                raise ParamError(self.name, f"{value!r} is not a whole number")
            number = int(number)
        too_low = self.min is not None and (number < self.min or (self.min_open and number == self.min))
        too_high = self.max is not None and (number > self.max or (self.max_open and number == self.max))
        if too_low or too_high:
            shown = str(value).strip() if self.type is int else number_text(number)
            raise ParamError(self.name, f"{shown} is out of range ({self.range_text()})")
        return number

    def _check_pair(self, value) -> tuple[str, str]:
        """Two parts, each a finite number of pixels or a percentage: ``'40%', '120'``."""
        parts = re.split(r"\s*[,x\u00d7]\s*", value.strip()) if isinstance(value, str) else list(value)
        try:
            if len(parts) != 2:
                raise ValueError
            numbers = [_decimal(str(part).strip().removesuffix("%")) for part in parts]
        except (TypeError, ValueError):
            raise ParamError(self.name, f"{value!r} is not {self.metavar} "
                                        f"(two numbers of pixels or percentages)") from None
        if not all(math.isfinite(n) for n in numbers):
            raise ParamError(self.name, f"{value!r} is not finite")
        for part, number in zip(parts, numbers):
            limit = PAIR_PERCENT_LIMIT if str(part).strip().endswith("%") else PAIR_PIXEL_LIMIT
            if abs(number) > limit:
                raise ParamError(self.name, f"{value!r} is out of range (each part within "
                                            f"+-{PAIR_PIXEL_LIMIT:g} px or +-{PAIR_PERCENT_LIMIT:g} %)")
        return tuple(str(part).strip() for part in parts)

    def _check_choice(self, value) -> str:
        """One of ``choices``, whatever its case: ``'Lower'`` -> ``'lower'``."""
        word = value.strip().lower() if isinstance(value, str) else None
        if word not in self.choices:
            raise ParamError(self.name, f"{value!r} is not one of {', '.join(self.choices)}")
        return word

    @property
    def type_name(self) -> str:
        """``float``, ``int``, ``pair`` or ``choice``."""
        return {tuple: "pair", str: "choice"}.get(self.type, self.type.__name__)

    @property
    def cli_name(self) -> str:
        """The option's name without its dashes: ``inner-radius`` for ``inner_radius``."""
        return self.name.replace("_", "-")

    def as_dict(self) -> dict:
        """JSON-ready description (for ``featurewarp warps --json``)."""
        return {
            "name": self.name, "type": self.type_name, "default": self.default,
            "min": self.min, "max": self.max, "min_open": self.min_open,
            "max_open": self.max_open, "help": self.help,
        } | ({"choices": list(self.choices)} if self.type is str else {})


class Warp:
    """Base class of a preset warp: a vectorized map of source points.

    Subclasses set ``name``, ``summary``, ``params`` (and optionally ``example`` and
    ``boundary``) and implement ``_setup`` (derive constants and the canvas) and
    ``forward``. The first paragraph of the subclass's docstring is its ``--help``.

    Parameters
    ----------
    width, height : int
        Size of the source image in pixels.
    **values
        Parameter values by name; missing ones take their declared default.

    Attributes
    ----------
    canvas : tuple of int
        ``(width, height)`` of the output image.
    offset : tuple of float
        Position of the canvas origin in the warp's own coordinates (non-zero
        when the canvas is the bounding box of a shape, as for ``arc``).
    values : dict
        The validated parameter values.
    """

    name: ClassVar[str] = ""
    summary: ClassVar[str] = ""
    params: ClassVar[tuple[Param, ...]] = ()
    #: The preset's own options in one example for ``--help`` (``--angle 120``); the help
    #: builds the whole command line around it. Empty: no example. The help's text is the
    #: first paragraph of the class docstring (or ``summary``): what the preset does and what
    #: its options mean, for a user; later paragraphs (the maths) are left out of it.
    example: ClassVar[str] = ""
    #: Default border handling: 'slide' lets nodes move along every side that W
    #: maps onto an axis-parallel straight line, unless W leaves the whole border
    #: in place (all sides of a stretch; none of a swirl or bulge, whose border
    #: stays put, or of an arc, whose sides are arcs and oblique rays), so a
    #: feature cut by the border keeps its shape while the canvas stays exact.
    #: 'fixed' pins every border node to W (the paper). A preset may override it.
    boundary: ClassVar[str] = "slide"

    def __init__(self, width: int, height: int, /, **values):
        if width < 1 or height < 1:
            raise ValueError(f"image size {width}x{height} is empty")
        known = {p.name for p in self.params}
        unknown = set(values) - known
        if unknown:
            import difflib

            near = [m for name in sorted(unknown) for m in difflib.get_close_matches(name, sorted(known), 1)]
            hint = f" (did you mean {', '.join(f'`{m}`' for m in near)}?)" if near else ""
            raise ParamError(tuple(sorted(unknown)), f"{self.name} has no such parameter{hint}", mentions=tuple(near))
        self.width, self.height = int(width), int(height)
        self.values = {p.name: p.check(values.get(p.name, p.default)) for p in self.params}
        self.offset = (0.0, 0.0)
        self.canvas = (self.width, self.height)
        self._setup(**self.values)

    def _setup(self, **values) -> None:
        """Derive constants and set ``self.canvas`` (and ``self.offset``)."""

    def forward(self, points: np.ndarray) -> np.ndarray:
        """Map ``(N, 2)`` source positions to ``(N, 2)`` canvas positions."""
        raise NotImplementedError

    def __call__(self, points) -> np.ndarray:
        """``forward`` of a copy of ``points`` as (N, 2) floats: a plugin that moves them in place
        moved the caller's grid nodes (the fidelity check then measured a 10 px stray that was
        not there, took the finest grid, and warned)."""
        import numpy as np

        return self.forward(np.array(points, dtype=np.float64).reshape(-1, 2))

    def __repr__(self) -> str:
        args = ", ".join(f"{k}={v!r}" for k, v in self.values.items())
        return f"{type(self).__name__}({self.width}, {self.height}, {args})"


#: How far (px) a shape may reach past a whole number of pixels without its canvas growing a
#: row or column: an arc of 0.001 degrees bows 0.001 px, a handles border at the image's
#: corners lands 4e-5 px out by rounding; either added a blank row or column.
CANVAS_SLACK = 0.01


class CheckedWarp:
    """``warp`` whose every call is checked against the :class:`Warp` contract: (N, 2) finite
    canvas positions for (N, 2) points. A preset that broke it gave an internal error deep in
    the solve (``cannot unpack non-iterable NoneType``) or, for NaN, a mesh with NaN nodes and
    no word. Its attributes are the warp's."""

    def __init__(self, warp):
        self.warp = warp

    def __getattr__(self, name):
        return getattr(self.warp, name)

    def __call__(self, points):
        import numpy as np

        out = np.asarray(self.warp(points))
        name = getattr(self.warp, "name", type(self.warp).__name__)
        if out.shape != np.shape(points):
            raise ValueError(f"{name}: the warp returned an array of shape {out.shape} for {np.shape(points)} "
                             "points; (N, 2) canvas positions are expected")
        if not np.all(np.isfinite(out)):
            raise ValueError(f"{name}: the warp returned positions that are not finite (inf or NaN)")
        return out


def canvas_size(extent) -> tuple[int, int]:
    """The canvas (width, height) that holds a shape ``extent`` (width, height) pixels across,
    within :data:`CANVAS_SLACK`."""
    width, height = (max(1, math.ceil(float(side) - CANVAS_SLACK)) for side in extent)
    return width, height


#: The largest canvas side a warp may ask for (a preset's fitted canvas, deform's).
MAX_CANVAS_SIDE = 65535


def check_canvas_side(size: tuple[int, int], name: str, hint: str = "") -> None:
    """ValueError (``name: the result would be WxH pixels ...``) for a canvas over
    :data:`MAX_CANVAS_SIDE` a side; ``hint``: what to do about it, after a semicolon."""
    if max(size) > MAX_CANVAS_SIDE:
        raise ValueError(f"{name}: the result would be {size[0]}x{size[1]} pixels (at most {MAX_CANVAS_SIDE} a side"
                         f"{'; ' + hint if hint else ''})")


#: A point or size parameter's parts: pixels and percentages within these (beyond, a warp's
#: arithmetic overflows or its grid cannot follow it: ``--center 1e308,1e308``).
PAIR_PIXEL_LIMIT = 1e5
PAIR_PERCENT_LIMIT = 1e3


def _decimal(value) -> float:
    """``float(value)``, but for text Python's own syntax takes and a number does not: digits
    grouped by underscores (``--angle 1_0`` ran as 10)."""
    if isinstance(value, str) and "_" in value:
        raise ValueError(value)
    return float(value)


def resolve_pair(pair: tuple[str, str], width: int, height: int, position: bool = False) -> tuple[float, float]:
    """A checked pair (:meth:`Param.check` of a ``tuple`` parameter) in pixels.

    Percentages are of ``width`` and ``height`` (a size: ``150%``), or with ``position``
    of the span between the first and last pixel centres, so that ``50%,50%`` is the
    image's centre and ``0%,0%`` its top-left pixel."""
    def one(part: str, extent: int) -> float:
        if not part.endswith("%"):
            return float(part)
        return float(part[:-1]) / 100.0 * ((extent - 1) if position else extent)

    return one(pair[0], width), one(pair[1], height)


def centre(width: int, height: int) -> np.ndarray:
    """Centre of an image in pixel-centre coordinates."""
    import numpy as np

    return np.array([(width - 1) / 2.0, (height - 1) / 2.0])


GROUP = "featurewarp.warps"

#: The built-in presets: name -> ``module:attribute``, as in pyproject.toml's entry points
#: (tests/test_presets.py checks that the two agree).
BUILTIN = {
    "stretch": "featurewarp_warps.stretch:Stretch",
    "arc": "featurewarp_warps.arc:Arc",
    "swirl": "featurewarp_warps.swirl:Swirl",
    "bulge": "featurewarp_warps.bulge:Bulge",
    "arch": "featurewarp_warps.arch:Arch",
    "flag": "featurewarp_warps.flag:Flag",
    "fish": "featurewarp_warps.fish:Fish",
    "rise": "featurewarp_warps.rise:Rise",
    "inflate": "featurewarp_warps.inflate:Inflate",
    "squeeze": "featurewarp_warps.squeeze:Squeeze",
    "shell": "featurewarp_warps.shell:Shell",
    "perspective": "featurewarp_warps.perspective:Perspective",
    "cylinder": "featurewarp_warps.cylinder:Cylinder",
    "sphere": "featurewarp_warps.sphere:Sphere",
}


class UnknownPreset(LookupError):
    """No preset of that name is registered, or it failed to load."""


def entry_points() -> list:
    """The entry points of :data:`GROUP` (importing :mod:`importlib.metadata` on first use)."""
    from importlib.metadata import entry_points as scan

    return list(scan(group=GROUP))


@lru_cache(maxsize=None)
def names() -> tuple[str, ...]:
    """Names of all registered presets, sorted."""
    return tuple(sorted(set(BUILTIN) | {ep.name for ep in entry_points()}))


def shadowing() -> list[tuple[str, str]]:
    """(name, entry point) of installed plugins that register a built-in's name (ignored: the
    built-in names always mean the built-ins)."""
    return [(ep.name, ep.value) for ep in entry_points() if ep.name in BUILTIN and ep.value != BUILTIN[ep.name]]


def known(name: str) -> bool:
    """Whether a preset ``name`` is registered (without a scan for the built-ins)."""
    return name in BUILTIN or name in names()


@lru_cache(maxsize=None)
def load(name: str):
    """Load the preset class registered as ``name``.

    Raises
    ------
    UnknownPreset
        If ``name`` is not registered or its module fails to import.
    TypeError
        If ``name`` is not a string.
    """
    if not isinstance(name, str):
        raise TypeError(f"a preset is named by a string ({', '.join(names())}), not {type(name).__name__}")
    matches = [] if name in BUILTIN else [ep for ep in entry_points() if ep.name == name]
    if name not in BUILTIN and not matches:
        from .styles import style_owners       # it reads the presets' summaries through this module

        owners = [(preset, style) for preset, style, _ in style_owners(name)]
        hint = (" and ".join(f"{style} is {preset}'s style" for preset, style in owners) + "; " if owners else
                did_you_mean(name, names()))
        raise UnknownPreset(f"unknown preset {name!r}; {hint}available: {', '.join(names()) or 'none'}")
    try:
        if matches:
            return matches[0].load()
        module, _, attribute = BUILTIN[name].partition(":")
        return getattr(importlib.import_module(module), attribute)
    except Exception as err:  # a broken third-party plugin must not take the CLI down
        raise UnknownPreset(f"preset {name!r} failed to load: {type(err).__name__}: {err}") from None


def did_you_mean(word: str, words) -> str:
    """``"did you mean 'swirl'? "`` for the closest of ``words`` to a misspelt ``word``, or ``""``."""
    import difflib

    close = difflib.get_close_matches(word, list(words), n=1)
    return f"did you mean {close[0]!r}? " if close else ""

"""Handles: the positional constraints of the interactive mode, and their JSON format.

A handles file (version 2; version 1 is version 2 without ``angle``) is a JSON object::

    {"version": 2,
     "points": [{"from": [x, y], "to": [x, y], "angle": A}, ...],   # from == to: a pin
     "curves": [{"from": [[x, y], ...], "to": [[x, y], ...]}, ...],
     "border": "free" | "pinned" | {"top": SIDE, "right": SIDE, "bottom": SIDE, "left": SIDE},
     "canvas": "fit" | "input",
     "radius": R}

Coordinates are pixels with pixel centres at whole numbers (the image spans -0.5 to
width - 0.5). A point handle holds a disc of radius R pixels (default: see
:func:`default_radius`), turned by the handles' overall rotation, or by ``angle`` degrees
when it has one (version 2: the editor's Alt-drag around a pin; positive turns +x towards
+y, clockwise on screen). A curve's two polylines may have different numbers of points:
both are resampled by arc length. A border SIDE is a polyline ``[[x, y], ...]`` or a cubic
Bezier ``{"bezier": [p0, p1, p2, p3]}``, running left to right (top, bottom) or top to bottom
(left, right), giving where that edge of the image goes; sides not given are free.
``canvas``: ``fit`` (default) is the bounding box of the deformed image, ``input`` keeps
the input's size and coordinates. Keys this version does not know are ignored, with a warning
naming them (``angle`` in a version-1 file too). :meth:`Handles.as_dict` writes version 1 when nothing
needs version 2, so files stay readable by the featurewarp that wrote them before.
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass, field

import numpy as np

from .grid import Grid

VERSION = 2
#: The versions this featurewarp reads.
VERSIONS = (1, 2)
KEYS = ("version", "points", "curves", "border", "canvas", "radius")
#: Samples on the ring of a point handle with an ``angle`` (its centre is one more).
RING_POINTS = 8
#: Points a Bezier side is flattened to before it is resampled by arc length.
BEZIER_POINTS = 256
#: Point handles and curves a handles file may hold (the schema's maxItems): each point
#: handle is a disc of 17 samples of the rigid map and each curve costs a few array passes,
#: so 490 000 handles (16 MiB) took 2.2 GB; a grid of 4 096 nodes cannot follow more anyway.
MOST = {"points": 10_000, "curves": 10_000}
#: Curve samples per cell of the grid a curve is followed on, at most (all curves together).
CURVE_SAMPLES_PER_CELL = 2
#: Targets may lie at most this many image sizes beyond the image.
REACH = 10
#: Point handles must start at least this far apart (px).
MIN_SPACING = 0.5


@dataclass
class Handles:
    """Validated handles (see the module docstring for the format).

    Attributes
    ----------
    points_from, points_to : (K, 2) ndarray
    curves : list of ((n, 2) ndarray, (m, 2) ndarray)
    border : 'free', 'pinned' or dict side -> (n, 2) ndarray
    canvas : 'fit' or 'input'
    angles : (K,) ndarray
        Each point handle's turn in radians (NaN: none given, the overall rotation applies).
    radius : float or None
        Disc radius of the point handles; None: :func:`default_radius`.
    notes : list of str
        What was ignored (unknown keys).
    border_spec : str or dict
        The border as the file gave it (Bezier sides stay Bezier when saved again).
    names : list of str or None
        How each point handle was given (``--pin 100,100``), for warnings; None: by its
        place in ``points`` and its coordinates.
    """

    points_from: np.ndarray
    points_to: np.ndarray
    curves: list = field(default_factory=list)
    border: object = "free"
    canvas: str = "fit"
    radius: float | None = None
    notes: list = field(default_factory=list)
    border_spec: object = "free"
    angles: np.ndarray = None
    names: list | None = None

    def __post_init__(self):
        """Point handles as (K, 2) arrays of finite numbers (a Handles made directly, not from a
        dict, gave numpy's and scipy's errors on NaN or on lists)."""
        ends = []
        for points, end in ((self.points_from, "from"), (self.points_to, "to")):
            try:
                points = np.asarray(points, float)
            except (TypeError, ValueError):
                raise ValueError(f"points[].{end}: expected (K, 2) numbers") from None
            if points.ndim != 2 or points.shape[1] != 2:
                raise ValueError(f"points[].{end}: expected (K, 2) numbers, not shape {points.shape}")
            ends.append(_points(points.tolist(), f"points[{{}}].{end}"))
        if len(ends[0]) != len(ends[1]):
            raise ValueError(f"points: {len(ends[0])} sources but {len(ends[1])} targets")
        self.points_from, self.points_to = ends
        if self.angles is None:
            self.angles = np.full(len(self.points_from), np.nan)

    def check_image(self, width: int, height: int) -> None:
        """ValueError unless the point handles start inside a ``width`` x ``height`` image and end
        near it (:meth:`from_dict` checks this; a Handles made directly, here)."""
        _inside(self.points_from, width, height, "points[{}].from")
        _near(self.points_to, width, height, "points[{}].to")

    @classmethod
    def from_dict(cls, data, width: int, height: int, source: str = "handles") -> "Handles":
        """Check ``data`` (a parsed handles file) against a ``width`` x ``height`` image: its
        version, then its shape through the shipped JSON Schema (``featurewarp schema
        handles``), then what a schema cannot say (finite numbers, places in the image).
        ``source`` names the file in the notes on keys it ignores (``h.json: ignoring ...``).

        Raises
        ------
        ValueError
            One line naming the first problem and its place (``points[2].to: ...``).
        """
        if not isinstance(data, dict):
            raise ValueError("the handles file must hold a JSON object ({\"version\": 1, \"points\": [...]})")
        version = data.get("version")
        if type(version) is float and version in VERSIONS:         # 1.0: the schema's enum takes it too
            version = int(version)
        if not (type(version) is int and version in VERSIONS):      # which schema applies, before it does
            given = "missing" if "version" not in data else json.dumps(version)
            raise ValueError(f"version: {given}; this featurewarp reads versions "
                             f"{', '.join(map(str, VERSIONS))} (\"version\": {VERSION})")
        _check_shape(data)
        notes = [f"handles: ignoring the key {key!r} (unknown to version {version})" for key in data if key not in KEYS]
        notes += _unknown_keys(data, version)
        points = data.get("points", [])
        angles = _angles(points, version, notes)
        notes = [f"{source}: {note.split(': ', 1)[1]}" if note.startswith("handles: ") else note for note in notes]
        sources = _points([p["from"] for p in points], "points[{}].from")
        targets = _points([p["to"] for p in points], "points[{}].to")
        _inside(sources, width, height, "points[{}].from")
        _near(targets, width, height, "points[{}].to")
        _no_duplicates(sources)
        curves = []
        for i, curve in enumerate(data.get("curves", [])):
            start = _points(curve["from"], f"curves[{i}].from[{{}}]")
            if not np.ptp(start, axis=0).any():       # no direction to follow: not a curve
                raise ValueError(f"curves[{i}].from: every point is ({start[0, 0]:g}, {start[0, 1]:g}); a curve "
                                 "runs somewhere (a point handle moves one point)")
            end = _points(curve["to"], f"curves[{i}].to[{{}}]")
            _inside(start, width, height, f"curves[{i}].from[{{}}]")
            _near(end, width, height, f"curves[{i}].to[{{}}]")
            curves.append((start, end))
        radius = data.get("radius")
        if radius is not None and not (_finite(radius) and radius <= max(width, height)):
            raise ValueError(f"radius: {radius!r}; use a number of pixels from 0 to {max(width, height)}")
        border = data.get("border", "free")
        handles = cls(sources, targets, curves, _border(border, width, height), data.get("canvas", "fit"),
                      None if radius is None else float(radius), notes,
                      border if isinstance(border, str) else json.loads(json.dumps(border)), angles)
        handles.check_enough()
        return handles

    @classmethod
    def from_file(cls, path, width: int, height: int) -> "Handles":
        """The handles file at ``path`` (a handles JSON file, as ``deform --handles`` reads),
        checked against a ``width`` x ``height`` image (see :meth:`from_dict`).

        Raises
        ------
        ValueError
            One line naming the file and the problem (unreadable, not JSON, not valid handles).
        """
        try:
            with open(path, "rb") as file:
                text = file.read()
            data = json.loads(text)
        except OSError as err:
            raise ValueError(f"{path}: cannot read it: {err.strerror or err}") from None
        except (ValueError, RecursionError) as err:
            raise ValueError(f"{path}: not valid JSON ({err if isinstance(err, ValueError) else 'nested too deeply'})") \
                from None
        try:
            return cls.from_dict(data, width, height)
        except ValueError as err:
            raise ValueError(f"{path}: {err}") from None

    def name(self, k: int) -> str:
        """How point handle ``k`` is named in warnings: as it was given (:attr:`names`), or by
        its place in the file and its coordinates."""
        if self.names is not None and k < len(self.names):
            return self.names[k]
        (x, y), (tx, ty) = self.points_from[k], self.points_to[k]
        return f"points[{k}] ({x:g},{y:g} -> {tx:g},{ty:g})"

    @classmethod
    def from_moves(cls, moves, pins, width: int, height: int, canvas: str = "fit") -> "Handles":
        """Handles from ``--move X,Y:X2,Y2`` and ``--pin X,Y`` pairs (already parsed to numbers)."""
        points = [{"from": list(a), "to": list(b)} for a, b in moves] + [{"from": list(p), "to": list(p)} for p in pins]
        return cls.from_dict({"version": 1, "points": points, "canvas": canvas}, width, height)

    def check_enough(self) -> None:
        """ValueError unless at least two distinct places are held (a rotation and a scale)."""
        held = len(np.unique(np.round(self.points_from, 6), axis=0)) + 2 * len(self.curves)
        held += 4 if self.border == "pinned" else 2 * len(self.border) if isinstance(self.border, dict) else 0
        if held < 2:
            given = "none are given" if held == 0 else "one handle alone leaves the rotation and scale free"
            raise ValueError(f"points: {given}; at least two handles are needed (a pin counts, or a curve, "
                             "or the border)")

    def as_dict(self) -> dict:
        """The JSON-ready handles file (version 1 unless a point has an ``angle``)."""
        points = [{"from": _plain(a), "to": _plain(b)} for a, b in zip(self.points_from, self.points_to)]
        for point, angle in zip(points, self.angles):
            if np.isfinite(angle):
                point["angle"] = round(math.degrees(angle), 6)
        data = {"version": 2 if np.any(np.isfinite(self.angles)) else 1,
                "points": points,
                "curves": [{"from": [_plain(p) for p in a], "to": [_plain(p) for p in b]} for a, b in self.curves],
                "border": self.border_spec,
                "canvas": self.canvas}
        if self.radius is not None:
            data["radius"] = self.radius
        return data

    def constraints(self, grid: Grid, radius: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Source points, their targets and their disc radii: point handles (radius
        ``radius``; one with an angle holds its centre, and its ring turned by that angle and
        scaled by the other handles' overall scale, after the curves), curves resampled by arc
        length, and the border's nodes.

        A curve is sampled every half cell of ``grid``, and the curves together at most
        :data:`CURVE_SAMPLES_PER_CELL` times per cell: a curve cannot say more than the grid
        can follow, and a longer one (a scribble that crosses the image many times over) is
        sampled more sparsely instead of costing time and memory in proportion to its length."""
        lengths = [_length(start) for start, _ in self.curves]
        budget = CURVE_SAMPLES_PER_CELL * (grid.nx - 1) * (grid.ny - 1)
        step = max(0.5 * min(grid.spacing), sum(lengths) / budget)
        turned = np.isfinite(self.angles)
        sources, targets = [self.points_from], [self.points_to]
        radii = [np.where(turned, 0.0, radius)]
        for (start, end), length in zip(self.curves, lengths):
            count = max(2, math.ceil(length / step) + 1)
            sources.append(resample(start, count))
            targets.append(resample(end, count))
            radii.append(np.zeros(count))
        if self.border != "free":
            for side, nodes, fraction in _border_nodes(grid):
                if self.border == "pinned" or side in self.border:
                    sources.append(nodes)
                    targets.append(nodes if self.border == "pinned" else along(self.border[side], fraction))
                    radii.append(np.zeros(len(nodes)))
        if np.any(turned) and radius > 0:
            ring_from, ring_to = self._rings(np.concatenate(sources), np.concatenate(targets), radius)
            sources.append(ring_from)
            targets.append(ring_to)
            radii.append(np.zeros(len(ring_from)))
        return np.concatenate(sources), np.concatenate(targets), np.concatenate(radii)

    def _rings(self, sources: np.ndarray, targets: np.ndarray, radius: float) -> tuple[np.ndarray, np.ndarray]:
        """The rings of the point handles with an angle: :data:`RING_POINTS` sources each at
        ``radius`` around the handle, and their targets turned by its angle and scaled by the
        rest size the rigid map gives the other constraints (:func:`arap.rest_scale`)."""
        from .arap import rest_scale

        scale = rest_scale(sources, targets)
        turned = np.flatnonzero(np.isfinite(self.angles))
        around = np.arange(RING_POINTS) * (2.0 * math.pi / RING_POINTS)
        ring = radius * np.stack([np.cos(around), np.sin(around)], axis=1)
        angle = self.angles[turned][:, None]
        turned_ring = scale * np.stack([np.cos(angle) * ring[:, 0] - np.sin(angle) * ring[:, 1],
                                        np.sin(angle) * ring[:, 0] + np.cos(angle) * ring[:, 1]], axis=-1)
        return ((self.points_from[turned][:, None, :] + ring).reshape(-1, 2),
                (self.points_to[turned][:, None, :] + turned_ring).reshape(-1, 2))


def default_radius(width: int, height: int, cell: float) -> float:
    """Disc radius of a point handle: 1.5 % of the image's diagonal, at least one grid cell."""
    return max(float(cell), 0.015 * math.hypot(width, height))


def resample(line: np.ndarray, count: int) -> np.ndarray:
    """``count`` points evenly spaced by arc length along the polyline ``line`` (n, 2)."""
    return along(line, np.linspace(0.0, 1.0, count))


def along(line: np.ndarray, fraction: np.ndarray) -> np.ndarray:
    """Points at arc-length ``fraction`` (0..1) of the polyline ``line``."""
    steps = np.hypot(*np.diff(line, axis=0).T)
    walked = np.concatenate([[0.0], np.cumsum(steps)])
    if walked[-1] == 0.0:
        return np.repeat(line[:1], len(fraction), axis=0)
    at = np.asarray(fraction) * walked[-1]
    return np.stack([np.interp(at, walked, line[:, axis]) for axis in range(2)], axis=1)


def _border_nodes(grid: Grid):
    """(side, its nodes' source positions, their fraction along the side) for the four sides."""
    nodes = grid.nodes().reshape(grid.ny, grid.nx, 2)
    across, down = np.linspace(0, 1, grid.nx), np.linspace(0, 1, grid.ny)
    return [("top", nodes[0], across), ("bottom", nodes[-1], across),
            ("left", nodes[:, 0], down), ("right", nodes[:, -1], down)]


def _length(line: np.ndarray) -> float:
    return float(np.sum(np.hypot(*np.diff(line, axis=0).T)))


def _finite(value) -> bool:
    """Whether the JSON number ``value`` is finite (Python's json reads NaN and Infinity)."""
    try:
        return math.isfinite(value)
    except OverflowError:                      # an integer of hundreds of digits
        return False


def _plain(point) -> list:
    return [float(point[0]), float(point[1])]


#: The keys of a point handle and of a curve (version 2's; version 1 is without ``angle``).
ITEM_KEYS = {"points": ("from", "to", "angle"), "curves": ("from", "to")}


def _unknown_keys(data: dict, version: int) -> list[str]:
    """Notes for the keys of point handles, curves and a border side's Bezier no version reads (a
    misspelt ``"angel"`` would otherwise drop a rotation silently); a version-1 ``angle`` has its own."""
    border = data.get("border") if isinstance(data.get("border"), dict) else {}
    return [f"handles: ignoring {group}[{k}].{key} (unknown to version {version})"
            for group, keys in ITEM_KEYS.items() for k, item in enumerate(data.get(group, []))
            for key in item if key not in keys] + [
        f"handles: ignoring border.{side}.{key} (unknown to version {version})"
        for side, line in border.items() if isinstance(line, dict) for key in line if key != "bezier"]


#: Largest turn of a point handle's disc, in degrees (ten turns): beyond, a turn is rounding noise
#: (1e308 degrees turned the disc by whatever 1e308 mod 360 rounds to).
MAX_ANGLE = 3600


def _angles(points: list, version: int, notes: list) -> np.ndarray:
    """Each point's ``angle`` in radians (NaN where none is given; in a version-1 file it is
    ignored, with a warning); ValueError for one that is not finite or beyond :data:`MAX_ANGLE`."""
    angles = np.full(len(points), np.nan)
    for k, point in enumerate(points):
        if "angle" not in point:
            continue
        if version < 2:
            notes.append(f"handles: ignoring points[{k}].angle (version 2 reads it; this file says version 1)")
            continue
        if not _finite(point["angle"]) or abs(point["angle"]) > MAX_ANGLE:
            from .. import schema

            raise ValueError(f"points[{k}].angle: expected a finite number of degrees within +-{MAX_ANGLE}, got "
                             f"{schema.shown(point['angle'])}")
        angles[k] = math.radians(point["angle"])
    return angles


def _points(values: list, where: str) -> np.ndarray:
    """(n, 2) float array of the schema-checked points ``values``; ValueError naming
    ``where.format(index)`` for the first point that is not two finite numbers."""
    from .. import schema

    for k, value in enumerate(values):
        if not all(_finite(v) for v in value):
            raise ValueError(f"{where.format(k)}: expected a point [x, y] of two finite numbers, "
                             f"got {schema.shown(value)}")
    return np.array(values, float).reshape(-1, 2)


def _inside(points: np.ndarray, width: int, height: int, where: str) -> None:
    """ValueError naming ``where.format(index)`` of the first of ``points`` (n, 2) outside the image."""
    outside = ~np.all((points >= -0.5) & (points <= np.array([width, height]) - 0.5), axis=1)
    if np.any(outside):
        k = int(np.argmax(outside))
        x, y = points[k]
        raise ValueError(f"{where.format(k)} ({x:g}, {y:g}) lies outside the {width}x{height} image "
                         f"(it spans -0.5..{width - 0.5:g}, -0.5..{height - 0.5:g}: pixel centres at whole numbers)")


def _near(points: np.ndarray, width: int, height: int, where: str) -> None:
    """ValueError naming ``where.format(index)`` of the first of ``points`` (n, 2) lying more
    than :data:`REACH` image sizes from the image."""
    reach = REACH * max(width, height)
    far = ~np.all((points >= -reach) & (points <= np.array([width, height]) + reach), axis=1)
    if np.any(far):
        k = int(np.argmax(far))
        x, y = points[k]
        raise ValueError(f"{where.format(k)} ({x:g}, {y:g}) lies more than {REACH} image sizes away from the image")


def _no_duplicates(sources: np.ndarray) -> None:
    """ValueError when two point handles start closer than :data:`MIN_SPACING` pixels."""
    if len(sources) < 2:
        return
    gap = np.hypot(*(sources[:, None, :] - sources[None, :, :]).transpose(2, 0, 1)) if len(sources) <= 2000 else None
    if gap is None:                            # many handles: exact duplicates only
        key = np.round(sources, 6)
        _, index, counts = np.unique(key, axis=0, return_index=True, return_counts=True)
        if not np.any(counts > 1):
            return
        point = key[index[np.argmax(counts > 1)]]
        a, b = np.flatnonzero(np.all(key == point, axis=1))[:2]
    else:
        np.fill_diagonal(gap, np.inf)
        if gap.min() >= MIN_SPACING:
            return
        a, b = sorted(np.unravel_index(np.argmin(gap), gap.shape))
    raise ValueError(f"points[{a}] and points[{b}] start {np.hypot(*(sources[a] - sources[b])):.3g} px apart "
                     f"(at least {MIN_SPACING:g} px between handles); one place can have one handle")


def _plain_point(value) -> bool:
    """Whether ``value`` is a point the schema accepts: a list of two JSON numbers."""
    return type(value) is list and len(value) == 2 and type(value[0]) in (int, float) and type(value[1]) in (int, float)


def _plain_line(value) -> bool:
    """Whether ``value`` is a polyline the schema accepts: a list of two or more plain points."""
    return type(value) is list and len(value) >= 2 and all(map(_plain_point, value))


def _cut_line(value):
    """A plain polyline cut to its first two points (what the schema needs to see of it)."""
    return value[:2] if _plain_line(value) else value


def _check_shape(data: dict) -> None:
    """Check ``data`` against the handles schema, counts first (:data:`MOST`).

    jsonschema checks about 5 000 points a second (a file of 150 000 point handles took 26 s,
    one curve of 100 000 points over a minute), so it sees every list whose items all have
    the right shape cut to its first items; this plain pass takes well under a second for
    the largest file read (16 MiB). A list with any item of another shape (an ``angle`` that
    is no number too) stays whole, and the schema names that item at its true index.
    """
    from .. import schema

    for key, most in MOST.items():
        if type(data.get(key)) is list and len(data[key]) > most:
            raise ValueError(f"{key}: {len(data[key])} {'point handles' if key == 'points' else key}; "
                             f"a handles file holds at most {most}")
    view = dict(data)
    points = data.get("points")
    if type(points) is list and all(type(p) is dict and _plain_point(p.get("from")) and _plain_point(p.get("to"))
                                    and type(p.get("angle", 0)) in (int, float) for p in points):
        view["points"] = points[:1]
    curves = data.get("curves")
    if type(curves) is list and all(type(c) is dict and _plain_line(c.get("from")) and _plain_line(c.get("to"))
                                    for c in curves):
        curves = curves[:1]
    if type(curves) is list:
        view["curves"] = [{key: _cut_line(line) if key in ("from", "to") else line for key, line in c.items()}
                          if type(c) is dict else c for c in curves]
    border = data.get("border")
    if type(border) is dict:
        view["border"] = {side: _cut_line(line) for side, line in border.items()}
    schema.check("handles", view)


def _border(value, width: int, height: int):
    """'free', 'pinned' or {side: (n, 2) polyline} with matching corners (``value`` has passed
    the schema)."""
    if isinstance(value, str):
        return value
    sides = {}
    for side, line in value.items():
        if isinstance(line, dict):
            line = _bezier(_points(line["bezier"], f"border.{side}.bezier[{{}}]"))
            _near(line, width, height, f"border.{side}.bezier")
        else:
            line = _points(line, f"border.{side}[{{}}]")
            _near(line, width, height, f"border.{side}[{{}}]")
        axis = 0 if side in ("top", "bottom") else 1        # sides run left to right, top to bottom
        if not line[-1, axis] > line[0, axis]:
            raise ValueError(f"border.{side} runs from ({line[0, 0]:g}, {line[0, 1]:g}) to ({line[-1, 0]:g}, "
                             f"{line[-1, 1]:g}); a {side} side runs {('left to right', 'top to bottom')[axis]}")
        sides[side] = line
    corners = {("top", 0): "left", ("top", -1): "right", ("bottom", 0): "left", ("bottom", -1): "right"}
    for (row, end), column in corners.items():
        if row in sides and column in sides:
            a, b = sides[row][end], sides[column][0 if row == "top" else -1]
            if np.hypot(*(a - b)) > 1.0:
                raise ValueError(f"border: {row} and {column} disagree on their shared corner "
                                 f"({a[0]:g}, {a[1]:g}) vs ({b[0]:g}, {b[1]:g})")
    return sides


def _bezier(control: np.ndarray) -> np.ndarray:
    t = np.linspace(0.0, 1.0, BEZIER_POINTS)[:, None]
    weights = [(1 - t) ** 3, 3 * t * (1 - t) ** 2, 3 * t * t * (1 - t), t ** 3]
    return sum(w * p for w, p in zip(weights, control))

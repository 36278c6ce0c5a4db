"""Cylinder: the image wrapped around a cylinder and seen from the front (the paper's Fig. 5)."""

from __future__ import annotations

import math

import numpy as np

from featurewarp_cli.plugins import Param, ParamError, Warp, centre, number_text

from .common import fit_canvas

#: The least foreshortening allowed at the image's edge, relative to its middle: cos 80
#: degrees (a side wrapped to 80 degrees from the viewer, seen from afar, is 5.8 x thinner).
#: Beyond, the plain wrap squeezes the edge into a sliver no grid follows.
MIN_SQUEEZE = math.cos(math.radians(80.0))

DISTANCE = Param("distance", float, None, "Viewer's distance from the centre in radii: a perspective view "
                 "(default: unset, an orthographic view from afar).", min=1, min_open=True, max=1000,
                 metavar="F")


def squeeze(cos_gamma, distance):
    """Foreshortening across the silhouette of a point at angle gamma from the view axis, 1 at gamma = 0.

    Orthographic (``distance`` None): cos gamma. Seen from ``distance`` radii: the
    derivative of ``sin g (d - 1) / (d - cos g)``, i.e. ``(d - 1)(d cos g - 1) / (d - cos g)^2``,
    positive exactly on the visible side of the silhouette (cos g > 1/d).
    """
    if distance is None:
        return cos_gamma
    d = distance
    return (d - 1.0) * (d * cos_gamma - 1.0) / (d - cos_gamma) ** 2


def scale(cos_gamma, distance):
    """Perspective scale of a point at depth cos gamma (radii towards the viewer), 1 at the front."""
    if distance is None:
        return np.ones_like(cos_gamma)
    return (distance - 1.0) / (distance - cos_gamma)


def largest_angle(cos_at, distance, top):
    """The largest wrap angle up to ``top`` degrees whose image keeps :data:`MIN_SQUEEZE`.

    ``cos_at(angles)`` gives the least cos gamma over the image wrapped by each angle.
    """
    angles = np.linspace(0.0, top, 20001)[1:]
    ok = squeeze(cos_at(np.radians(angles)), distance) >= MIN_SQUEEZE - 1e-12
    if not ok.any():                          # below the first step: on a log scale down to 1e-9 of it
        angles = np.geomspace(angles[0] * 1e-9, angles[0], 2001)
        ok = squeeze(cos_at(np.radians(angles)), distance) >= MIN_SQUEEZE - 1e-12
    return float(angles[ok].max()) if ok.any() else 0.0


def _at_most(limit: float) -> str:
    """``limit`` rounded down to two significant digits, one decimal at least: a bound that holds."""
    if not limit > 0:
        return "no angle here: view it from further"
    scale = 10.0 ** max(1, 1 - math.floor(math.log10(limit)))
    return f"at most {math.floor(limit * scale) / scale:g} here"


def check_view(warp, cos_at, angle, distance, top):
    """ParamError naming ``angle`` when ``angle`` wraps too close to the silhouette."""
    if squeeze(cos_at(math.radians(angle)), distance) >= MIN_SQUEEZE - 1e-12:
        return
    seen = "seen from afar" if distance is None else f"seen from `distance` {number_text(distance)}"
    limit = largest_angle(cos_at, distance, top)
    raise ParamError("angle", f"{angle:g} degrees wraps the {warp.name} too close to its silhouette {seen} "
                              f"({_at_most(limit)})", mentions=("distance",))


class Cylinder(Warp):
    """Wrap the image around a cylinder seen from the front, like a label on a can: it covers
    --angle degrees of the cylinder (up to 160), whose --axis is vertical (the width wraps)
    or horizontal (the height wraps). --distance F views it in perspective from F radii
    away (default: orthographic, from afar); a closer view refuses an angle that reaches
    too near its silhouette, naming the largest it allows. The canvas is the bounding box.

    R = w / angle (the width keeps its length on the cylinder); a column at offset x from
    the middle sits at phi = x / R from the viewer. Seen orthographically it lands at
    ``R sin phi``; from d radii away, it and its column are scaled by ``(d - 1) / (d - cos
    phi)`` about the middle (1 at the front). The map keeps columns as columns (vertical
    segments, scaled about the middle row by a positive factor) and sends x to
    ``R sin(phi) s(phi)``, whose derivative :func:`squeeze` is positive exactly while phi
    stays on the visible side of the silhouette: so it is one-to-one with a positive
    Jacobian determinant there. The declared range (at most 160 degrees) keeps the edge
    at least :data:`MIN_SQUEEZE` as wide as the middle when seen from afar; closer views
    see less of the cylinder, and an angle past their limit is a ValueError naming it.
    The canvas is the projected bounding box.
    """

    name = "cylinder"
    summary = "Wrap around a cylinder seen from the front (a label on a can, a mug); orthographic or perspective."
    boundary = "fixed"
    example = "--angle 150"
    params = (
        Param("angle", float, 120.0, "Angle of the cylinder the image covers, in degrees.",
              min=0, min_open=True, max=160, metavar="DEG"),
        DISTANCE,
        Param("axis", str, "vertical", "The cylinder's axis: vertical (wraps the width) or horizontal "
              "(wraps the height).", metavar="AXIS", choices=("vertical", "horizontal")),
    )

    def _setup(self, angle, distance, axis):
        self.turn = axis == "horizontal"
        self.distance = distance
        self.c = centre(self.width, self.height)
        self.theta = max(math.radians(angle), 1e-9)          # a finite radius
        self.r = (self.height if self.turn else self.width) / self.theta
        check_view(self, lambda a: np.cos(a / 2.0), angle, distance, 160.0)
        self._shift = 0.0
        self._shift = fit_canvas(self, self.forward)

    def forward(self, points):
        d = points - self.c
        if self.turn:
            d = d[:, ::-1]
        phi = d[:, 0] / self.r
        s = scale(np.cos(phi), self.distance)
        out = np.stack([self.r * np.sin(phi) * s, d[:, 1] * s], axis=1)
        return (out[:, ::-1] if self.turn else out) - self._shift

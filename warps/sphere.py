"""Sphere: the image laid on a sphere and seen from the front."""

from __future__ import annotations

import math

import numpy as np

from featurewarp_cli.plugins import Param, Warp, centre

from .common import fit_canvas
from .cylinder import DISTANCE, check_view, scale


class Sphere(Warp):
    """Lay the image on a sphere seen from the front (a ball, a globe), its longer side over
    --angle degrees of a great circle (up to 120). --distance F views it in perspective from
    F radii away (default: orthographic, from afar); a closer view refuses an angle that
    reaches too near its silhouette, naming the largest it allows. The canvas is the
    bounding box.

    R = max(w, h) / angle. An offset (x, y) from the middle becomes longitude x / R and
    latitude y / R, the point ``P = R (cos b sin l, sin b, cos b cos l)`` (z towards the
    viewer), seen orthographically at ``(P_x, P_y)`` or from d radii away at ``(P_x, P_y)
    (d - 1) / (d - P_z / R)``. For |l|, |b| < 90 degrees, (l, b) -> P is one-to-one (a
    latitude-longitude chart) onto a patch of the near hemisphere with Jacobian
    determinant ``R^2 cos b``, and the projection is one-to-one on the part of the sphere
    in front of its silhouette (P_z / R > 1 / d, or > 0 from afar): so is the map, with
    orthographic determinant ``R^2 cos^2 b cos l > 0``. The declared range (at most 120
    degrees) keeps every point within 60 degrees of the view axis in both, so that
    foreshortening leaves at least cos 80 degrees of the width, as for ``cylinder``;
    closer views refuse a larger angle with a ValueError naming their limit.
    The canvas is the projected bounding box.
    """

    name = "sphere"
    summary = "Wrap onto a sphere seen from the front (a ball, a globe; Spherize); orthographic or perspective."
    boundary = "fixed"
    example = "--angle 100 --distance 4"
    params = (
        Param("angle", float, 90.0, "Angle of a great circle the image's longer side covers, in degrees.",
              min=0, min_open=True, max=120, metavar="DEG"),
        DISTANCE,
    )

    def _setup(self, angle, distance):
        self.distance = distance
        self.c = centre(self.width, self.height)
        longer = max(self.width, self.height)
        self.r = longer / max(math.radians(angle), 1e-9)     # a finite radius
        fractions = np.array([self.width, self.height]) / longer

        def corner_cos(theta):
            return np.cos(theta / 2.0 * fractions[0]) * np.cos(theta / 2.0 * fractions[1])

        check_view(self, corner_cos, angle, distance, 120.0)
        self._shift = 0.0
        self._shift = fit_canvas(self, self.forward)

    def forward(self, points):
        lon, lat = ((points - self.c) / self.r).T
        depth = np.cos(lat) * np.cos(lon)
        s = scale(depth, self.distance) * self.r
        return np.stack([np.cos(lat) * np.sin(lon) * s, np.sin(lat) * s], axis=1) - self._shift

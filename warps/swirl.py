"""Swirl: rotation that is strongest at the centre and fades out at a radius."""

from __future__ import annotations

import math

import numpy as np

from featurewarp_cli.engine.fidelity import MAX_PL_ERROR, finest_cell
from featurewarp_cli.plugins import Param, ParamError, Warp, centre, resolve_pair

#: The largest angle, in degrees. Beyond one and a half turns the fold-over guard relaxes the
#: features all the way to the plain warp (they are wound past recognition), and that took
#: 18-44 s CPU at 720 degrees on photos of 0.08 to 1 MP; 540 at its tightest radius takes
#: 10-25 s at 1 MP (56 s with a ring of 36 features around the centre at 1155 x 866).
MAX_ANGLE = 540.0
#: A swirl folds the triangles of a grid of cells c px unless its radius R spans enough of
#: them: angle^2 * c / R at most this (degrees squared; measured at 1 and 4 MP without
#: features, folds from about 2 800, none below 2 400).
FOLD_RATE = 2200.0


def smallest_radius(angle: float, cell: float) -> float:
    """The smallest radius in pixels at which a grid of ``cell`` px follows a swirl of
    ``angle`` degrees: without a fold (:data:`FOLD_RATE`), and within 0.5 px (the largest
    gap between the swirl and its grid is about ``c^2 t (0.8 + 0.1 t) / R`` for t radians,
    fitted on 1 MP runs from 90 to 720 degrees)."""
    turn = math.radians(abs(angle))
    return max(angle * angle * cell / FOLD_RATE, cell * cell * turn * (0.8 + 0.1 * turn) / MAX_PL_ERROR)


def largest_angle(radius: float, cell: float) -> float:
    """The largest angle in degrees that a grid of ``cell`` px follows at a swirl radius of
    ``radius`` px (the inverse of :func:`smallest_radius`)."""
    folds = math.sqrt(FOLD_RATE * radius / cell)
    square = cell * cell
    gaps = (-0.8 * square + math.sqrt(0.64 * square * square + 0.4 * MAX_PL_ERROR * square * radius)) / (0.2 * square)
    return min(folds, math.degrees(gaps), MAX_ANGLE)


class Swirl(Warp):
    """Turn the picture about --center (default: the image's centre) by --angle degrees
    there, less and less further out, not at all from --radius on (a fraction of the shorter
    side: 0.5 reaches the nearer edges). A positive angle turns counter-clockwise on screen,
    as ImageMagick's -swirl; at most 540 either way (a large angle over a radius of few
    pixels is refused, naming the radius it needs). The canvas is the input's size.

    The radius in pixels is R = radius * min(width, height). A point at distance d < R turns by angle * (1 - d/R)^2, so the swirl joins the unmoved
    outside smoothly, and each circle about the centre maps onto itself (no fold at any
    angle). A positive angle turns the picture counter-clockwise on screen, as ImageMagick's
    ``-swirl`` does: ``convert -swirl 120`` and ``--angle 120`` both take a mark above the
    centre to its upper left. Up to one and a half turns either way; a tight swirl (a large
    angle over a small radius in pixels) that even the finest automatic grid cannot follow
    without folds is refused, naming the radius it needs. Canvas = input size.
    """

    name = "swirl"
    summary = ("Swirl, Twist (Photoshop's Twist style and Twirl filter, ImageMagick -swirl): turn the "
               "centre by an angle, fading smoothly to zero at a radius.")
    example = "--angle 120"
    params = (
        Param("angle", float, 90.0, "Rotation at the centre in degrees (positive: counter-clockwise "
              "on screen, as ImageMagick's -swirl), at most one and a half turns either way; a large "
              "angle needs a radius of enough pixels for the grid to follow it (refused otherwise, "
              "naming it).",
              min=-MAX_ANGLE, max=MAX_ANGLE, metavar="DEG"),
        Param("radius", float, 0.5, "Radius of the swirl as a fraction of min(width, height).",
              min=0.001, max=10),
        Param("center", tuple, None, "Centre of the effect: X,Y in pixels (pixel centres at whole "
              "numbers) or percentages (50%,50% is the image's centre, the default).", metavar="X,Y"),
    )

    def _setup(self, angle, radius, center):
        self.centre = (centre(self.width, self.height) if center is None else
                       np.array(resolve_pair(center, self.width, self.height, position=True)))
        self.r = radius * min(self.width, self.height)
        self.theta = np.deg2rad(angle)
        cell = finest_cell(self.width, self.height)
        need = smallest_radius(angle, cell)
        if self.r < need:
            least = math.ceil(need / min(self.width, self.height) * 1000.0) / 1000.0
            raise ParamError("angle", f"{angle:g} degrees needs a swirl radius of {need:.3g} px or more on a "
                                      f"{self.width}x{self.height} image (the finest grid folds or strays on a "
                                      f"tighter one), and `radius` {radius:g} is {self.r:.3g} px: use `radius` "
                                      f"{least:g} or more, or an angle within +-"
                                      f"{math.floor(largest_angle(self.r, cell)):g}", mentions=("radius",))

    def forward(self, points):
        d = points - self.centre
        t = np.clip(1.0 - np.hypot(d[:, 0], d[:, 1]) / self.r, 0.0, None)
        a = -self.theta * t * t                         # y down: a negative turn is counter-clockwise
        c, s = np.cos(a), np.sin(a)
        return np.stack([c * d[:, 0] - s * d[:, 1], s * d[:, 0] + c * d[:, 1]], axis=1) + self.centre

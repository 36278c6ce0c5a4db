"""Arch: every column moves up by a parabola, as the design tools' Arch style."""

from __future__ import annotations

import numpy as np

from .common import Style


class Arch(Style):
    """Raise the columns along a parabola, top and bottom alike: --bend 50 lifts the middle
    column by an eighth of the image's width, 100 by a quarter; a negative bend lowers it (a
    smile). --hdistort and --vdistort (percent) add a keystone. The canvas is the bounding box.

    Each column is shifted up by ``b w/4 (1 - u^2)``, u = x / (w/2) in -1..1 across the image.

    Columns stay vertical and keep their length: the map is a shear ``(x, y) -> (x, y -
    g(x))`` with Jacobian determinant 1, one-to-one for every bend (each column slides
    along itself). Its slope ``|g'|`` is at most ``|b|`` (1 at a bend of 100 %). Positive
    bend raises the middle (a rainbow), negative lowers it (a smile).
    """

    name = "arch"
    summary = "Arch (Photoshop, Illustrator): columns rise along a parabola, top and bottom alike."
    params = Style.params
    example = "--bend 30"

    def _shape(self, d):
        u = d[:, 0] / self.half[0]
        lift = self.b * self.half[0] / 2.0 * (1.0 - u * u)
        return np.stack([d[:, 0], d[:, 1] - lift], axis=1)

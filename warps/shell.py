"""Shell Lower and Shell Upper: one side bows out and narrows, as the design tools' Shell styles."""

from __future__ import annotations

import numpy as np

from featurewarp_cli.plugins import Param

from .common import Style, bounds


class Shell(Style):
    """Bow one side out and narrow it, the other side straight: --side lower (the bottom,
    Shell Lower) or upper (the top, Shell Upper). At --bend 50 the side bows out by an eighth
    of the image's width (at most 0.45 of its height) and narrows by up to a quarter; a
    negative bend pulls it in and widens it. --hdistort and --vdistort (percent) add a
    keystone. The canvas is the bounding box.

    Described for ``lower`` (``upper`` is its mirror image top to bottom, which keeps every
    property). Two steps, each one-to-one:

    1. Bow: with t = (y + h/2) / h in 0..1 from the top row to the bottom row and u = x /
       (w/2), ``y -> y + t A (1 - u^2)``, ``A = b min(w/4, 0.9 h)``. Columns stay in place,
       each scaled by ``1 + A (1 - u^2) / h >= 0.1`` (Jacobian determinant).
    2. Fan: ``x -> x (1 - f s)``, s in 0..1 from the top of the bowed image to its
       lowest point, ``f = (b/2) min(1, D / (w/2))`` with D that depth: rows stay in place,
       each scaled by at least ``1 - |b|/2 >= 0.5``, and the shear ``|x f / D| <= |b|/2``
       stays bounded however wide and thin the image.

    Positive bend bows the side out and narrows it, like the inside of a shell; negative
    bend pulls it in and widens it.
    """

    name = "shell"
    summary = ("Shell Lower (--side lower) and Shell Upper (--side upper) of Photoshop and Illustrator: one "
               "side bows out and narrows.")
    example = "--side upper --bend 40"
    params = Style.params + (
        Param("side", str, "lower", "The side that bows: lower (Shell Lower) or upper (Shell Upper).",
              metavar="SIDE", choices=("lower", "upper")),
    )

    def _shape_setup(self, side):
        self.flip = 1.0 if side == "lower" else -1.0
        self.bow = self.b * min(self.width / 4.0, 0.9 * self.height)
        lo, hi = bounds(self.width, self.height, lambda p: self._bow((p - self.c) * [1.0, self.flip]))
        self.top, self.depth = float(lo[1]), float(hi[1] - lo[1]) or 1.0
        self.fan = 0.5 * self.b * min(1.0, self.depth / self.half[0])

    def _bow(self, d):
        u = d[:, 0] / self.half[0]
        t = (d[:, 1] + self.half[1]) / self.height
        return np.stack([d[:, 0], d[:, 1] + t * self.bow * (1.0 - u * u)], axis=1)

    def _shape(self, d):
        bowed = self._bow(d * [1.0, self.flip])
        s = (bowed[:, 1] - self.top) / self.depth
        return np.stack([bowed[:, 0] * (1.0 - self.fan * s), bowed[:, 1] * self.flip], axis=1)

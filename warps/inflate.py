"""Inflate: the image swells like a cushion, as the design tools' Inflate style."""

from __future__ import annotations

import numpy as np

from .common import Style


class Inflate(Style):
    """Swell the image like a cushion: at --bend 50 each side bulges out at its middle by 11 %
    of the image's shorter side (22 % at 100); a negative bend pinches the sides in.
    --hdistort and --vdistort (percent) add a keystone. The canvas is the bounding box.

    Offsets (x, y) from the centre -> ``(x (1 + s (1 - v^2)), y (1 + t (1 - u^2)))``.

    u = x / (w/2), v = y / (h/2), both in -1..1: rows grow most in the middle row, columns
    in the middle column. Inflate has ``s = 0.45 b m / w``, ``t = 0.45 b m / h``, m = min(w,
    h): each side bulges out by ``0.45 b m / 2`` pixels at its middle, and the shear terms
    ``2 s u v (w / h)`` and ``2 t u v (h / w)`` stay under 1 however long and thin the
    image (a long strip is not bent across its thickness). With p = u^2, q = v^2 in [0, 1],
    the Jacobian determinant is ``(1 + s (1 - q)) (1 + t (1 - p)) - 4 s t p q``, bilinear
    in (p, q), so its least value is at a corner of [0, 1]^2: ``(1 + s)(1 + t)``,
    ``1 + s``, ``1 + t`` and ``1 - 4 s t``: all positive when ``|s|, |t| < 1/2``, and
    here ``|s|, |t| <= 0.45``. Each side maps onto a curve that is a graph over
    its own axis, the border onto a simple closed curve, so with a positive determinant
    the map is one-to-one (tests/test_styles.py checks the winding number).
    """

    name = "inflate"
    summary = "Inflate (Photoshop, Illustrator): swell like a cushion; Pinch (--bend -40): a negative bend."
    params = Style.params
    example = "--bend 40"
    #: (s, t) per unit bend, on a square image
    gains = (0.45, 0.45)

    def _shape(self, d):
        u, v = d[:, 0] / self.half[0], d[:, 1] / self.half[1]
        shorter = min(self.width, self.height)
        s, t = self.b * self.gains[0] * shorter / self.width, self.b * self.gains[1] * shorter / self.height
        return np.stack([d[:, 0] * (1.0 + s * (1.0 - v * v)), d[:, 1] * (1.0 + t * (1.0 - u * u))], axis=1)

"""Squeeze: the middle is pressed flat and pushed out sideways, as the design tools' Squeeze style."""

from __future__ import annotations

from .inflate import Inflate


class Squeeze(Inflate):
    """Press the middle flat and out sideways: at --bend 50 the top and bottom edges dip in
    at their middle, and the left and right sides bulge out, by 19 % of the image's shorter
    side (37.5 % at 100); a negative bend does the reverse (Photoshop's Bulge style).
    --hdistort and --vdistort (percent) add a keystone. The canvas is the bounding box.

    Inflate's map with ``s = 0.75 b m / w``, ``t = -0.75 b m / h`` (m = min(w, h)): the
    middle column loses height, the middle row gains width.

    s and t have opposite signs, so the corner values of Inflate's bilinear determinant,
    ``(1 + s)(1 + t)``, ``1 + s``, ``1 + t`` and ``1 - 4 s t >= 1``, are positive when
    ``|s|, |t| < 1``; here ``|s|, |t| <= 0.75``.
    """

    name = "squeeze"
    summary = "Squeeze (Photoshop, Illustrator): press the middle flat, out sideways (negative: Bulge)."
    gains = (0.75, -0.75)
    example = "--bend 30"

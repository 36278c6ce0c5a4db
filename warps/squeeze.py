"""Squeeze: the middle is pressed flat and pushed out sideways, as the design tools' Squeeze style."""

from __future__ import annotations

from .inflate import Inflate


class Squeeze(Inflate):
    """Inflate's map with ``s = 0.75 b``, ``t = -0.75 b``: the middle column loses height,
    the middle row gains width (negative bend: the middle bulges up and down and narrows,
    like Photoshop's Bulge style).

    The corner values of Inflate's bilinear determinant become ``1 - s^2``, ``1 + s``,
    ``1 - s`` and ``1 + 4 s^2``: positive exactly when ``|s| < 1``; ``|0.75 b| <= 0.75``.
    """

    name = "squeeze"
    summary = "Squeeze (Photoshop, Illustrator): press the middle flat, out sideways (negative: Bulge)."
    gains = (0.75, -0.75)

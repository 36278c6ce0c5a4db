"""Squeeze: the middle is pressed flat and pushed out sideways, as the design tools' Squeeze style."""

from __future__ import annotations

from .inflate import Inflate


class Squeeze(Inflate):
    """Inflate's map with ``s = 0.75 b m / w``, ``t = -0.75 b m / h`` (m = min(w, h)): the
    middle column loses height, the middle row gains width (negative bend: the middle
    bulges up and down and narrows, like Photoshop's Bulge style).

    s and t have opposite signs, so the corner values of Inflate's bilinear determinant,
    ``(1 + s)(1 + t)``, ``1 + s``, ``1 + t`` and ``1 - 4 s t >= 1``, are positive when
    ``|s|, |t| < 1``; here ``|s|, |t| <= 0.75``.
    """

    name = "squeeze"
    summary = "Squeeze (Photoshop, Illustrator): press the middle flat, out sideways (negative: Bulge)."
    gains = (0.75, -0.75)

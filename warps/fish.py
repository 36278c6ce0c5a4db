"""Fish: the left half swells and the right half narrows, as the design tools' Fish style."""

from __future__ import annotations

import math

import numpy as np

from .common import Style


class Fish(Style):
    """Scale each column's height about the middle row by ``1 - (b/2) sin(pi u)``, u = x / (w/2).

    The left half (u < 0) swells into the body, the right half narrows into the tail, the
    ends and the middle keep their height. Columns stay vertical and each is scaled by a
    factor of at least ``1 - |b|/2 >= 0.5``: one-to-one, with Jacobian determinant equal to
    that factor.
    """

    name = "fish"
    summary = "Fish (Photoshop, Illustrator): a swelling body on the left, a narrowing tail on the right."
    params = Style.params

    def _shape(self, d):
        u = d[:, 0] / self.half[0]
        return np.stack([d[:, 0], d[:, 1] * (1.0 - 0.5 * self.b * np.sin(math.pi * u))], axis=1)

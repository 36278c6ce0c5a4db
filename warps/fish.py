"""Fish: the left half swells and the right half narrows, as the design tools' Fish style."""

from __future__ import annotations

import math

import numpy as np

from .common import Style


class Fish(Style):
    """Swell the left half into a body and narrow the right half into a tail: at --bend 50
    the body is up to 1.25x as tall and the tail 0.75x (on a landscape image; a portrait
    one swells less); a negative bend swaps them. --hdistort and --vdistort (percent) add a
    keystone. The canvas is the bounding box.

    Each column's height is scaled about the middle row by ``1 - g sin(pi u)``, u = x / (w/2).

    ``g = (b/2) min(1, w / h)``. The left half (u < 0) swells into the body, the right half
    narrows into the tail, the ends and the middle keep their height. Columns stay
    vertical and each is scaled by a factor of at least ``1 - |b|/2 >= 0.5``: one-to-one,
    with Jacobian determinant equal to that factor. The shear ``y g pi cos(pi u) / (w/2)``
    stays under ``pi |b| / 2`` however tall and narrow the image: a portrait image swells
    less than a landscape one.
    """

    name = "fish"
    summary = "Fish (Photoshop, Illustrator): a swelling body on the left, a narrowing tail on the right."
    params = Style.params
    example = "--bend 30"

    def _shape(self, d):
        u = d[:, 0] / self.half[0]
        gain = 0.5 * self.b * min(1.0, self.width / self.height)
        return np.stack([d[:, 0], d[:, 1] * (1.0 - gain * np.sin(math.pi * u))], axis=1)

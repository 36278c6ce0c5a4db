"""Rise: the image climbs from left to right along a sine, as the design tools' Rise style."""

from __future__ import annotations

import math

import numpy as np

from .common import Style


class Rise(Style):
    """Make the image climb from left to right along a sine: the middle column stays, the
    right end rises and the left end falls, each by 0.16 of the image's width at --bend 50
    (0.32 at 100); a negative bend descends. --hdistort and --vdistort (percent) add a
    keystone. The canvas is the bounding box.

    Each column is shifted up by ``b w / pi sin(pi u / 2)``, u = x / (w/2) in -1..1.

    The middle column stays, the right end rises and the left end falls (positive bend).
    A shear ``(x, y) -> (x, y - g(x))``: Jacobian determinant 1, one-to-one for every bend;
    the slope ``|g'|`` is at most ``|b|``, steepest in the middle.
    """

    name = "rise"
    summary = "Rise (Photoshop, Illustrator): the image climbs from left to right along a sine."
    params = Style.params
    example = "--bend 30"

    def _shape(self, d):
        u = d[:, 0] / self.half[0]
        return np.stack([d[:, 0], d[:, 1] - self.b * self.width / math.pi * np.sin(0.5 * math.pi * u)], axis=1)

"""Flag and Wave: every column moves up and down along a sine, as the design tools' styles."""

from __future__ import annotations

import math

import numpy as np

from featurewarp_cli.plugins import Param

from .common import Style


class Flag(Style):
    """Make the columns ride --waves full sine periods up and down (1: Flag; 2 or more: Wave),
    the ends level; --bend sets the height in percent (at 100 the steepest slope is 45
    degrees, whatever the number of waves). --hdistort and --vdistort (percent) add a
    keystone. The canvas is the bounding box.

    Each column is shifted by ``b w / (2 pi n) sin(pi n (1 + u))``, u = x / (w/2) in -1..1.

    n = --waves full periods across the image; the ends stay level. A shear ``(x, y) ->
    (x, y + g(x))``: Jacobian determinant 1, one-to-one for every bend and every n. The
    slope ``|g'|`` is at most ``|b|`` whatever n, so more waves are lower ones.
    """

    name = "flag"
    summary = "Flag (--waves 1) and Wave (--waves 2 or more) of Photoshop and Illustrator: columns ride a sine."
    example = "--bend 30 --waves 2"
    params = Style.params + (
        Param("waves", int, 1, "Full sine periods across the image (1: Flag; 2 or more: Wave).",
              min=1, max=12, metavar="N"),
    )

    def _shape_setup(self, waves):
        self.n = waves

    def _shape(self, d):
        u = d[:, 0] / self.half[0]
        amplitude = self.b * self.width / (2.0 * math.pi * self.n)
        return np.stack([d[:, 0], d[:, 1] + amplitude * np.sin(math.pi * self.n * (1.0 + u))], axis=1)

"""Non-uniform scale: the aspect-ratio change of a banner or a photo."""

from __future__ import annotations

import math

import numpy as np

from featurewarp_cli.plugins import Param, Warp


class Stretch(Warp):
    """Scale x by sx and y by sy; the canvas is round(w*sx) x round(h*sy).

    --width / --height name the target size in pixels instead of a factor.
    """

    name = "stretch"
    summary = "Non-uniform scale to a new size or aspect ratio."

    params = (
        Param("sx", float, 1.0, "Horizontal scale factor, or a percentage (150%).", min=0, min_open=True, max=100,
              percent=True),
        Param("sy", float, 1.0, "Vertical scale factor, or a percentage (150%).", min=0, min_open=True, max=100,
              percent=True),
        Param("width", int, None, "Target width in pixels (overrides --sx).", min=1, max=65535, metavar="PX"),
        Param("height", int, None, "Target height in pixels (overrides --sy).", min=1, max=65535, metavar="PX"),
    )

    def _setup(self, sx, sy, width, height):
        # Half-up rounding (Python's round() goes to even: 160.5 -> 160).
        out_w = width if width is not None else max(1, math.floor(self.width * sx + 0.5))
        out_h = height if height is not None else max(1, math.floor(self.height * sy + 0.5))
        self.canvas = (int(out_w), int(out_h))
        # Scale the pixel-edge extent exactly onto the canvas edge extent.
        self.scale = np.array([out_w / self.width, out_h / self.height])

    def forward(self, points):
        return (points + 0.5) * self.scale - 0.5

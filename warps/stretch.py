"""Non-uniform scale: the aspect-ratio change of a banner or a photo."""

from __future__ import annotations

import math

import numpy as np

from featurewarp_cli.plugins import Param, ParamError, Warp, number_text, resolve_pair


class Stretch(Warp):
    """Scale the image to a new size or aspect ratio: --sx and --sy are factors (2, or 200%:
    twice as wide), --width and --height the target size in pixels, --size WxH both at once
    (pixels or percentages: 1920x1080, 150%x100%). The canvas is round(w*sx) x round(h*sy).

    x is scaled by sx and y by sy, the pixel-edge extent exactly onto the canvas's.
    """

    name = "stretch"
    summary = "Non-uniform scale to a new size or aspect ratio."
    example = "--sx 1.5"

    params = (
        Param("sx", float, 1.0, "Horizontal scale factor, or a percentage (150%).", min=0, min_open=True, max=100,
              percent=True),
        Param("sy", float, 1.0, "Vertical scale factor, or a percentage (150%).", min=0, min_open=True, max=100,
              percent=True),
        Param("width", int, None, "Target width in pixels (overrides --sx).", min=1, max=65535, metavar="PX",
              overrides=("sx",)),
        Param("height", int, None, "Target height in pixels (overrides --sy).", min=1, max=65535, metavar="PX",
              overrides=("sy",)),
        Param("size", tuple, None, "Target size WxH in pixels or percentages (800x600, 150%x100%); "
              "overrides the others.", metavar="WxH", overrides=("sx", "sy", "width", "height")),
    )

    def _setup(self, sx, sy, width, height, size):
        if size is not None:
            size_w, size_h = resolve_pair(size, self.width, self.height)
            for value, name in ((size_w, "width"), (size_h, "height")):
                if not 1 <= math.floor(value + 0.5) <= 65535:
                    raise ParamError("size", f"the {name} {number_text(value)} is out of range (1 <= PX <= 65535)")
            width, height = math.floor(size_w + 0.5), math.floor(size_h + 0.5)
        # Half-up rounding (Python's round() goes to even: 160.5 -> 160).
        out_w = width if width is not None else max(1, math.floor(self.width * sx + 0.5))
        out_h = height if height is not None else max(1, math.floor(self.height * sy + 0.5))
        self.notes = [f"--{name} {number_text(factor)} makes the {side} {size * factor:.3g} px: it is 1 px"
                      for name, factor, side, size, given in (("sx", sx, "width", self.width, width),
                                                               ("sy", sy, "height", self.height, height))
                      if given is None and size * factor < 0.5]
        self.canvas = (int(out_w), int(out_h))
        # Scale the pixel-edge extent exactly onto the canvas edge extent.
        self.scale = np.array([out_w / self.width, out_h / self.height])

    def review(self, mesh, quick: bool = False) -> list[str]:
        """The canvas sides a factor far below 1 px left at 1 px (the report keeps the factor asked for)."""
        return list(self.notes)

    def forward(self, points):
        return (points + 0.5) * self.scale - 0.5

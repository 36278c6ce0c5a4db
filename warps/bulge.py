"""Bulge: magnify (or pinch) the centre, joining the outside smoothly."""

from __future__ import annotations

import numpy as np

from featurewarp_cli.plugins import Param, Warp, centre, resolve_pair


class Bulge(Warp):
    """Magnify the centre (--strength S above 0: 0.5 shows it 1.5x as large) or pinch it
    (S below 0), fading smoothly to no change at --radius (a fraction of the shorter side)
    around --center (default: the image's centre). The canvas is the input's size.

    A radial map d -> R * g(d / R) inside radius R, identity outside.

    g(t) = t * (1 + S (1 - t)**2): g(0) = 0, g(1) = 1, g'(1) = 1 (smooth at R) and
    g'(0) = 1 + S (the magnification at the centre). g' > 0 on [0, 1], so the map
    is injective, exactly when -1 < S < 3; the declared range stays inside that.
    """

    name = "bulge"
    summary = ("Fisheye (Photoshop's Fisheye style), Bulge and Pinch (--strength -0.5: Photoshop's Pinch "
               "filter): magnify (--strength > 0) or pinch (--strength < 0) the centre, smooth at the radius.")
    example = "--strength 0.8"
    params = (
        Param("strength", float, 0.5,
              "Centre magnification minus 1 (0.5: 1.5x). Injective only for -1 < S < 3, hence the range.",
              min=-0.95, max=2.95, metavar="S"),
        Param("radius", float, 0.5, "Radius of the effect as a fraction of min(width, height).",
              min=0.001, max=10),
        Param("center", tuple, None, "Centre of the effect: X,Y in pixels (pixel centres at whole "
              "numbers) or percentages (50%,50% is the image's centre, the default).", metavar="X,Y"),
    )

    def _setup(self, strength, radius, center):
        self.centre = (centre(self.width, self.height) if center is None else
                       np.array(resolve_pair(center, self.width, self.height, position=True)))
        self.r = radius * min(self.width, self.height)
        self.s = strength

    def forward(self, points):
        d = points - self.centre
        t = np.hypot(d[:, 0], d[:, 1]) / self.r
        inside = np.clip(1.0 - t, 0.0, None)
        gain = 1.0 + self.s * inside * inside      # g(t) / t, = 1 outside R
        return d * gain[:, None] + self.centre

"""Swirl: rotation that is strongest at the centre and fades out at a radius."""

from __future__ import annotations

import numpy as np

from featurewarp_cli.plugins import Param, Warp, centre, resolve_pair


class Swirl(Warp):
    """Rotate each point about the centre by angle * (1 - d/R)^2 for d < R.

    A positive angle turns counter-clockwise on screen (x right, y down), as ImageMagick's
    ``-swirl`` does: its inverse map samples the source at the output position turned by
    +angle (clockwise on screen), so the picture turns the other way; ``convert -swirl 120``
    takes a mark above the centre to its upper left, and so does ``--angle 120`` here (before
    issue 25 the sign was the opposite). R = radius * min(w, h). The rotation and its derivative fall to zero at R,
    so the swirl joins the unmoved outside smoothly. Each circle about the centre
    maps onto itself, so the map is injective for every angle; the declared range
    (two turns either way) is where the automatic grid follows it within its node
    limit and the result has no fold (320x240 with features at 720: 13 s, 0.7 GB).
    Canvas = input size.
    """

    name = "swirl"
    summary = ("Swirl, Twist (Photoshop's Twist style and Twirl filter, ImageMagick -swirl): turn the "
               "centre by an angle, fading smoothly to zero at a radius.")
    params = (
        Param("angle", float, 90.0, "Rotation at the centre in degrees (positive: counter-clockwise "
              "on screen, as ImageMagick's -swirl), at most two turns either way: beyond, the grid that follows the swirl "
              "outgrows its node limit and features can no longer be kept apart.",
              min=-720, max=720, metavar="DEG"),
        Param("radius", float, 0.5, "Radius of the swirl as a fraction of min(width, height).",
              min=0.001, max=10),
        Param("center", tuple, None, "Centre of the effect: X,Y in pixels (pixel centres at whole "
              "numbers) or percentages (50%,50% is the image's centre, the default).", metavar="X,Y"),
    )

    def _setup(self, angle, radius, center):
        self.centre = (centre(self.width, self.height) if center is None else
                       np.array(resolve_pair(center, self.width, self.height, position=True)))
        self.r = radius * min(self.width, self.height)
        self.theta = np.deg2rad(angle)

    def forward(self, points):
        d = points - self.centre
        t = np.clip(1.0 - np.hypot(d[:, 0], d[:, 1]) / self.r, 0.0, None)
        a = -self.theta * t * t                         # y down: a negative turn is counter-clockwise
        c, s = np.cos(a), np.sin(a)
        return np.stack([c * d[:, 0] - s * d[:, 1], s * d[:, 0] + c * d[:, 1]], axis=1) + self.centre

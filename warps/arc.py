"""Arc: bend the image into a ring sector, as ImageMagick's ``-distort Arc``."""

from __future__ import annotations

import math

import numpy as np

from featurewarp_cli.plugins import Param, Warp


class Arc(Warp):
    """Bend the image into a ring sector spanning --angle degrees.

    Columns become rays, rows become arcs; the top edge lies on the outer arc
    and the sector is symmetric about the vertical. The middle row keeps its
    length (radius w / angle) while that leaves an inner radius of at least
    h / 10; beyond that the inner radius stays h / 10. Rows keep their spacing,
    so the ring is h thick. The map is injective for every angle in range; the
    canvas is the sector's bounding box.
    """

    name = "arc"
    summary = "Bend into a ring sector spanning an angle (top edge outside)."
    params = (
        Param("angle", float, 90.0, "Angle the sector spans, in degrees.",
              min=0, min_open=True, max=360, metavar="DEG"),
    )

    def _setup(self, angle):
        w, h = self.width, self.height
        # Below 1e-9 rad the sector is a straight image to within 1e-6 px; the floor
        # keeps the radius finite.
        self.theta = max(math.radians(angle), 1e-9)
        r_inner = max(w / self.theta - h / 2.0, h / 10.0)
        self.r_outer = r_inner + h
        # Bounding box of the sector: the arc ends plus the axis directions inside the span.
        half = self.theta / 2.0
        phis = [-half, half] + [a for a in (0.0, math.pi / 2, -math.pi / 2, math.pi, -math.pi) if abs(a) <= half]
        corners = self._place(np.repeat(np.array(phis), 2), np.tile([r_inner, self.r_outer], len(phis)))
        lo = corners.min(axis=0)
        size = np.ceil(corners.max(axis=0) - lo - 1e-6).astype(int)
        self.canvas = (max(1, int(size[0])), max(1, int(size[1])))
        self.offset = (float(lo[0]), float(lo[1]))
        self._shift = lo + 0.5

    def _place(self, phi, r):
        """Position of polar (phi, r) relative to the top of the outer arc (y down).

        Written with the sagitta 2 r sin^2(phi/2) so that huge radii at tiny
        angles lose no precision.
        """
        return np.stack([r * np.sin(phi), (self.r_outer - r) + 2.0 * r * np.sin(phi / 2.0) ** 2], axis=1)

    def forward(self, points):
        phi = ((points[:, 0] + 0.5) / self.width - 0.5) * self.theta
        r = self.r_outer - (points[:, 1] + 0.5)
        return self._place(phi, r) - self._shift

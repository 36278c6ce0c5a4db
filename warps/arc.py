"""Arc: bend the image into a ring sector, as ImageMagick's ``-distort Arc`` (the design tools'
Arc), or bow only its bottom or top edge (their Arc Lower and Arc Upper)."""

from __future__ import annotations

import math

import numpy as np

from featurewarp_cli.plugins import Param, ParamError, Warp, canvas_size, number_text

from .common import fit_canvas

#: Largest angle of --where lower or upper: at 180 degrees the bowed edge turns vertical, and
#: from 160 the fold-over guard's work grows fast (at 1 MP with features, 170 took 34 to 60 s
#: CPU and 2.3 GB, 160 up to 28 s; 150 takes at most 11 s).
EDGE_MAX = 150.0


class Arc(Warp):
    """Bend the image into a ring sector spanning --angle degrees (up to 360: a full ring),
    its top edge outside, as ImageMagick's -distort Arc with its default radii (the middle
    row keeps its length), except where those leave an inner radius under a tenth of the
    height (width / angle in radians < 0.6 x height: a tall image or a wide angle, such as
    600x600 at 120 degrees, whose bottom rows ImageMagick folds across the centre): the
    ring is then moved out to that radius, a larger canvas (1144x630 there, ImageMagick's
    1016x595). The canvas is the sector's bounding box (ImageMagick's is a pixel or two
    larger). --where lower (upper) keeps the columns vertical and bows only the bottom (top)
    edge into a circular arc of --angle degrees, at most 150: the design tools' Arc Lower
    (Arc Upper).

    Columns become rays, rows become arcs; the top edge lies on the outer arc
    and the sector is symmetric about the vertical. The middle row keeps its
    length (radius w / angle) while that leaves an inner radius of at least
    h / 10; beyond that the inner radius stays h / 10. Rows keep their spacing,
    so the ring is h thick. The map is injective for every angle in range; the
    canvas is the sector's bounding box.

    ``--where lower`` (``upper``) keeps the columns vertical and the top (bottom) edge
    straight and bows the other edge into a circular arc of --angle degrees through its
    ends, sagging ``S(x)`` at column x; each row in between follows a share of that
    sag in proportion to its distance from the straight edge. Each column is then scaled
    by ``1 + S(x) / h >= 1``: one-to-one, Jacobian determinant ``1 + S(x) / h``. The arc
    is the graph of a function of x up to 180 degrees; --angle is refused beyond
    :data:`EDGE_MAX` there.
    """

    name = "arc"
    summary = ("Arc (ImageMagick, Photoshop): a ring sector; Arc Lower (--where lower) and Arc Upper "
               "(--where upper): one edge bows.")
    example = "--angle 120"
    params = (
        Param("angle", float, 90.0, "Angle the sector spans, in degrees (--where lower or upper: the "
              f"bowed edge's arc, at most {EDGE_MAX:g}).", min=0, min_open=True, max=360, metavar="DEG"),
        Param("where", str, "both", "both: the whole image bends into a ring sector; lower (Arc Lower) or "
              "upper (Arc Upper): only that edge bows out.", metavar="WHERE", choices=("both", "lower", "upper")),
    )

    def _setup(self, angle, where):
        self.where = where
        if where != "both":
            self._setup_edge(angle)
            return
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
        self.canvas = canvas_size(corners.max(axis=0) - lo)
        self.offset = (float(lo[0]), float(lo[1]))
        self._shift = lo + 0.5

    def _setup_edge(self, angle):
        if angle > EDGE_MAX:
            raise ParamError("angle", f"{number_text(angle)} is out of range when `where` is {self.where} "
                                      f"(at most {EDGE_MAX:g})", mentions=("where",))
        half = max(math.radians(angle), 1e-9) / 2.0
        self.radius = self.width / (2.0 * math.sin(half))      # the circle through the edge's ends
        self.chord_depth = self.radius * math.cos(half)         # from its centre to the chord
        self._shift = 0.0
        self._shift = fit_canvas(self, self._bow)

    def _bow(self, points):
        """Arc Lower / Upper: each column sags by its share of the bowed edge's sag."""
        x = points[:, 0] - (self.width - 1) / 2.0
        sag = np.sqrt(np.maximum(self.radius ** 2 - x * x, 0.0)) - self.chord_depth
        share = (points[:, 1] + 0.5) / self.height
        if self.where == "lower":
            return np.stack([points[:, 0], points[:, 1] + share * sag], axis=1) - self._shift
        return np.stack([points[:, 0], points[:, 1] - (1.0 - share) * sag], axis=1) - self._shift

    def _place(self, phi, r):
        """Position of polar (phi, r) relative to the top of the outer arc (y down).

        Written with the sagitta 2 r sin^2(phi/2) so that huge radii at tiny
        angles lose no precision.
        """
        return np.stack([r * np.sin(phi), (self.r_outer - r) + 2.0 * r * np.sin(phi / 2.0) ** 2], axis=1)

    def forward(self, points):
        if self.where != "both":
            return self._bow(points)
        phi = ((points[:, 0] + 0.5) / self.width - 0.5) * self.theta
        r = self.r_outer - (points[:, 1] + 0.5)
        return self._place(phi, r) - self._shift

"""What several presets share: the dense source border, the bounding-box canvas, and the
Photoshop-style warps' Bend and Distortion sliders (:class:`Style`).

Not a preset itself (nothing registers it): the design tools' styles (``arch``, ``flag``,
``fish``, ``rise``, ``inflate``, ``squeeze``, ``shell``) subclass :class:`Style`.
"""

from __future__ import annotations

import math

import numpy as np

from featurewarp_cli.plugins import Param, Warp, canvas_size, centre, check_canvas_side

__all__ = ["BEND", "HDISTORT", "VDISTORT", "Style", "border", "bounds", "fit_canvas"]

BEND = Param("bend", float, 50.0, "Bend in percent, as the design tools' slider (negative: the other way).",
             min=-100, max=100, metavar="PCT")
HDISTORT = Param("hdistort", float, 0.0, "Horizontal distortion in percent: the right side grows taller "
                 "(negative: the left), a linear keystone close to perspective.", min=-90, max=90, metavar="PCT")
VDISTORT = Param("vdistort", float, 0.0, "Vertical distortion in percent: the bottom grows wider "
                 "(negative: the top), a linear keystone close to perspective.", min=-90, max=90, metavar="PCT")


def border(width: int, height: int, step: float = 0.25) -> np.ndarray:
    """The source pixel extent's border, sampled every ``step`` pixels or finer.

    Returns
    -------
    (N, 2) ndarray
        Points on the four sides of ``[-0.5, width - 0.5] x [-0.5, height - 0.5]``, corners included.
    """
    xs = np.linspace(-0.5, width - 0.5, int(math.ceil(width / step)) + 1)
    ys = np.linspace(-0.5, height - 0.5, int(math.ceil(height / step)) + 1)
    top, bottom = np.full_like(xs, -0.5), np.full_like(xs, height - 0.5)
    left, right = np.full_like(ys, -0.5), np.full_like(ys, width - 0.5)
    return np.concatenate([np.stack([xs, top], 1), np.stack([xs, bottom], 1),
                           np.stack([left, ys], 1), np.stack([right, ys], 1)])


def bounds(width: int, height: int, place) -> tuple[np.ndarray, np.ndarray]:
    """The bounding box ``(lo, hi)`` of the image of the source extent under ``place``.

    ``place`` maps ``(N, 2)`` source points one-to-one, so the image is bounded by the image
    of the border: sampled every 0.25 px (:func:`border`), then every 0.005 px around each
    extreme sample, which leaves the box short by far less than 1e-6 px for a smooth map.
    """
    step = 0.25
    edge = border(width, height, step)
    placed = place(edge)
    extremes = edge[np.r_[placed.argmin(axis=0), placed.argmax(axis=0)]]
    t = np.linspace(-step, step, 101)[:, None]
    near = np.concatenate([extremes[:, None] + t * axis for axis in ([1.0, 0.0], [0.0, 1.0])], axis=1)
    placed = np.concatenate([placed, place(np.clip(near.reshape(-1, 2), -0.5, [width - 0.5, height - 0.5]))])
    return placed.min(axis=0), placed.max(axis=0)


def fit_canvas(warp: Warp, place) -> np.ndarray:
    """Set ``warp.canvas`` and ``warp.offset`` to the bounding box of the image under ``place``
    (:func:`bounds`). Returns the shift to subtract from a placed point so that the box's
    top-left lands on the canvas extent's corner (-0.5, -0.5).
    """
    lo, hi = bounds(warp.width, warp.height, place)
    size = canvas_size(hi - lo)
    check_canvas_side(size, warp.name)
    warp.canvas = size
    warp.offset = (float(lo[0]), float(lo[1]))
    return lo + 0.5


class Style(Warp):
    """A design tool's warp style: a shape (``_shape``), then two keystones.

    Subclasses implement ``_shape(d)``, a one-to-one map of offsets ``d`` from the image's
    centre (``(N, 2)``, pixels) to offsets, using ``self.b`` (the bend, -1..1) and
    ``self.half`` (half the width and height). The horizontal distortion H then scales
    each offset's y by ``1 + H x / X`` and the vertical distortion V each offset's x by
    ``1 + V y / Y``, where X and Y are the largest ``|x|`` and ``|y|`` over the image so
    far. With ``|H|, |V| <= 0.9`` each factor is at least 0.1: each keystone keeps
    every column (row) in place and scales it by a positive factor, so it is one-to-one
    with Jacobian determinant ``1 + H x / X > 0``; the composition of one-to-one maps is
    one-to-one. The canvas is the bounding box of the image (:func:`fit_canvas`).
    """

    boundary = "fixed"          # most styles curve the border
    params = (BEND, HDISTORT, VDISTORT)

    def _setup(self, bend, hdistort, vdistort, **extra):
        self.c = centre(self.width, self.height)
        self.half = np.array([self.width / 2.0, self.height / 2.0])
        self.b = bend / 100.0
        self._shape_setup(**extra)
        self.h, self.v = hdistort / 100.0, vdistort / 100.0
        size = (self.width, self.height)
        self.extent_x = self.extent_y = 1.0
        shaped = bounds(*size, lambda p: self._shape(p - self.c))
        self.extent_x = max(float(np.abs(shaped).max(axis=0)[0]), 1e-300)
        keystoned = bounds(*size, lambda p: self._keystone_h(self._shape(p - self.c)))
        self.extent_y = max(float(np.abs(keystoned).max(axis=0)[1]), 1e-300)
        self._shift = 0.0
        self._shift = fit_canvas(self, self.forward)

    def _shape_setup(self, **extra) -> None:
        """Constants of the shape from the style's own parameters (none by default)."""

    def _shape(self, d: np.ndarray) -> np.ndarray:
        """The style's own map.

        Parameters
        ----------
        d : (N, 2) ndarray
            Offsets of source points from the image's centre, in pixels.

        Returns
        -------
        (N, 2) ndarray
            Their offsets in the shaped image (any origin: the canvas is fitted afterwards).
        """
        raise NotImplementedError

    def _keystone_h(self, d: np.ndarray) -> np.ndarray:
        """Horizontal distortion: each column's y scaled by ``1 + H x / X`` (>= 0.1)."""
        return np.stack([d[:, 0], d[:, 1] * (1.0 + self.h * d[:, 0] / self.extent_x)], axis=1)

    def _keystone_v(self, d: np.ndarray) -> np.ndarray:
        """Vertical distortion: each row's x scaled by ``1 + V y / Y`` (>= 0.1)."""
        return np.stack([d[:, 0] * (1.0 + self.v * d[:, 1] / self.extent_y), d[:, 1]], axis=1)

    def forward(self, points):
        d = self._shape(points - self.c)
        return self._keystone_v(self._keystone_h(d)) - self._shift

"""What a solved mesh makes of the canvas: the share it leaves blank, and where the
background is stretched most.

Both are measured against the plain warp W on the same grid, so they name what the
feature-aware solve adds to what the preset asks for: blank canvas the plain warp fills, and
background texture pulled into streaks.
"""

from __future__ import annotations

import cv2
import numpy as np

#: Sub-pixel bits of the outline's vertices when it is filled (1/16 px).
_SHIFT = 4


def outline(nx: int, ny: int) -> np.ndarray:
    """Node indices of a ``nx`` x ``ny`` grid's border, once around (top, right, bottom, left)."""
    top = np.arange(nx)
    right = np.arange(1, ny) * nx + nx - 1
    bottom = (ny - 1) * nx + np.arange(nx - 2, -1, -1)
    left = np.arange(ny - 2, 0, -1) * nx
    return np.concatenate([top, right, bottom, left])


def coverage(points: np.ndarray, ring: np.ndarray, canvas: tuple[int, int]) -> np.ndarray:
    """(height, width) bool: canvas pixels whose centre lies inside the mesh's outline.

    The mesh is injective, so what it covers is the inside of its border's image."""
    width, height = canvas
    covered = np.zeros((height, width), np.uint8)
    vertices = np.round(points[ring] * (1 << _SHIFT)).astype(np.int64)
    vertices = np.clip(vertices, -(1 << 28), 1 << 28).astype(np.int32)   # far outside: clipped, same fill
    cv2.fillPoly(covered, [vertices.reshape(-1, 1, 2)], 1, lineType=cv2.LINE_8, shift=_SHIFT)
    return covered.astype(bool)


def blank_shares(target: np.ndarray, warped: np.ndarray, nx: int, ny: int, canvas: tuple[int, int]):
    """Blank canvas under the result and under W, and where the result leaves blank what W fills.

    Returns
    -------
    blank, plain_blank : float
        Shares (0..1) of the canvas no source pixel lands on.
    extra_box : tuple of 4 ints or None
        ``(x0, y0, x1, y1)``: the pixels W fills that the result leaves blank (None: none).
    """
    ring = outline(nx, ny)
    result, plain = coverage(target, ring, canvas), coverage(warped, ring, canvas)
    extra = plain & ~result
    box = None
    if extra.any():
        ys, xs = np.nonzero(extra.any(axis=1))[0], np.nonzero(extra.any(axis=0))[0]
        box = (int(xs[0]), int(ys[0]), int(xs[-1]), int(ys[-1]))
    return float(1.0 - result.mean()), float(1.0 - plain.mean()), box


def largest_stretch(target: np.ndarray, warped: np.ndarray, triangles: np.ndarray):
    """The background's largest stretch beyond W, and where.

    For each triangle the map from its image under W to its image in the result is affine;
    its largest singular value is how much the solve stretches it beyond what the warp asks
    (1: as W; 8: a star becomes a needle eight times as long).

    Returns
    -------
    stretch : float
        The largest over ``triangles`` (1.0 when there are none).
    where : tuple of 2 floats or None
        The canvas position of that triangle's centre.
    """
    if not triangles.size:
        return 1.0, None
    (a, b), (c, d) = _edges(warped, triangles)                     # W's edge matrix [[a, c], [b, d]]
    det = a * d - b * c
    valid = np.abs(det) > 1e-12
    if not valid.any():
        return 1.0, None
    (p, q), (r, t) = _edges(target, triangles)
    inverse = 1.0 / np.where(valid, det, 1.0)
    # maps = [[p, r], [q, t]] @ inv([[a, c], [b, d]]), entry by entry
    m00, m01 = (p * d - r * b) * inverse, (r * a - p * c) * inverse
    m10, m11 = (q * d - t * b) * inverse, (t * a - q * c) * inverse
    frobenius = m00 * m00 + m01 * m01 + m10 * m10 + m11 * m11
    gap = np.sqrt(np.maximum(frobenius ** 2 - 4.0 * (m00 * m11 - m01 * m10) ** 2, 0.0))
    largest = np.where(valid, np.sqrt(0.5 * (frobenius + gap)), 0.0)
    worst = int(np.argmax(largest))
    centre = target[triangles[worst]].mean(axis=0)
    return float(max(1.0, largest[worst])), (float(centre[0]), float(centre[1]))


def _edges(points: np.ndarray, triangles: np.ndarray):
    """Each triangle's two edges from its first corner: ((x1, y1), (x2, y2)), each (M,)."""
    x, y = points[:, 0], points[:, 1]
    first, second, third = triangles[:, 0], triangles[:, 1], triangles[:, 2]
    return (x[second] - x[first], y[second] - y[first]), (x[third] - x[first], y[third] - y[first])


def outline_departure(target: np.ndarray, warped: np.ndarray, nx: int, ny: int, past=None):
    """How far the result's outline leaves W's: the largest distance of a border node of the
    result from W's outline (a polyline through W's border nodes), and where.

    A border that slides along W's outline does not count; one let go of it does, except the
    nodes ``past`` ((N,) bool: beyond a side that ``--grow-past-edge`` lets features grow past).

    Returns
    -------
    distance : float
        Pixels (0.0 when every border node lies on W's outline).
    where : tuple of 2 floats or None
        The canvas position of that node.
    """
    ring = outline(nx, ny)
    moved = np.hypot(*(target[ring] - warped[ring]).T) > 1e-9
    if past is not None:                      # beyond a side a grown feature was let past: a crop
        moved &= ~past[ring]
    moved = ring[moved]
    if not moved.size:
        return 0.0, None
    starts = warped[ring]
    along = np.roll(starts, -1, axis=0) - starts
    squared = np.maximum(np.sum(along * along, axis=1), 1e-300)
    distance = np.empty(moved.size)
    for chunk in range(0, moved.size, 256):                         # bounded memory: 256 x segments
        p = target[moved[chunk:chunk + 256], None, :]
        t = np.clip(np.sum((p - starts) * along, axis=2) / squared, 0, 1)
        nearest = starts + t[:, :, None] * along
        distance[chunk:chunk + 256] = np.sqrt(np.min(np.sum((p - nearest) ** 2, axis=2), axis=1))
    worst = int(np.argmax(distance))
    return float(distance[worst]), (float(target[moved[worst], 0]), float(target[moved[worst], 1]))

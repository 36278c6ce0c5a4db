"""Keeping the mapping free of fold-overs.

The solver keeps a mapping known to be injective (every triangle positively
oriented: at first the warp itself on a grid that follows it) and only ever
moves it along straight segments as far as no triangle degenerates. These are
the geometric pieces of that scheme.
"""

from __future__ import annotations

import cv2
import numpy as np

from .grid import Grid, grid_shape, signed_areas


def max_step(start: np.ndarray, end: np.ndarray, triangles: np.ndarray, floor: np.ndarray | None = None) -> float:
    """Largest t in [0, 1] such that no triangle's area falls below ``floor`` (default: no
    triangle degenerates) anywhere on start -> start + t (end - start).

    Each triangle's signed area along the segment is a quadratic in t; the step stops at the
    first root in [0, 1] of any of them minus its floor: an exact function of the inputs, so a
    one-ulp change of them moves it by rounding only (no bisection). ``start`` must keep every
    triangle's area above (or at) its floor; one at its floor whose area falls at once stops
    the step at 0.

    Parameters
    ----------
    start, end : (N, 2) ndarray
        Node positions.
    triangles : (M, 3) ndarray of int
    floor : (M,) ndarray, optional
        Least area per triangle.

    Returns
    -------
    float
        1.0 when the whole segment keeps every floor.
    """
    corners = [np.ascontiguousarray(triangles[:, k]) for k in range(3)]

    def edges(points):                      # (x, y) of the edges a->b and a->c of every triangle
        x, y = np.ascontiguousarray(points[:, 0]), np.ascontiguousarray(points[:, 1])
        (xa, xb, xc), (ya, yb, yc) = ([axis.take(k) for k in corners] for axis in (x, y))
        return (xb - xa, yb - ya), (xc - xa, yc - ya)

    def cross(p, q):
        return p[0] * q[1] - p[1] * q[0]

    (u0, v0), (du, dv) = edges(start), edges(end - start)  # gathered as signed_areas does: ~6x faster
    c = cross(u0, v0)                       # area * 2 at t = 0 (> 0)
    if floor is not None:
        c = np.maximum(c - 2.0 * floor, 0.0)
    return first_root(c, cross(u0, dv) + cross(du, v0), cross(du, dv))


def max_step_of(areas, start: np.ndarray, end: np.ndarray) -> float:
    """:func:`max_step` (no floor) from three calls of ``areas`` (positions -> signed area per
    triangle; on a grid, :func:`grid_areas` slices instead of gathering, several times faster):
    the quadratics' coefficients from the areas at t = 0, 1 and -1."""
    at_start, ahead, behind = areas(start), areas(end), areas(2.0 * start - end)
    return first_root(at_start, 0.5 * (ahead - behind), 0.5 * (ahead + behind) - at_start)


def first_root(c: np.ndarray, b: np.ndarray, a: np.ndarray) -> float:
    """The first t in [0, 1] where any of the quadratics c + b t + a t^2 (c >= 0) reaches
    zero (one at zero that falls at once: 0), 1.0 where none does. The roots are q / a and
    c / q with q = -(b + sign(b) sqrt(b^2 - 4 a c)) / 2, the form that does not cancel (a
    linear one, a = 0, has the second only). Only quadratics that can reach zero on [0, 1]
    (c <= |b| + |a|, with room for rounding) are solved: most are far from it."""
    near = np.flatnonzero(~(c > (1.0 + 1e-9) * (np.abs(b) + np.abs(a))))      # NaN rows stay, as before
    c, b, a = c[near], b[near], a[near]
    roots = np.where((c <= 0) & ((b < 0) | ((b == 0) & (a < 0))), 0.0, np.inf)
    disc = b * b - 4.0 * a * c
    with np.errstate(divide="ignore", invalid="ignore"):
        q = -0.5 * (b + np.copysign(np.sqrt(np.where(disc >= 0, disc, 0.0)), b))
        for root in (q / a, c / q):
            roots = np.where((disc >= 0) & (root > 0) & (root < roots), root, roots)
    first = float(roots.min(initial=np.inf))
    return 1.0 if first > 1.0 else first


def eased(grid: Grid, start: np.ndarray, end: np.ndarray, triangles: np.ndarray, share: float,
          reach: float) -> tuple[np.ndarray, float]:
    """A fold-free point between ``start`` (injective) and ``end`` that stays at ``end`` away
    from its folds.

    Around the triangles ``end`` folds, nodes stop at ``share`` of the fold-free step
    (:func:`max_step`); from there their share of the way rises smoothly (a half cosine) to
    all of it over ``reach`` cells. Where that folds a triangle, every node stops at the
    fold-free step's share (the straight segment, which cannot fold).

    Returns
    -------
    points : (N, 2) ndarray
    step : float
        The share of the way the nodes around the folds went.
    """
    step = share * max_step(start, end, triangles)
    near = np.zeros(grid.n_nodes, bool)
    near[triangles[signed_areas(end, triangles) <= 0].ravel()] = True
    if not near.any():
        return end.copy(), 1.0
    free = (~near).reshape(grid.ny, grid.nx).astype(np.uint8)
    cells = cv2.distanceTransform(free, cv2.DIST_L2, cv2.DIST_MASK_PRECISE).ravel()
    rise = 0.5 - 0.5 * np.cos(np.pi * np.clip(cells / reach, 0.0, 1.0))
    points = start + (step + (1.0 - step) * rise)[:, None] * (end - start)
    if np.all(signed_areas(points, triangles) > 0):
        return points, step
    return start + step * (end - start), step


def grid_areas(grid: Grid, points: np.ndarray) -> np.ndarray:
    """Signed areas of ``grid.triangles()`` under node positions ``points``, by slicing
    the node array (several times faster than gathering corners by index): (2K,)."""
    c = points.reshape(grid.ny, grid.nx, 2)
    tl, tr, br, bl = c[:-1, :-1], c[:-1, 1:], c[1:, 1:], c[1:, :-1]

    def cross(u, v):
        return 0.5 * (u[..., 0] * v[..., 1] - u[..., 1] * v[..., 0])

    diagonal = br - tl
    return np.concatenate([cross(tr - tl, diagonal).ravel(), cross(diagonal, bl - tl).ravel()])


def flipped(points: np.ndarray, triangles: np.ndarray) -> np.ndarray:
    """(M,) bool: triangles whose signed area is <= 0."""
    return signed_areas(points, triangles) <= 0


def trouble_quads(grid: Grid, bad: np.ndarray, radius: int = 2) -> np.ndarray:
    """Quads holding a ``bad`` triangle ((M,) bool), grown by ``radius`` quads: (K,) bool."""
    n_quads = (grid.nx - 1) * (grid.ny - 1)
    quads = np.zeros(n_quads, np.uint8)
    quads[np.flatnonzero(bad) % n_quads] = 1      # triangles t and t + K share quad t
    quads = quads.reshape(grid.quad_shape)
    if radius > 0:
        quads = cv2.dilate(quads, np.ones((2 * radius + 1, 2 * radius + 1), np.uint8))
    return quads.ravel().astype(bool)


def window(grid: Grid, quads: np.ndarray, margin: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The quads within ``margin`` quads of ``quads``, and the nodes they can move.

    Parameters
    ----------
    grid : Grid
    quads : (K,) bool ndarray
        Quads to open (holding a folded or crushed triangle).
    margin : int
        Rings of quads added around them.

    Returns
    -------
    quads : (K,) bool ndarray
        The window's quads.
    nodes : (N,) bool ndarray
        Corners of the window's quads.
    inner : (N,) bool ndarray
        Nodes all four of whose quads are in the window (so never a border
        node): moving only these changes no triangle outside the window.
    """
    inside = quads.reshape(grid.quad_shape).astype(np.uint8)
    if margin > 0:
        inside = cv2.dilate(inside, np.ones((2 * margin + 1, 2 * margin + 1), np.uint8))
    padded = np.zeros((grid.ny + 1, grid.nx + 1), bool)
    padded[1:-1, 1:-1] = inside
    around = (padded[:-1, :-1], padded[:-1, 1:], padded[1:, :-1], padded[1:, 1:])
    nodes = around[0] | around[1] | around[2] | around[3]
    inner = around[0] & around[1] & around[2] & around[3]
    return inside.ravel().astype(bool), nodes.ravel(), inner.ravel()


def extent(grid: Grid, quads: np.ndarray) -> int:
    """Longest side, in quads, of the bounding boxes of the connected groups of ``quads`` (indices)."""
    if quads.size == 0:
        return 0
    marked = np.zeros(grid.quad_shape[0] * grid.quad_shape[1], np.uint8)
    marked[quads] = 1
    _, _, stats, _ = cv2.connectedComponentsWithStats(marked.reshape(grid.quad_shape), connectivity=8)
    return int(stats[1:, cv2.CC_STAT_WIDTH:cv2.CC_STAT_HEIGHT + 1].max())


#: A triangle below this share of its floor counts as crushed: the guard's window is around
#: it and continues the barrier below it (:func:`guard._open_window`); the path from W's
#: predictor, a release, a fallback and the tapered moves stop before it; the scale search's
#: spread keeps above it. Lower lets those steps leave slivers; higher ends them (and releases) sooner.
CRUSHED_SHARE = 0.5


def area_gradients(points: np.ndarray, triangles: np.ndarray) -> np.ndarray:
    """Gradient of each triangle's signed area with respect to its three corners.

    Returns
    -------
    (M, 3, 2) ndarray
    """
    a, b, c = (points[triangles[:, k]] for k in range(3))

    def half_perp(p, q):  # d area / d r for the corner r opposite to the edge p -> q
        return 0.5 * np.stack([p[:, 1] - q[:, 1], q[:, 0] - p[:, 0]], axis=1)

    return np.stack([half_perp(b, c), half_perp(c, a), half_perp(a, b)], axis=1)


def penalty_force(x: np.ndarray, triangles: np.ndarray, slopes: np.ndarray) -> np.ndarray:
    """Sum of ``slopes`` times the ``triangles``' area gradients, per node: the gradient of
    sum_t f_t(area_t) for slopes f_t'(area_t) (the barrier's, :func:`barrier.converge`), or the
    force that opens them for slopes of the opposite sign.

    Parameters
    ----------
    x : (N, 2) ndarray
    triangles : (M, 3) ndarray of int
    slopes : (M,) ndarray
        d energy / d area of each triangle.

    Returns
    -------
    (N, 2) ndarray
    """
    contributions = slopes[:, None, None] * area_gradients(x, triangles)
    corners = triangles.ravel()
    return np.stack([np.bincount(corners, contributions[:, :, d].ravel(), minlength=x.shape[0])
                     for d in range(2)], axis=1)


def penalty_stiffness(x: np.ndarray, triangles: np.ndarray, stiffness: np.ndarray) -> np.ndarray:
    """Per triangle, the kappa at which kappa (area)^2 is as stiff as the quadratic energy at its corners
    (:func:`barrier.weights` scales it)."""
    grads = area_gradients(x, triangles)
    return stiffness[triangles].mean(axis=1) / np.maximum(2.0 * (grads * grads).sum(axis=(1, 2)), 1e-12)


def border_crossings(source: np.ndarray, target: np.ndarray) -> int:
    """How many pairs of the grid's border edges cross on the canvas.

    A map that folds no triangle can still lay the image over itself when its border
    winds across itself (a handle dragged far through the image); it is one-to-one exactly
    when no triangle folds and this is 0.

    Parameters
    ----------
    source, target : (N, 2) ndarray
        Node positions of a row-major grid (as :meth:`Grid.nodes`) in the source and on the canvas.
    """
    nx, ny = grid_shape(source)
    if nx < 2 or ny < 2:
        return 0
    index = np.arange(nx * ny).reshape(ny, nx)
    loop = np.concatenate([index[0, :-1], index[:-1, -1], index[-1, :0:-1], index[:0:-1, 0]])
    start, end = target[loop], np.roll(target[loop], -1, axis=0)
    edges, count = len(loop), 0

    def cross(u, v):
        return u[..., 0] * v[..., 1] - u[..., 1] * v[..., 0]

    low, high = np.minimum(start, end), np.maximum(start, end)
    for first in range(0, edges, 64):            # runs of 64 edges against the edges near them
        last = min(edges, first + 64)
        box_low, box_high = low[first:last].min(axis=0), high[first:last].max(axis=0)
        near = np.flatnonzero(np.all((high >= box_low) & (low <= box_high), axis=1))
        a, b = start[first:last, None], end[first:last, None]
        c, d = start[near][None], end[near][None]
        hit = (cross(b - a, c - a) * cross(b - a, d - a) < 0) & (cross(d - c, a - c) * cross(d - c, b - c) < 0)
        i = np.arange(first, last)[:, None]
        j = near[None]
        count += int(np.count_nonzero(hit & (j > i + 1) & ~((i == 0) & (j == edges - 1))))
    return count

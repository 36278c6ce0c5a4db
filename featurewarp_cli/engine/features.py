"""Feature mask -> per-quad feature flags, connected components and weights (paper 2, 2.1)."""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

from .defaults import DECAY, FEATURE_WEIGHT
from .grid import Grid


@dataclass(frozen=True)
class Features:
    """What the mask means for each quad of a grid.

    Attributes
    ----------
    is_feature : (K,) bool ndarray
        The quad holds at least one feature pixel.
    component : (K,) int ndarray
        Connected component (0 .. n_components-1) of a feature quad, or of the
        feature nearest to a transition quad; -1 for plain background quads.
    weight : (K,) float ndarray
        Equation weight: w_F on features, decaying to 1 within ``decay`` cells (Eq. 7).
    n_components : int
    frame_strip : ((P, 2) float ndarray, (P,) int ndarray) or None
        The mask pixels (x, y) that :func:`short_of_frame` left to the background, in the
        frame's outer cells along a side their component's mask stops short of, and each one's
        component: they follow the background, and the report says how far
        (:func:`featurewarp_cli.engine.quality.frame_strip_figures`). None: no such pixel.
    """

    is_feature: np.ndarray
    component: np.ndarray
    weight: np.ndarray
    n_components: int
    frame_strip: tuple | None = None

    @property
    def is_constrained(self) -> np.ndarray:
        """Quads that get shape equations (features and transition quads)."""
        return self.component >= 0


def decay(distance: np.ndarray, rho: float) -> np.ndarray:
    """The paper's cubic decay f(x) = 2x^3/rho^3 - 3x^2/rho^2 + 1 (Eq. 6), 0 beyond rho."""
    x = np.clip(distance / rho, 0.0, 1.0)
    return 2.0 * x**3 - 3.0 * x**2 + 1.0


def analyse(mask: np.ndarray, grid: Grid, feature_weight: float = FEATURE_WEIGHT, rho: float = DECAY) -> Features:
    """Classify and weight the quads of ``grid`` from a boolean feature ``mask``.

    Parameters
    ----------
    mask : (h, w) bool ndarray
        True where a pixel belongs to a feature.
    grid : Grid
    feature_weight : float
        w_F, the weight of feature equations (each side multiplied by it).
    rho : float
        Decay radius in cells (the paper uses 2).

    Returns
    -------
    Features
    """
    qy, qx = grid.quad_shape
    n_quads = qy * qx
    if not mask.any():
        return Features(np.zeros(n_quads, bool), np.full(n_quads, -1), np.ones(n_quads), 0)

    sx, sy = grid.spacing
    cx = np.clip(np.round((np.arange(qx) + 0.5) * sx - 0.5).astype(int), 0, grid.width - 1)
    cy = np.clip(np.round((np.arange(qy) + 0.5) * sy - 0.5).astype(int), 0, grid.height - 1)
    origin, given = None, mask
    if min(sx, sy) >= 1.0:
        pooled = _pooled(mask, grid)
        mask, pooled, origin = short_of_frame(mask, grid, pooled)
    else:  # sub-pixel cells: the pixel under the quad's centre decides
        pooled = np.ascontiguousarray(mask[np.ix_(cy, cx)]).view(np.uint8)
    is_feature = pooled.astype(bool)

    n_labels, labels = cv2.connectedComponents(pooled, connectivity=8)
    strip = None
    if origin is not None:            # the pixels dropped, and their components as labelled after the drop
        final = np.full(origin.max() + 1, -1, np.int64)
        final[origin[is_feature]] = labels[is_feature] - 1     # a component keeps one piece
        ys, xs = np.nonzero(given & ~mask)
        rows, cols = grid.quad_of_pixel()
        strip = (np.stack([xs, ys], axis=1).astype(np.float64), final[origin[rows[ys], cols[xs]]])
    # Nearest feature quad of every quad, then its component.
    _, nearest = cv2.distanceTransformWithLabels(
        (~is_feature).view(np.uint8), cv2.DIST_L2, 5, labelType=cv2.DIST_LABEL_PIXEL)
    label_to_component = np.zeros(nearest.max() + 1, dtype=np.int64)
    label_to_component[nearest[is_feature]] = labels[is_feature] - 1
    nearest_component = label_to_component[nearest]

    # Distance from each quad centre to the nearest feature pixel, in cells (beyond rho, the
    # weight is 1 whatever it is).
    reach = int(np.ceil(rho * (sx + sy) / 2.0))
    distance = feature_distance(mask, cy, cx, reach) / ((sx + sy) / 2.0)

    f = np.where(is_feature, 1.0, decay(distance, rho))
    weight = feature_weight * f + (1.0 - f)
    component = np.where(f > 0, nearest_component, -1)
    return Features(is_feature.ravel(), component.ravel(), weight.ravel(), n_labels - 1, strip)


def feature_distance(mask: np.ndarray, rows: np.ndarray, cols: np.ndarray, reach: int) -> np.ndarray:
    """Euclidean distance from each pixel (row, col) of ``rows`` x ``cols`` to the nearest True
    pixel of ``mask``: exact where it is at most ``reach``, above ``reach`` elsewhere.

    The squared distance is a whole number, and the root of it is taken once, so the result
    is the same on every machine. Where only short distances matter, it is computed at the
    quad centres alone: per column, the vertical distance from each of ``rows`` to the
    nearest True pixel (one sweep down and one up), then the least of dx^2 + dy^2 over the
    columns within ``reach`` (Felzenszwalb and Huttenlocher's two passes, the second
    bounded). At 12 MP with the automatic grid that takes 20 ms where a distance transform
    of the whole image took 90-280 ms; where the bounded pass would cost more than the image
    has pixels (a wide ``reach`` on a fine grid), the whole transform runs (OpenCV's float32
    distances may be an ulp off, differently from run to run, so their squares are rounded
    to the whole numbers they are).

    Returns
    -------
    (len(rows), len(cols)) float32 ndarray
    """
    height, width = mask.shape
    reach = min(reach, height + width)
    if (2 * reach + 1) * rows.size * cols.size > mask.size:
        pixel_distance = cv2.distanceTransform((~mask).view(np.uint8), cv2.DIST_L2, cv2.DIST_MASK_PRECISE)
        pixel_distance = pixel_distance[np.ix_(rows, cols)].astype(np.float64)
        return np.sqrt(np.rint(pixel_distance * pixel_distance)).astype(np.float32)
    rows, row_of = np.unique(rows, return_inverse=True)       # sub-pixel cells repeat rows
    vertical = np.full((rows.size, width), float(reach + 1))
    slot = np.full(height, -1)
    slot[rows] = np.arange(rows.size)
    for sweep in (range(height), range(height - 1, -1, -1)):
        last = np.full(width, np.inf)                 # the nearest True row so far, this way
        for row in sweep:
            np.copyto(last, row, where=mask[row])
            if slot[row] >= 0:
                np.minimum(vertical[slot[row]], np.abs(last - row), out=vertical[slot[row]])
    vertical *= vertical
    squared = np.full((rows.size, cols.size), float((reach + 1) ** 2))
    for dx in range(-reach, reach + 1):
        at = cols + dx
        inside = (at >= 0) & (at < width)
        squared[:, inside] = np.minimum(squared[:, inside], dx * dx + vertical[:, at[inside]])
    return np.sqrt(squared[row_of.ravel()]).astype(np.float32)


def _pooled(mask: np.ndarray, grid: Grid) -> np.ndarray:
    """(qy, qx) uint8: 1 for a quad any of whose pixels is a feature pixel (max-pool; cells of
    at least a pixel)."""
    qy, qx = grid.quad_shape
    rows, cols = grid.quad_of_pixel()
    row_bounds = np.append(np.searchsorted(rows, np.arange(qy)), grid.height)
    col_starts = np.searchsorted(cols, np.arange(qx))
    # Rows of pixels -> rows of quads, one reduction per quad row (10x faster than
    # np.maximum.reduceat along axis 0), then columns.
    by_row = np.empty((qy, grid.width), np.uint8)
    for j in range(qy):
        np.maximum.reduce(mask[row_bounds[j] : row_bounds[j + 1]].view(np.uint8), axis=0, out=by_row[j])
    return np.maximum.reduceat(by_row, col_starts, axis=1)


def short_of_frame(mask: np.ndarray, grid: Grid, pooled: np.ndarray) -> tuple[np.ndarray, np.ndarray, object]:
    """The mask, less the pixels a component holds in the frame's outer cells along a side that
    its mask does not reach; the quads pooled again (``pooled`` when nothing changed); and the
    quads' components before (None when nothing changed).

    A lasso that stops a few pixels short of an edge puts the component in the outer cells,
    whose nodes the border holds: the component would count as cut by the frame, and under a
    preset that curves that edge no similarity could follow it. Read as stopping a cell short,
    it stays inside the frame and keeps its shape; the band around it takes the rest. A
    component the mask leads out of the frame (a pixel on the edge) stays cut; one that lies
    wholly in the outer cells, or would fall apart without them, keeps them.

    Parameters
    ----------
    mask : (h, w) bool ndarray
    grid : Grid
        Cells of at least a pixel.
    pooled : (qy, qx) uint8 ndarray
        The feature quads of ``mask`` (:func:`_pooled`).

    Returns
    -------
    mask : (h, w) bool ndarray
        ``mask`` itself when nothing is dropped, else a copy without those pixels.
    pooled : (qy, qx) uint8 ndarray
        Its feature quads.
    origin : (qy, qx) int ndarray or None
        The component of every feature quad of the ``pooled`` given (-1: none), numbered by
        its own labelling; None when nothing is dropped.
    """
    n_labels, labels = cv2.connectedComponents(pooled, connectivity=8)
    quads, n = labels - 1, n_labels - 1                     # component per quad, -1 for none
    rows, cols = grid.quad_of_pixel()
    strips = [(0, slice(None)), (-1, slice(None)), (slice(None), 0), (slice(None), -1)]   # top bottom left right
    edges = [(mask[0], cols), (mask[-1], cols), (mask[:, 0], rows), (mask[:, -1], rows)]
    reach = np.zeros((4, n + 1), bool)                      # column n: no component
    for side, ((line, along), strip) in enumerate(zip(edges, strips)):
        reach[side, quads[strip][along][line]] = True       # a mask pixel on the edge itself
    drop = np.zeros(quads.shape, bool)
    for side, strip in enumerate(strips):
        drop[strip] |= (quads[strip] >= 0) & ~reach[side, quads[strip]]
    for side, strip in enumerate(strips):                   # a corner cell of a side reached stays
        drop[strip] &= ~reach[side, quads[strip]]
    left = np.bincount(quads[(quads >= 0) & ~drop], minlength=n + 1) > 0
    drop &= left[quads]                                     # a component would vanish: it keeps them
    kept = (quads >= 0) & ~drop
    _, parts = cv2.connectedComponents(kept.view(np.uint8), connectivity=8)
    # The distinct (component, part) pairs, as one integer each (np.unique(axis=1) on the
    # stacked pairs sorts them as raw bytes: 0.12 s at 12 MP, this 3 ms).
    span = np.int64(parts.max()) + 1
    pairs = np.unique(quads[kept].astype(np.int64) * span + parts[kept]) // span
    drop &= ~(np.bincount(pairs, minlength=n + 1) > 1)[quads]   # one that would split keeps them
    if not drop.any():
        return mask, pooled, None
    # Every pixel of a dropped quad goes, and no other: pooling again would give pooled & ~drop.
    return mask & ~drop[rows][:, cols], pooled & ~drop.view(np.uint8), quads

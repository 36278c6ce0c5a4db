"""Antialiasing for :func:`featurewarp_cli.render.raster.render`: a prefilter where the
map shrinks the image, and a feathered silhouette.

* **Minification.** Where the inverse map's Jacobian ``J`` (source pixels per
  output pixel, constant on each triangle) has a singular value above
  :data:`AA_START`, the pixel is sampled from a Gaussian pyramid of the source
  (``cv2.pyrDown`` levels, trilinear between the two levels bracketing
  ``log2`` of the smaller singular value) with a tent of probes along the major
  axis of its footprint (anisotropic filtering as GPUs do it). Elsewhere the
  plain ``cv2.remap`` sample is kept, so warps that do not shrink the image are
  untouched. :class:`Footprints` holds each minifying triangle's filter,
  :func:`filter_band` applies it to a band's pixels.
* **Coverage.** Pixels within half a pixel of the mesh's outer boundary
  (:class:`Silhouette`) get a fractional coverage ``0.5 + d`` inside and
  ``0.5 - d`` outside (``d`` the distance from the pixel centre to the
  boundary, i.e. a one-pixel box feather), which becomes partial alpha on a
  transparent canvas or a blend with the background colour, instead of a
  binary staircase. A pixel whose centre falls just outside takes the colour
  of the nearest boundary point.

The footprints, the probes' positions and their weighted sums are computed in
the compiled module :mod:`featurewarp_cli.render._raster`; the samples come
from :func:`cv2.remap`.
"""

from __future__ import annotations

import threading

import cv2
import numpy as np

from . import _raster
from .remap import remap

#: Minification (largest singular value of J) from which a pixel is prefiltered.
AA_START = 1.1
#: Most probes on each side of the centre along a footprint's major axis.
AA_MAX_STEPS = 4
#: Interpolation of the probes (the tent of probes is the wider filter there).
AA_INTERPOLATION = cv2.INTER_LINEAR
#: Footprints from this size on (NaN, overflow) are not filtered.
LARGEST_FOOTPRINT = 2.0 ** 60
#: Width of the (rows, width) maps that :func:`sample_points` samples scattered points with.
COMPACT_WIDTH = 4096


class Footprints:
    """The filter of each minifying triangle among a band's triangles.

    Parameters
    ----------
    records : (n, 16) float64 ndarray
        The triangles' records (:meth:`featurewarp_cli.render.raster.Triangles.records`);
        only their J is read.
    threshold : float
        Largest singular value of J from which a triangle minifies.

    Attributes
    ----------
    index : (n,) int32 ndarray
        The minifying triangles numbered 0, 1, ...; -1 for the others.
    ints : (m, 3) int32 ndarray
        Per minifying triangle: probes per side k, pyramid level ``floor(L)``, and
        whether level ``floor(L) + 1`` is blended in (L = log2 of the minor axis).
    floats : (m, 3) float32 ndarray
        Per minifying triangle: the source offset between two probes (x, y), along
        J's major left singular vector, and ``L - floor(L)``.
    max_level : int
        The highest pyramid level they use.
    weights : (AA_MAX_STEPS + 1, 2 AA_MAX_STEPS - 1) float32 ndarray
        ``weights[k]`` holds the 2k-1 tent weights ``(1 - |j|/k) / k`` of k probes a side.
    """

    weights = np.zeros((AA_MAX_STEPS + 1, 2 * AA_MAX_STEPS - 1), np.float32)
    for _k in range(1, AA_MAX_STEPS + 1):
        _j = np.arange(-(_k - 1), _k, dtype=np.float32)
        weights[_k, :2 * _k - 1] = (1.0 - np.abs(_j) / _k) / _k           # tent, sums to 1
    del _k, _j

    def __init__(self, records: np.ndarray, threshold: float = AA_START):
        n = records.shape[0]
        self.index = np.empty(n, np.int32)
        ints, floats = np.empty((n, 3), np.int32), np.empty((n, 3), np.float32)
        count, self.max_level = _raster.footprints(records, threshold, AA_MAX_STEPS, LARGEST_FOOTPRINT,
                                                   self.index, ints, floats)
        self.ints, self.floats = ints[:count], floats[:count]


class Pyramid:
    """Gaussian pyramid of the source (cv2.pyrDown), built on demand (thread-safe)."""

    def __init__(self, image: np.ndarray):
        self.levels = [image]
        self.lock = threading.Lock()

    def __getitem__(self, k: int) -> np.ndarray:
        with self.lock:
            while len(self.levels) <= k:
                last = self.levels[-1]
                self.levels.append(last if min(last.shape[:2]) < 2 else cv2.pyrDown(last))
            return self.levels[k]


def sample_points(image: np.ndarray, mx: np.ndarray, my: np.ndarray, interp: int) -> np.ndarray:
    """Sample ``image`` at scattered points.

    Parameters
    ----------
    image : (h, w) or (h, w, C) ndarray
    mx, my : (n,) float32 ndarray
        Source positions.
    interp : int
        A cv2 interpolation flag.

    Returns
    -------
    (n, C) ndarray
        The samples, in ``image``'s dtype (borders replicated).
    """
    channels = 1 if image.ndim == 2 else image.shape[2]
    total = mx.size
    rows = -(-total // COMPACT_WIDTH)
    pad = rows * COMPACT_WIDTH - total
    if pad:
        mx = np.concatenate([mx, np.zeros(pad, np.float32)])
        my = np.concatenate([my, np.zeros(pad, np.float32)])
    mx, my = mx.reshape(rows, COMPACT_WIDTH), my.reshape(rows, COMPACT_WIDTH)
    return remap(image, mx, my, interp).reshape(-1, channels)[:total]


def filter_band(pyramid: Pyramid, foot: Footprints, aatri: np.ndarray, bx: np.ndarray, by: np.ndarray,
                flat: np.ndarray, scratch) -> None:
    """Write the prefiltered value of a band's minified pixels.

    Each pixel averages 2k-1 probes ``j * step`` (j = -(k-1) .. k-1, tent
    weights) around its source position along its footprint's major axis, on
    pyramid level floor(L) and, with weight frac(L), floor(L) + 1. The probes
    of each level are laid out in one (rows, :data:`COMPACT_WIDTH`) map for one
    :func:`cv2.remap` per level.

    Parameters
    ----------
    pyramid : Pyramid
    foot : Footprints
        The band's footprints.
    aatri : (n,) int32 ndarray
        Per band pixel, its triangle's number in ``foot`` (-1: not minified).
    bx, by : (n,) float32 ndarray
        The band's source positions.
    flat : (n, channels) ndarray
        The band's output pixels (its first channels are written).
    scratch : callable
        ``scratch(name, size, dtype)``: a reusable uninitialised array.
    """
    counts = np.zeros(foot.max_level + 2, np.int64)
    _raster.aa_count(aatri, foot.ints, counts)
    offsets = np.zeros(counts.size + 1, np.int64)
    np.cumsum(-(-counts // COMPACT_WIDTH) * COMPACT_WIDTH, out=offsets[1:])
    px, py = scratch("px", offsets[-1], np.float32), scratch("py", offsets[-1], np.float32)
    for level in range(counts.size):                       # the padding after each level's probes
        px[offsets[level] + counts[level]:offsets[level + 1]] = 0.0
        py[offsets[level] + counts[level]:offsets[level + 1]] = 0.0
    _raster.aa_probes(aatri, bx, by, foot.ints, foot.floats, offsets, px, py)
    image = pyramid[0]
    channels = 1 if image.ndim == 2 else image.shape[2]
    used = np.flatnonzero(counts)
    if used.size == 1:                       # one level: its samples are all of them (no copy)
        samples = sample_points(pyramid[used[0]], px, py, AA_INTERPOLATION)
    else:
        samples = np.empty((offsets[-1], channels), image.dtype)
        for level in used:
            a, b = offsets[level], offsets[level + 1]
            samples[a:b] = sample_points(pyramid[level], px[a:b], py[a:b], AA_INTERPOLATION)
    _raster.aa_resolve(aatri, foot.ints, foot.floats, foot.weights, AA_MAX_STEPS, offsets,
                       samples, channels, flat, flat.shape[1])


class Silhouette:
    """The mesh's outer boundary on the canvas: segments with their source endpoints.

    The source mesh covers a rectangle (the image's pixel extent): its
    boundary edges are the triangle edges whose two nodes lie on the same
    side of the source nodes' bounding box.

    Parameters
    ----------
    source, target : (N, 2) ndarray
        Node positions in the input image and on the canvas.
    triangles : (M, 3) ndarray of int
    """

    def __init__(self, source, target, triangles):
        source = np.asarray(source, dtype=np.float64)
        x, y = source[:, 0], source[:, 1]
        lo, hi = np.array([x.min(), y.min()]), np.array([x.max(), y.max()])     # (min(axis=0) is slow)
        tol = 1e-9 * max(1.0, float(np.abs(source).max()))
        side = np.zeros(source.shape[0], dtype=np.int64)      # bit mask of the box sides a node lies on
        side |= (np.abs(source[:, 0] - lo[0]) <= tol) * 1
        side |= (np.abs(source[:, 0] - hi[0]) <= tol) * 2
        side |= (np.abs(source[:, 1] - lo[1]) <= tol) * 4
        side |= (np.abs(source[:, 1] - hi[1]) <= tol) * 8
        tri = np.asarray(triangles, dtype=np.int64)
        on = side[tri] > 0
        cand = np.flatnonzero(on[:, 0].astype(np.int8) + on[:, 1] + on[:, 2] >= 2)
        a_list, b_list = [], []
        for i, j in ((0, 1), (1, 2), (2, 0)):
            a, b = tri[cand, i], tri[cand, j]
            shared = (side[a] & side[b]) != 0
            a_list.append(a[shared])
            b_list.append(b[shared])
        a, b = np.concatenate(a_list), np.concatenate(b_list)
        key = np.unique(np.minimum(a, b) * source.shape[0] + np.maximum(a, b))
        a, b = key // source.shape[0], key % source.shape[0]
        target = np.asarray(target, dtype=np.float64)
        self.ta, self.tb = target[a], target[b]
        self.sa, self.sb = source[a], source[b]
        self.ymin = np.minimum(self.ta[:, 1], self.tb[:, 1])
        self.ymax = np.maximum(self.ta[:, 1], self.tb[:, 1])

    def inside_canvas(self, width: int, height: int) -> bool:
        """True when some boundary segment comes within half a pixel of a pixel centre's box."""
        xmin = np.minimum(self.ta[:, 0], self.tb[:, 0])
        xmax = np.maximum(self.ta[:, 0], self.tb[:, 0])
        tol = 1e-6
        return bool(np.any((xmax > -0.5 + tol) & (xmin < width - 0.5 - tol)
                           & (self.ymax > -0.5 + tol) & (self.ymin < height - 0.5 - tol)))

    def band(self, y0: int, y1: int, width: int):
        """Pixels of rows [y0, y1) within half a pixel of the boundary.

        Returns
        -------
        pixel : (n,) int64 ndarray
            Flat index in the band.
        dist : (n,) float64 ndarray
            Distance from the pixel centre to the nearest boundary point.
        src : (n, 2) float64 ndarray
            The source position of that point.
        """
        sel = np.flatnonzero((self.ymax >= y0 - 0.5) & (self.ymin <= y1 - 0.5))
        empty = np.zeros(0, np.int64), np.zeros(0), np.zeros((0, 2))
        if sel.size == 0:
            return empty
        ta, tb = self.ta[sel], self.tb[sel]
        x0 = np.maximum(np.ceil(np.minimum(ta[:, 0], tb[:, 0]) - 0.5), 0).astype(np.int64)
        x1 = np.minimum(np.floor(np.maximum(ta[:, 0], tb[:, 0]) + 0.5), width - 1).astype(np.int64)
        r0 = np.maximum(np.ceil(self.ymin[sel] - 0.5), y0).astype(np.int64)
        r1 = np.minimum(np.floor(self.ymax[sel] + 0.5), y1 - 1).astype(np.int64)
        bw, bh = np.maximum(x1 - x0 + 1, 0), np.maximum(r1 - r0 + 1, 0)
        n = bw * bh
        if n.sum() == 0:
            return empty
        seg = np.repeat(np.arange(sel.size), n)
        local = np.arange(n.sum()) - np.repeat(np.cumsum(n) - n, n)
        px = x0[seg] + local % bw[seg]
        py = r0[seg] + local // bw[seg]
        a, d = ta[seg], tb[seg] - ta[seg]
        with np.errstate(over="ignore", invalid="ignore"):      # absurd nodes (1e300): NaN, not near
            length2 = (d * d).sum(axis=1)
            t = np.clip(((px - a[:, 0]) * d[:, 0] + (py - a[:, 1]) * d[:, 1]) / np.maximum(length2, 1e-300), 0, 1)
            dist = np.hypot(a[:, 0] + t * d[:, 0] - px, a[:, 1] + t * d[:, 1] - py)
        near = dist < 0.5
        if not near.any():
            return empty
        seg, px, py, t, dist = seg[near], px[near], py[near], t[near], dist[near]
        pixel = (py - y0) * width + px
        order = np.lexsort((dist, pixel))
        pixel, seg, t, dist = pixel[order], seg[order], t[order], dist[order]
        first = np.ones(pixel.size, bool)
        first[1:] = pixel[1:] != pixel[:-1]
        pixel, seg, t, dist = pixel[first], seg[first], t[first], dist[first]
        sa, sb = self.sa[sel][seg], self.sb[sel][seg]
        return pixel, dist, sa + t[:, None] * (sb - sa)

"""Forward mesh -> inverse map (rasterized deformed triangles) -> resampled image.

:func:`render` is the whole stage: it walks the output canvas in bands of rows,
rasterizes the deformed triangles that reach each band into float32 maps of
source positions, resamples the band with :func:`cv2.remap` and writes it into
the output, so that no full-canvas map is ever held. Two kinds of antialiasing
are applied on the way:

* **Minification.** Where the inverse map's Jacobian ``J`` (source pixels per
  output pixel, constant on each triangle) has a singular value above
  :data:`AA_START`, the pixel is sampled from a Gaussian pyramid of the source
  (``cv2.pyrDown`` levels, trilinear between the two levels bracketing
  ``log2`` of the smaller singular value) with a tent of probes along the major
  axis of its footprint (anisotropic filtering as GPUs do it). Elsewhere the
  plain ``cv2.remap`` sample is kept, so warps that do not shrink the image are
  untouched.
* **Coverage.** Pixels within half a pixel of the mesh's outer boundary get a
  fractional coverage ``0.5 + d`` inside and ``0.5 - d`` outside (``d`` the
  distance from the pixel centre to the boundary, i.e. a one-pixel box
  feather), which becomes partial alpha on a transparent canvas or a blend with
  the background colour, instead of a binary staircase. A pixel whose centre
  falls just outside takes the colour of the nearest boundary point.

:func:`inverse_map` and :func:`resample` are the two halves without
antialiasing, kept for callers that want the map itself.

The per-triangle and per-pixel loops (triangle setup, scanline filling, the
filter's probes and sums) run in the compiled module :mod:`featurewarp_cli.render._raster`,
which reproduces the numpy code here bit for bit; when it is not built, the
numpy code runs instead (slower), with one notice on stderr per process.
"""

from __future__ import annotations

import math
import os
import sys
import threading
from concurrent.futures import ThreadPoolExecutor

import cv2
import numpy as np

try:
    from . import _raster
except ImportError:                # built without a C compiler: the numpy code below instead
    _raster = None

_fallback_noted = False

INTERPOLATION = {"linear": cv2.INTER_LINEAR, "cubic": cv2.INTER_CUBIC, "lanczos": cv2.INTER_LANCZOS4}

#: Output pixels per band (rows are grouped so that a band holds about this many).
BAND_PIXELS = 1 << 18
#: Bands rendered at once (the compiled loops, numpy and OpenCV release the GIL).
#: 12 MP at cell 4 (swirl 180) on the 2-core machine takes about 0.9 s of CPU
#: antialiased, 0.6 s without; with two threads under 0.5 s and 0.35 s. The
#: output does not depend on it.
THREADS = min(2, os.cpu_count() or 1)
#: Minification (largest singular value of J) from which a pixel is prefiltered.
AA_START = 1.1
#: Most probes on each side of the centre along a footprint's major axis.
AA_MAX_STEPS = 4
#: Interpolation of the probes (the tent of probes is the wider filter there).
AA_INTERPOLATION = cv2.INTER_LINEAR
_COMPACT_WIDTH = 4096     # width of the (rows, width) maps used to sample scattered points
#: Footprints from this size on (NaN, overflow) are not filtered.
_LARGEST_FOOTPRINT = 2.0 ** 60
#: log2(x) = t (c1 + t^2 (c3 + t^2 (c5 + ...))) with t = (x - 1) / (x + 1): the blend
#: between two pyramid levels, within 2e-7 of log2 on [1, 2). Only + - * / and sqrt,
#: which numpy and C round the same, go into the footprints.
_LOG2_SERIES = tuple(2.0 / (k * math.log(2.0)) for k in (1, 3, 5, 7, 9, 11))


def _compiled():
    """The compiled loops, or None (then say once on stderr that numpy stands in)."""
    global _fallback_noted
    if _raster is None and not _fallback_noted:
        sys.stderr.write("featurewarp: the compiled rasterizer is not built; "
                         "rendering with numpy, which is slower\n")
        _fallback_noted = True
    return _raster


# --------------------------------------------------------------------------- triangles

class _Triangles:
    """Per-triangle data for scanline rasterization and sampling (float64 geometry).

    For each non-degenerate triangle that reaches the canvas (``index``): its
    row range on the canvas, the two lower and two upper x-bounds
    ``x(y) = k + m*y`` of its interior on a row, and the inverse affine map
    (``source = s0 + J (p - p0)``). Edges are evaluated from their
    lower-numbered node, so that the two triangles sharing an edge compute
    bit-identical bounds: every pixel centre is claimed by at least one of them
    (no cracks) and, off the edge, by one.

    With ``compiled`` (the :mod:`featurewarp_cli.render._raster` module) only
    ``index``, the row ranges and the nodes (``corners``, int32) are stored,
    stably sorted by first row with ``sort`` (the order the bands rasterize them
    in), and :meth:`records` computes the rest for a range of them, in C.
    Without, numpy computes everything, in the triangles' order.
    """

    #: Columns of :meth:`records`.
    FIELDS = ("lk0", "lm0", "lk1", "lm1", "uk0", "um0", "uk1", "um1",
              "j00", "j01", "j10", "j11", "px0", "py0", "sx0", "sy0")
    J = slice(8, 12)

    def __init__(self, source, target, triangles, canvas, compiled=None, sort=True):
        self.compiled = compiled
        if compiled is None:
            self._setup(source, target, triangles, canvas)
            return
        self.canvas = width, height = tuple(int(c) for c in canvas)
        self.target = np.ascontiguousarray(target, dtype=np.float64).reshape(-1, 2)
        self.source = np.ascontiguousarray(source, dtype=np.float64).reshape(-1, 2)
        triangles = np.asarray(triangles, dtype=np.int64).reshape(-1, 3)     # any strides
        m = triangles.shape[0]
        index, ylo, yhi = np.empty(m, np.int64), np.empty(m, np.int64), np.empty(m, np.int64)
        self.corners = np.empty((m, 3), np.int32)       # the kept triangles' nodes, in order
        self.count = compiled.triangles(self.target, triangles, width, height, sort,
                                        index, ylo, yhi, self.corners)
        self.index, self.ylo, self.yhi = index[:self.count], ylo[:self.count], yhi[:self.count]
        self.corners = self.corners[:self.count]

    def records(self, sel: np.ndarray, out: np.ndarray | None = None) -> np.ndarray:
        """(len(sel), 16) float64: :data:`FIELDS` of triangles ``sel`` (compiled setup),
        in ``out`` (an array of at least that many float64) if given."""
        size = (sel.size, len(self.FIELDS))
        rec = np.empty(size) if out is None else out[:size[0] * size[1]].reshape(size)
        self.compiled.records(self.target, self.source, self.corners, *self.canvas, sel, rec)
        return rec

    def _setup(self, source, target, triangles, canvas):
        """The numpy version of ``_raster.triangles`` and the setup in ``_raster.rasterize``."""
        width, height = canvas
        tri = np.asarray(triangles)
        target = np.asarray(target, dtype=np.float64)
        tx, ty = np.ascontiguousarray(target[:, 0]), np.ascontiguousarray(target[:, 1])
        n0, n1, n2 = (np.ascontiguousarray(tri[:, c]) for c in range(3))
        x0, x1, x2 = tx[n0], tx[n1], tx[n2]
        y0, y1, y2 = ty[n0], ty[n1], ty[n2]
        det = (x1 - x0) * (y2 - y0) - (y1 - y0) * (x2 - x0)
        ylo = np.maximum(np.ceil(np.minimum(np.minimum(y0, y1), y2)), 0)
        yhi = np.minimum(np.floor(np.maximum(np.maximum(y0, y1), y2)), height - 1)
        keep = (np.abs(det) > 1e-12) & (ylo <= yhi)
        keep &= np.maximum(np.maximum(x0, x1), x2) >= 0
        keep &= np.minimum(np.minimum(x0, x1), x2) <= width - 1
        self.index = index = np.flatnonzero(keep)
        everything = index.size == tri.shape[0]

        def kept(a):
            return a if everything else a[keep]

        n0, n1, n2, x0, x1, x2, y0, y1, y2, det = map(kept, (n0, n1, n2, x0, x1, x2, y0, y1, y2, det))
        self.ylo = kept(ylo).astype(np.int64)
        self.yhi = kept(yhi).astype(np.int64)
        self.count = index.size

        # x-bounds per edge: the edge from node a to node b (a < b) cuts row y at
        # x = ax + m (y - ay); it bounds the interior from below when the third
        # vertex lies to its right on that row, from above otherwise.
        positive = det > 0
        ks, ms, lower, upper = [], [], [], []
        verts = ((n0, x0, y0), (n1, x1, y1), (n2, x2, y2))
        for i, j in ((0, 1), (1, 2), (2, 0)):
            (ni, xi, yi), (nj, xj, yj) = verts[i], verts[j]
            swap = ni > nj
            ax, ay = np.where(swap, xj, xi), np.where(swap, yj, yi)
            dx, dy = np.where(swap, xi - xj, xj - xi), np.where(swap, yi - yj, yj - yi)
            flat = dy == 0
            m = dx / np.where(flat, 1.0, dy)
            m[flat] = 0.0
            ks.append(ax - m * ay)
            ms.append(m)
            # Interior where sign(det) * cross(pj - pi, q - pi) >= 0; the x
            # coefficient of that is -sign(det) * (yj - yi).
            rising, falling = yj > yi, yj < yi
            lower.append(np.where(positive, falling, rising))
            upper.append(np.where(positive, rising, falling))
        # At most two edges bound each side: the first and the last of them
        # (the same edge twice when only one does).
        self.lk, self.lm, self.uk, self.um = [], [], [], []
        for flags, inf, ks_out, ms_out in ((lower, -np.inf, self.lk, self.lm), (upper, np.inf, self.uk, self.um)):
            f0, f1, f2 = flags
            none = ~(f0 | f1 | f2)
            first_k = np.where(f0, ks[0], np.where(f1, ks[1], ks[2]))
            first_m = np.where(f0, ms[0], np.where(f1, ms[1], ms[2]))
            last_k = np.where(f2, ks[2], np.where(f1, ks[1], ks[0]))
            last_m = np.where(f2, ms[2], np.where(f1, ms[1], ms[0]))
            for kk, mm in ((first_k, first_m), (last_k, last_m)):
                kk[none] = inf
                mm[none] = 0.0
                ks_out.append(kk)
                ms_out.append(mm)

        # Inverse affine map: source = s0 + J (q - p0), J = S E^-1 with
        # S = [s1 - s0, s2 - s0] and E = [p1 - p0, p2 - p0] as columns.
        source = np.asarray(source, dtype=np.float64)
        sx, sy = np.ascontiguousarray(source[:, 0]), np.ascontiguousarray(source[:, 1])
        sx0, sy0 = sx[n0], sy[n0]
        d1x, d1y = sx[n1] - sx0, sy[n1] - sy0
        d2x, d2y = sx[n2] - sx0, sy[n2] - sy0
        inv = 1.0 / det
        i00, i01 = (y2 - y0) * inv, -(x2 - x0) * inv
        i10, i11 = -(y1 - y0) * inv, (x1 - x0) * inv
        self.j00 = d1x * i00 + d2x * i10
        self.j01 = d1x * i01 + d2x * i11
        self.j10 = d1y * i00 + d2y * i10
        self.j11 = d1y * i01 + d2y * i11
        self.px0, self.py0 = x0, y0
        self.sx0, self.sy0 = sx0, sy0


def _spans(tris: _Triangles, sel: np.ndarray, y0: int, y1: int, width: int):
    """Row spans of triangles ``sel`` inside rows [y0, y1).

    Returns the triangle (index into ``tris``), row and first / last pixel
    column of every non-empty span.
    """
    lo = np.maximum(tris.ylo[sel], y0)
    hi = np.minimum(tris.yhi[sel], y1 - 1)
    n = np.maximum(hi - lo + 1, 0)
    total = int(n.sum())
    t = np.repeat(sel, n)
    y = (np.repeat(lo - np.cumsum(n) + n, n) + np.arange(total)).astype(np.float64)

    def bound(k, m):                          # k + m * y on every span
        v = np.repeat(m[sel], n)
        v *= y
        v += np.repeat(k[sel], n)
        return v

    xl = np.maximum(bound(tris.lk[0], tris.lm[0]), bound(tris.lk[1], tris.lm[1]))
    xr = np.minimum(bound(tris.uk[0], tris.um[0]), bound(tris.uk[1], tris.um[1]))
    np.ceil(xl, out=xl)
    np.floor(xr, out=xr)
    np.maximum(xl, 0, out=xl)
    np.minimum(xr, width - 1, out=xr)
    ok = xl <= xr
    return t[ok], y[ok].astype(np.int64), xl[ok].astype(np.int64), xr[ok].astype(np.int64)


def _rasterize_band(tris: _Triangles, sel: np.ndarray, y0: int, y1: int, width: int,
                    mapx: np.ndarray, mapy: np.ndarray, minified: np.ndarray | None = None):
    """Fill the band's maps (flat, -1 where uncovered) from triangles ``sel``.

    With ``minified`` (bool per triangle), also return the band pixels that
    belong to minifying triangles and their triangle: (pixels, triangles).
    """
    t, y, xl, xr = _spans(tris, sel, y0, y1, width)
    n = xr - xl + 1
    total = int(n.sum())
    if total == 0:
        return (np.zeros(0, np.int64), np.zeros(0, np.int64)) if minified is not None else None
    # Source position of each span's first pixel (float64), then per-pixel steps (float32).
    j00, j10 = tris.j00[t], tris.j10[t]
    qx, qy = xl - tris.px0[t], y - tris.py0[t]
    start_x = tris.sx0[t] + j00 * qx + tris.j01[t] * qy
    start_y = tris.sy0[t] + j10 * qx + tris.j11[t] * qy
    offset = np.cumsum(n) - n
    local = (np.arange(total) - np.repeat(offset, n)).astype(np.float32)
    pixel = np.repeat((y - y0) * width + xl - offset, n) + np.arange(total)
    mapx[pixel] = np.repeat(start_x.astype(np.float32), n) + np.repeat(j00.astype(np.float32), n) * local
    mapy[pixel] = np.repeat(start_y.astype(np.float32), n) + np.repeat(j10.astype(np.float32), n) * local
    if minified is None:
        return None
    spans = np.flatnonzero(minified[t])
    if spans.size == 0:
        return np.zeros(0, np.int64), np.zeros(0, np.int64)
    m = n[spans]
    first = ((y - y0) * width + xl)[spans]
    pix = np.repeat(first - (np.cumsum(m) - m), m) + np.arange(int(m.sum()))
    return pix, np.repeat(t[spans], m)


def _band_order(tris: _Triangles):
    """Triangles sorted (stably) by first row, their first rows, and the tallest
    triangle's height. The compiled setup stores them in that order: order is None."""
    tallest = int((tris.yhi - tris.ylo).max()) if tris.count else 0
    if tris.compiled is not None:
        return None, tris.ylo, tallest
    order = np.argsort(tris.ylo, kind="stable")
    return order, tris.ylo[order], tallest


def _band_range(ylo_sorted, tallest, y0, y1) -> tuple[int, int]:
    """[a, b): the sorted triangles that may have a row in [y0, y1)."""
    return (int(np.searchsorted(ylo_sorted, y0 - tallest, side="left")),
            int(np.searchsorted(ylo_sorted, y1 - 1, side="right")))


def _band_triangles(order, ylo_sorted, yhi, tallest, y0, y1):
    """Triangles (indices into the triangle data) with a row in [y0, y1), in rasterizing order."""
    a, b = _band_range(ylo_sorted, tallest, y0, y1)
    cand = order[a:b]
    return cand[yhi[cand] >= y0]


def _band_rows(width: int, height: int, band_pixels: int | None) -> int:
    return max(1, min(height, (band_pixels or BAND_PIXELS) // max(width, 1)))


# --------------------------------------------------------------------------- inverse map

def inverse_map(source: np.ndarray, target: np.ndarray, triangles: np.ndarray,
                canvas: tuple[int, int]) -> tuple[np.ndarray, np.ndarray]:
    """Source position of every canvas pixel, by rasterizing the deformed triangles.

    Each pixel centre inside a target triangle gets the affine interpolation
    of that triangle's source corners. Shared edges are computed identically
    by both triangles, so there are no cracks between triangles.

    Parameters
    ----------
    source : (N, 2) ndarray
        Node positions in the input image.
    target : (N, 2) ndarray
        Node positions on the output canvas.
    triangles : (M, 3) ndarray of int
    canvas : (int, int)
        Output (width, height).

    Returns
    -------
    coords : (H, W, 2) float32 ndarray
        Source (x, y) per pixel; -1 where no triangle covers the pixel.
    covered : (H, W) bool ndarray
    """
    width, height = canvas
    mapx = np.full(height * width, -1.0, dtype=np.float32)
    mapy = np.full(height * width, -1.0, dtype=np.float32)
    raster = _compiled()
    tris = _Triangles(source, target, triangles, canvas, raster, sort=False)   # later ones win
    if tris.count and raster is not None:
        for a in range(0, tris.count, 1 << 16):           # later triangles win, as in numpy
            sel = np.arange(a, min(tris.count, a + (1 << 16)))
            raster.rasterize(tris.records(sel), tris.ylo[sel], tris.yhi[sel], 0, height, width,
                             mapx, mapy, None, None)
    elif tris.count:
        _rasterize_band(tris, np.arange(tris.count), 0, height, width, mapx, mapy)
    covered = mapx > -0.75
    coords = np.stack([mapx, mapy], axis=1).reshape(height, width, 2)
    return coords, covered.reshape(height, width)


# --------------------------------------------------------------------------- coverage

class _Boundary:
    """The mesh's outer boundary on the canvas: segments with their source endpoints.

    The source mesh covers a rectangle (the image's pixel extent): its
    boundary edges are the triangle edges whose two nodes lie on the same
    side of the source nodes' bounding box.
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
        """Band pixels within half a pixel of the boundary: flat index, distance,
        and the source position of the nearest boundary point."""
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


# --------------------------------------------------------------------------- antialiasing

class _Minification:
    """Footprint of the minifying triangles among those whose J is (j00, j01, j10, j11).

    ``minified`` and ``index`` (the minifying triangles numbered 0, 1, ..., the
    others -1) run over those triangles; ``ints`` = (k, base level, blend) and
    ``floats`` = (step x, step y, frac), float32 steps and frac, over the
    minifying ones. ``weights[k]`` holds the 2k-1 tent weights of k probes per
    side. The values of a triangle depend on its J only.
    """

    weights = np.zeros((AA_MAX_STEPS + 1, 2 * AA_MAX_STEPS - 1), np.float32)
    for _k in range(1, AA_MAX_STEPS + 1):
        _j = np.arange(-(_k - 1), _k, dtype=np.float32)
        weights[_k, :2 * _k - 1] = (1.0 - np.abs(_j) / _k) / _k           # tent, sums to 1
    del _k, _j

    def __init__(self, a, b, c, d, threshold: float = AA_START):
        # J = [[a, b], [c, d]] = R(theta) diag(s1, s2) R(phi)^T with (u1 + i v1) / 2 =
        # (s1 + s2) / 2 e^{i (theta + phi)} and (u2 + i v2) / 2 = (s1 - s2) / 2 e^{i (theta - phi)}.
        u1, v1, u2, v2 = a + d, c - b, a - d, c + b
        p, q = np.sqrt(u1 * u1 + v1 * v1), np.sqrt(u2 * u2 + v2 * v2)
        s1 = (p + q) / 2.0
        with np.errstate(invalid="ignore"):
            self.minified = (s1 > threshold) & (s1 < _LARGEST_FOOTPRINT)
        sel = np.flatnonzero(self.minified)
        self.index = np.full(self.minified.size, -1, np.int32)
        self.index[sel] = np.arange(sel.size, dtype=np.int32)
        u1, v1, u2, v2, p, q, s1 = (v[sel] for v in (u1, v1, u2, v2, p, q, s1))
        s2 = np.abs(p - q) / 2.0
        m1 = np.maximum(s1, 1.0)
        m2 = np.maximum(s2, 1.0)
        # Tent of half-width W = 2 (m1 - m2) along the major axis, probes at most
        # m2 apart (the level's prefilter width), at most AA_MAX_STEPS per side.
        steps = np.maximum(2, np.ceil(2.0 * (m1 - m2) / m2 - 1e-9))
        over = steps > AA_MAX_STEPS
        m2 = np.where(over, 2.0 * m1 / (AA_MAX_STEPS + 2.0), m2)
        steps = np.minimum(steps, AA_MAX_STEPS).astype(np.int64)
        half = 2.0 * (m1 - m2)
        steps[half < 1e-3] = 1
        # The major axis e^{i theta}: the square root of e^{i (theta + phi)} e^{i (theta - phi)}
        # (up to its sign, which the symmetric tent does not see).
        p1, q1 = np.where(p > 0, p, 1.0), np.where(q > 0, q, 1.0)
        e1x, e1y = np.where(p > 0, u1 / p1, 1.0), v1 / p1
        e2x, e2y = np.where(q > 0, u2 / q1, 1.0), v2 / q1
        zr, zi = e1x * e2x - e1y * e2y, e1x * e2y + e1y * e2x
        r = np.sqrt(zr * zr + zi * zi)
        right = zr >= 0
        t = np.sqrt(np.where(right, r + zr, r - zr) / 2.0)
        norm = np.sqrt(r)
        axis_x = np.where(right, t, np.abs(zi) / (2.0 * t)) / norm
        axis_y = np.where(right, zi / (2.0 * t), np.copysign(t, zi)) / norm
        # Pyramid level log2(m2) = base + frac (frac from _LOG2_SERIES).
        mantissa, exponent = np.frexp(m2)
        base = exponent.astype(np.int64) - 1
        x = 2.0 * mantissa
        t = (x - 1.0) / (x + 1.0)
        t2 = t * t
        c1, c3, c5, c7, c9, c11 = _LOG2_SERIES
        frac = (t * (c1 + t2 * (c3 + t2 * (c5 + t2 * (c7 + t2 * (c9 + t2 * c11)))))).astype(np.float32)
        blend = frac > 1e-4
        self.ints = np.stack([steps, base, blend], axis=1).astype(np.int32)
        self.floats = np.empty((sel.size, 3), np.float32)
        spacing = half / steps                                           # source offset between probes
        self.floats[:, 0] = spacing * axis_x
        self.floats[:, 1] = spacing * axis_y
        self.floats[:, 2] = frac
        self.max_level = int((base + blend).max()) if sel.size else 0

    @classmethod
    def compiled(cls, raster, rec: np.ndarray, threshold: float = AA_START) -> "_Minification":
        """The same from records ``rec`` (n, 16), in C (the same operations)."""
        self = cls.__new__(cls)
        n = rec.shape[0]
        self.index, ints, floats = np.empty(n, np.int32), np.empty((n, 3), np.int32), np.empty((n, 3), np.float32)
        count, self.max_level = raster.footprints(rec, threshold, AA_MAX_STEPS, _LARGEST_FOOTPRINT, self.index,
                                                  ints, floats)
        self.minified = self.index >= 0
        self.ints, self.floats = ints[:count], floats[:count]
        return self


class _Scratch(threading.local):
    """Arrays that each thread reuses from band to band: fresh arrays of megabytes cost
    page faults (the kernel zeroing the pages) every time. ``scratch(name, n, dtype)``
    is the first n items of that thread's array, uninitialised."""

    def __call__(self, name: str, n, dtype) -> np.ndarray:
        n = int(n)
        a = self.__dict__.get(name)
        if a is None or a.size < n or a.dtype != dtype:
            a = self.__dict__[name] = np.empty(n + n // 4, dtype)
        return a[:n]


class _Pyramid:
    """Gaussian pyramid of the source (cv2.pyrDown), built on demand (thread-safe)."""

    def __init__(self, image):
        self.levels = [image]
        self.lock = threading.Lock()

    def __getitem__(self, k):
        with self.lock:
            while len(self.levels) <= k:
                last = self.levels[-1]
                if min(last.shape[:2]) < 2:
                    self.levels.append(last)
                else:
                    self.levels.append(cv2.pyrDown(last))
            return self.levels[k]


def _sample_grid(image, x, y, interp):
    """Sample ``image`` at the points of (n, P) float32 arrays; returns (n, P, C) uint/float."""
    n, probes = x.shape
    return _sample_points(image, x.reshape(-1), y.reshape(-1), interp).reshape(n, probes, -1)


def _sample_points(image, mx, my, interp):
    """Sample ``image`` at the points of flat float32 arrays; returns (n, C) uint/float."""
    channels = 1 if image.ndim == 2 else image.shape[2]
    total = mx.size
    rows = -(-total // _COMPACT_WIDTH)
    pad = rows * _COMPACT_WIDTH - total
    if pad:
        mx = np.concatenate([mx, np.zeros(pad, np.float32)])
        my = np.concatenate([my, np.zeros(pad, np.float32)])
    mx, my = mx.reshape(rows, _COMPACT_WIDTH), my.reshape(rows, _COMPACT_WIDTH)
    parts = [cv2.remap(image, mx[r:r + 8192], my[r:r + 8192], interp, borderMode=cv2.BORDER_REPLICATE)
             for r in range(0, rows, 8192)]            # remap wants fewer than 32767 rows
    values = parts[0] if len(parts) == 1 else np.concatenate(parts)
    return values.reshape(-1, channels)[:total]


def _antialiased(pyramid: _Pyramid, minif: _Minification, tri: np.ndarray,
                 sx: np.ndarray, sy: np.ndarray, interp) -> np.ndarray:
    """Prefiltered samples (n, C) float32 for pixels at source (sx, sy) on minifying triangles ``tri``.

    Each pixel averages 2k-1 probes j * step (j = -(k-1) .. k-1, tent weights
    1 - |j|/k) along its footprint's major axis, on pyramid level floor(L)
    and, with weight frac(L), floor(L) + 1.
    """
    n = tri.size
    ints, floats = minif.ints[minif.index[tri]].astype(np.int64), minif.floats[minif.index[tri]]
    steps, base, frac = ints[:, 0], ints[:, 1], floats[:, 2]
    image0 = pyramid[0]
    channels = 1 if image0.ndim == 2 else image0.shape[2]
    acc = np.zeros((n, channels), np.float32)
    group_key = (steps * 64 + base) * 2 + ints[:, 2]
    order = np.argsort(group_key, kind="stable")
    keys = group_key[order]
    cuts = np.flatnonzero(np.diff(keys)) + 1
    for members in np.split(order, cuts):
        key = int(group_key[members[0]])
        k = int(steps[members[0]])
        b = int(base[members[0]])
        j = np.arange(-(k - 1), k, dtype=np.float32)
        weight = minif.weights[k, :2 * k - 1]
        step = floats[members, :2]
        px = sx[members, None] + j[None, :] * step[:, 0:1]
        py = sy[members, None] + j[None, :] * step[:, 1:2]
        f = frac[members]
        blend = key % 2 == 1
        for lev, w_level in ((b, 1.0 - f if blend else None), (b + 1, f if blend else None)):
            if w_level is None and lev != b:
                continue
            scale = np.float32(0.5 ** lev)                       # pyrDown: level pixel i sits on 2^lev i
            vals = _sample_grid(pyramid[lev], px * scale, py * scale, AA_INTERPOLATION)
            contrib = vals[:, 0].astype(np.float32) * np.float32(weight[0])
            for p in range(1, weight.size):
                contrib += vals[:, p] * np.float32(weight[p])
            if w_level is not None:
                contrib *= w_level[:, None]
            acc[members] += contrib
    return acc


def _antialiased_compiled(raster, pyramid: _Pyramid, minif: _Minification, aatri: np.ndarray,
                          bx: np.ndarray, by: np.ndarray, flat: np.ndarray, scratch) -> None:
    """:func:`_antialiased` and its write into the band, with the compiled loops.

    The pixels with ``aatri >= 0`` (their triangle's number in ``minif``) get the
    prefiltered value, rounded into ``flat`` (band pixels, out channels). The
    probes of each pyramid level are laid out in one (rows, _COMPACT_WIDTH) map
    for one :func:`cv2.remap` per level.
    """
    counts = np.zeros(minif.max_level + 2, np.int64)
    raster.aa_count(aatri, minif.ints, counts)
    offsets = np.zeros(counts.size + 1, np.int64)
    np.cumsum(-(-counts // _COMPACT_WIDTH) * _COMPACT_WIDTH, out=offsets[1:])
    px, py = scratch("px", offsets[-1], np.float32), scratch("py", offsets[-1], np.float32)
    for level in range(counts.size):                       # the padding after each level's probes
        px[offsets[level] + counts[level]:offsets[level + 1]] = 0.0
        py[offsets[level] + counts[level]:offsets[level + 1]] = 0.0
    raster.aa_probes(aatri, bx, by, minif.ints, minif.floats, offsets, px, py)
    image = pyramid[0]
    channels = 1 if image.ndim == 2 else image.shape[2]
    used = np.flatnonzero(counts)
    if used.size == 1:                       # one level: its samples are all of them (no copy)
        samples = _sample_points(pyramid[used[0]], px, py, AA_INTERPOLATION)
    else:
        samples = np.empty((offsets[-1], channels), image.dtype)
        for level in used:
            a, b = offsets[level], offsets[level + 1]
            samples[a:b] = _sample_points(pyramid[level], px[a:b], py[a:b], AA_INTERPOLATION)
    raster.aa_resolve(aatri, minif.ints, minif.floats, minif.weights, AA_MAX_STEPS, offsets,
                      samples, channels, flat, flat.shape[1])


# --------------------------------------------------------------------------- render

def render(image: np.ndarray, source: np.ndarray, target: np.ndarray, triangles: np.ndarray,
           canvas: tuple[int, int], interp: str = "cubic", background=None, *,
           antialias: bool = True, band_pixels: int | None = None,
           threads: int | None = None) -> np.ndarray:
    """Resample ``image`` through a deformed triangle mesh, band by band, with antialiasing.

    Parameters
    ----------
    image : (h, w) or (h, w, C) ndarray, uint8 or uint16
    source : (N, 2) ndarray
        Node positions in the input image.
    target : (N, 2) ndarray
        Node positions on the output canvas.
    triangles : (M, 3) ndarray of int
    canvas : (int, int)
        Output (width, height).
    interp : {'linear', 'cubic', 'lanczos'}
    background : (r, g, b) tuple of 0..255, or None
        Fill colour where no triangle lands; None means transparent (an alpha
        channel is added when the image has none and some pixel is not fully
        covered).
    antialias : bool
        Prefilter where the map shrinks the image and feather the mesh's
        silhouette (default). False gives exactly ``resample(image,
        *inverse_map(...))``.
    band_pixels : int, optional
        Output pixels per band (default :data:`BAND_PIXELS`); the result does
        not depend on it.
    threads : int, optional
        Bands rendered at once (default :data:`THREADS`); the result does not
        depend on it.

    Returns
    -------
    ndarray
        Same dtype as ``image``; same channels, plus alpha where needed.
    """
    if interp not in INTERPOLATION:
        raise ValueError(f"interp must be one of {', '.join(INTERPOLATION)}, not {interp!r}")
    width, height = (int(c) for c in canvas)
    raster = _compiled() if image.dtype in (np.uint8, np.uint16) else None
    with ThreadPoolExecutor(1) as helper:       # the boundary's setup beside the triangles'
        boundary = helper.submit(_Boundary, source, target, triangles) if antialias else None
        tris = _Triangles(source, target, triangles, (width, height), raster)
        boundary = boundary.result() if antialias else None
    flag = INTERPOLATION[interp]
    channels = 1 if image.ndim == 2 else image.shape[2]
    # The compiled path takes each band's footprints in its thread (the numpy path all at once).
    minif = (_Minification(tris.j00, tris.j01, tris.j10, tris.j11)
             if antialias and tris.count and raster is None else None)
    pyramid = _Pyramid(image)

    # Decide the output layout up front: alpha is added when the background is
    # transparent and some pixel may be less than fully covered.
    maybe_partial = True
    if boundary is not None:
        maybe_partial = boundary.inside_canvas(width, height) or tris.count == 0
    add = background is None and channels in (1, 3) and maybe_partial
    # Without antialiasing a pixel is covered or not: render without alpha, note
    # the uncovered pixels (holes) and add alpha at the end if there are any.
    holes = {} if add and boundary is None else None
    add = add and holes is None
    out_channels = 4 if add else channels
    shape = (height, width) if out_channels == 1 else (height, width, out_channels)
    out = np.empty(shape, dtype=image.dtype)
    fill = None if background is None else np.array(fill_value(background, out), dtype=np.float64)
    top = np.iinfo(image.dtype).max

    order, ylo_sorted, tallest = _band_order(tris)
    rows = _band_rows(width, height, band_pixels)
    if minif is not None and minif.minified.any():
        pyramid[minif.max_level + 1]            # build the levels before the threads share them

    scratch = _Scratch()

    def one_band(y0):
        y1 = min(height, y0 + rows)
        size = (y1 - y0) * width
        bx, by = scratch("bx", size, np.float32), scratch("by", size, np.float32)
        bx.fill(-1.0)
        by.fill(-1.0)
        opaque = True
        if raster is not None:
            # The band's triangles (a range of the sorted ones, less those that end
            # above the band), their records and footprints. aatri: the last
            # minifying triangle on each pixel (its number in local, -1: none), as
            # the numpy code's last write of a pixel listed twice leaves it.
            a, b = _band_range(ylo_sorted, tallest, y0, y1)
            sel = a + np.flatnonzero(tris.yhi[a:b] >= y0)
            rec = tris.records(sel, scratch("rec", sel.size * 16, np.float64))
            local = _Minification.compiled(raster, rec) if antialias and sel.size else None
            aatri = scratch("aatri", size, np.int32) if local is not None else None
            if aatri is not None:
                aatri.fill(-1)
            marked = raster.rasterize(rec, tris.ylo[sel], tris.yhi[sel], y0, y1, width, bx, by,
                                      None if local is None else local.index, aatri)
        else:
            sel = (_band_triangles(order, ylo_sorted, tris.yhi, tallest, y0, y1) if tris.count
                   else np.zeros(0, np.int64))
            aa = _rasterize_band(tris, sel, y0, y1, width, bx, by,
                                 minif.minified if minif is not None else None)
        # Coverage below 1: uncovered pixel centres, and pixels near the silhouette.
        uncovered = np.flatnonzero(bx < -0.75)
        near, dist, src = boundary.band(y0, y1, width) if boundary is not None else (np.zeros(0, np.int64),) * 3
        coverage = None
        if uncovered.size or near.size:
            coverage = np.ones(size, np.float32)
            coverage[uncovered] = 0.0
            if near.size:
                inside = bx[near] > -0.75
                coverage[near] = np.where(inside, 0.5 + dist, 0.5 - dist)
                outside = ~inside
                bx[near[outside]] = src[outside, 0]
                by[near[outside]] = src[outside, 1]
        target_band = out[y0:y1]
        flat = target_band.reshape(size, out_channels)
        if out_channels != channels:
            target_band[..., 3] = top
        if raster is not None and marked > size // 4:
            # Most of the band is the filter's: resample only the other pixels.
            px, py = scratch("px", size + _COMPACT_WIDTH, np.float32), scratch("py", size + _COMPACT_WIDTH, np.float32)
            n = raster.gather(aatri, bx, by, px, py)
            if n:
                m = -(-n // _COMPACT_WIDTH) * _COMPACT_WIDTH
                px[n:m] = py[n:m] = 0.0
                values = _sample_points(image, px[:m], py[:m], flag)[:n]
                raster.scatter(aatri, values, channels, flat, out_channels)
        elif out_channels == channels:
            band = cv2.remap(image, bx.reshape(-1, width), by.reshape(-1, width), flag,
                             dst=target_band, borderMode=cv2.BORDER_REPLICATE)
            if band is not target_band and not np.shares_memory(band, target_band):
                target_band[...] = band
        else:
            band = cv2.remap(image, bx.reshape(-1, width), by.reshape(-1, width), flag,
                             borderMode=cv2.BORDER_REPLICATE)
            target_band[..., :3] = band[..., None] if channels == 1 else band
        if raster is not None:
            if marked:
                _antialiased_compiled(raster, pyramid, local, aatri, bx, by, flat, scratch)
        elif aa is not None and aa[0].size:
            pix, tri = aa
            values = _antialiased(pyramid, minif, tri, bx[pix], by[pix], flag)
            values = np.clip(np.rint(values), 0, top).astype(image.dtype)
            if out_channels == channels:
                flat[pix] = values
            else:
                flat[pix, :3] = values
        if coverage is None:
            return opaque
        partial = np.flatnonzero(coverage < 1.0)
        cov = coverage[partial][:, None].astype(np.float64)
        if background is None:
            if out_channels == 4:
                alpha = flat[partial, 3].astype(np.float64)
                flat[partial, 3] = np.rint(alpha * cov[:, 0]).astype(image.dtype)
                flat[partial[cov[:, 0] <= 0]] = 0
                opaque = False
            else:
                # No alpha (yet): uncovered pixels become 0.
                flat[partial[cov[:, 0] <= 0]] = 0
                if holes is not None:
                    holes[y0] = partial
        else:
            values = flat[partial].astype(np.float64)
            flat[partial] = np.rint(values * cov + fill[None, :] * (1.0 - cov)).astype(image.dtype)
        return opaque

    starts = range(0, height, rows)
    workers = min(threads if threads is not None else THREADS, len(starts))
    if workers > 1:
        with ThreadPoolExecutor(workers) as pool:
            all_opaque = all(list(pool.map(one_band, starts)))
    else:
        all_opaque = all([one_band(y0) for y0 in starts])
    if add and all_opaque:
        out = np.ascontiguousarray(out[:, :, :channels] if channels > 1 else out[:, :, 0])
    if holes:
        out = add_alpha(out)
        for y0, pixels in holes.items():
            out.reshape(-1, 4)[y0 * width + pixels] = 0
    return out


# --------------------------------------------------------------------------- resample

def resample(image: np.ndarray, coords: np.ndarray, covered: np.ndarray,
             interp: str = "cubic", background=None) -> np.ndarray:
    """Sample ``image`` at ``coords``; fill uncovered pixels with ``background``.

    Parameters
    ----------
    image : (h, w) or (h, w, C) ndarray, uint8 or uint16
    coords, covered : as returned by :func:`inverse_map`
    interp : {'linear', 'cubic', 'lanczos'}
    background : (r, g, b) tuple of 0..255, or None
        Fill colour where no triangle lands; None means transparent (an alpha
        channel is added when the image has none and some pixel is uncovered).

    Returns
    -------
    ndarray
        Same dtype as ``image``; same channels, plus alpha where needed.
    """
    out = cv2.remap(image, coords, None, INTERPOLATION[interp], borderMode=cv2.BORDER_REPLICATE)
    if covered.all():
        return out
    if background is None:
        out = add_alpha(out)
        out[~covered] = 0
    else:
        out[~covered] = fill_value(background, out)
    return out


def fill_value(rgb, image: np.ndarray) -> tuple:
    """An 8-bit (r, g, b) colour as an opaque fill for ``image``'s channels and depth."""
    top = np.iinfo(image.dtype).max
    r, g, b = (round(c * top / 255) for c in rgb)
    gray = round(0.299 * r + 0.587 * g + 0.114 * b)
    channels = 1 if image.ndim == 2 else image.shape[2]
    return {1: (gray,), 2: (gray, top), 3: (b, g, r), 4: (b, g, r, top)}[channels]


def add_alpha(image: np.ndarray) -> np.ndarray:
    """Return a BGRA copy of a gray, BGR or BGRA image (opaque alpha added)."""
    if image.ndim == 3 and image.shape[2] == 4:
        return image
    opaque = np.iinfo(image.dtype).max
    if image.ndim == 2:
        image = cv2.cvtColor(image, cv2.COLOR_GRAY2BGR)
    alpha = np.full(image.shape[:2] + (1,), opaque, dtype=image.dtype)
    return np.concatenate([image, alpha], axis=2)

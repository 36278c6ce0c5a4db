"""Antialiasing for :func:`featurewarp_cli.render.raster.render`: a reduction filter where
the map shrinks the image, and a feathered silhouette.

* **Minification.** Where the inverse map's Jacobian ``J`` (source pixels per output
  pixel, constant on each triangle) has a singular value above :data:`AA_START`, the
  pixel is sampled from a pyramid of the source with :data:`LEVELS_PER_OCTAVE` levels
  an octave (:mod:`featurewarp_cli.render.pyramid`): level ``8 o + r`` is the source halved ``o`` times and
  low-passed to ``2^(-r/8)`` of its band, by Lanczos-3 kernels (integer taps, exact
  sums). The footprint's axes ``m1 >= m2`` are J's singular values less, in
  quadrature, the reach that the interpolation has by itself (``AA_START^2 - 1``), so
  that the filter grows from nothing at ``AA_START``. The pixel takes the level made
  for ``m2``, blended with the next one between two levels' scales (linearly in
  ``m2`` over the middle of the interval, :data:`BLEND_MARGIN`: nothing jumps as the
  scale changes), sampled with the user's interpolation (``--interp``; ``lanczos``
  samples the probes of tents with cubic, at a fifth of the cost); along the
  major axis it averages a tent of probes of radius ``1.2 sqrt(m1^2 - (1.1 m2)^2)``
  (none up to an anisotropy of AA_START) at most ``m2`` apart: anisotropic filtering
  as GPUs do it, :data:`AA_MAX_STEPS` a side at most, beyond which the level rises. A
  footprint whose filter is one probe on level 0 keeps the plain ``cv2.remap`` sample.
  :class:`Footprints` holds each minifying triangle's filter, :func:`filter_band`
  applies it to a band's pixels; a band filters a level over the window its probes
  reach, until the level is worth building whole.

  Why so: a Gaussian pyramid (``cv2.pyrDown``) sampled with linear probes,
  trilinearly between octaves, from a minification of 1.1 on, gave a shrink by 0.5 a
  seventh of the detail (Laplacian variance) of ImageMagick's ``-resize`` and lost
  three fifths of it from 0.91 to 0.909. Eighth-octave Lanczos levels keep a shrink as
  sharp as ``-resize -filter Catrom`` or sharper, alias about as ImageMagick's
  ``-distort`` (EWA), and cost one separable filter per level used (8-bit 12 MP: 20 ms
  of CPU); the samples cost what ``--interp`` costs.
* **Coverage.** Pixels within half a pixel of the mesh's outer boundary
  (:class:`Silhouette`) get a fractional coverage ``0.5 + d`` inside and
  ``0.5 - d`` outside (``d`` the distance from the pixel centre to the
  boundary, i.e. a one-pixel box feather), which becomes partial alpha on a
  transparent canvas or a blend with the background colour, instead of a
  binary staircase. A pixel whose centre falls just outside takes the colour
  of the nearest boundary point.

Which triangles minify, the probes' positions and their weighted sums are computed in
the compiled module :mod:`featurewarp_cli.render._raster`; the footprints' filters
with numpy (basic operations only, so that no libm difference moves a level); the
levels with :func:`cv2.sepFilter2D` and the samples with :func:`cv2.remap`.
"""

from __future__ import annotations

import cv2
import numpy as np

from . import _raster
from .pyramid import COMPACT_WIDTH, LEVEL_SCALES, LEVELS_PER_OCTAVE, Pyramid, _to_level

#: Minification (largest singular value of J) from which a pixel is filtered.
AA_START = 1.1
#: Share of each end of the interval between two levels' scales where one level is used
#: alone (between, the blend goes from one to the other): fewer pixels sample two levels.
BLEND_MARGIN = 0.25
#: Most probes on each side of the centre along a footprint's major axis.
AA_MAX_STEPS = 4
#: The tent along a footprint's major axis has radius TENT_REACH sqrt(m1^2 - (AA_START m2)^2):
#: a grating of 0.4 cycles a pixel shrunk 2:1 along one axis keeps 0.14 of its contrast (plain: all).
TENT_REACH = 1.2
#: Footprints from this size on (NaN, overflow) are not filtered.
LARGEST_FOOTPRINT = 2.0 ** 60
#: Columns of J in a triangle's record (raster.Triangles.FIELDS j00, j01, j10, j11).
J_COLUMNS = slice(8, 12)


class Footprints:
    """The filter of each minifying triangle among a band's triangles.

    Parameters
    ----------
    records : (n, 16) float64 ndarray
        The triangles' records (:meth:`featurewarp_cli.render.raster.Triangles.records`);
        only their J is read.
    threshold : float
        Largest singular value of J from which a triangle minifies.
    top_level : int
        The highest pyramid level (:attr:`Pyramid.top_level`): coarser footprints use it.

    Attributes
    ----------
    index : (n,) int32 ndarray
        The minifying triangles numbered 0, 1, ...; -1 for the others (and for those whose
        filter is a single probe on level 0: the plain sample).
    ints : (m, 3) int32 ndarray
        Per minifying triangle: probes per side k, pyramid level ``b``, and whether
        level ``b + 1`` is blended in.
    floats : (m, 3) float32 ndarray
        Per minifying triangle: the source offset between two probes (x, y), along
        J's major left singular vector, and the weight of level ``b + 1``.
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

    def __init__(self, records: np.ndarray, threshold: float = AA_START, top_level: int = 1 << 20):
        n = records.shape[0]
        self.index = np.empty(n, np.int32)
        ints, floats = np.empty((n, 3), np.int32), np.empty((n, 3), np.float32)
        count, _ = _raster.footprints(records, threshold, AA_MAX_STEPS, LARGEST_FOOTPRINT,
                                      self.index, ints, floats)
        minifying = self.index >= 0
        self.max_level = footprint_filters(records[minifying, J_COLUMNS], top_level, ints[:count], floats[:count])
        kept = (ints[:count, 0] > 1) | (ints[:count, 1] > 0) | (ints[:count, 2] > 0)
        self.index[minifying] = np.where(kept, np.cumsum(kept) - 1, -1)   # no filter: the plain sample
        self.ints, self.floats = ints[:count][kept], floats[:count][kept]


def footprint_filters(jacobians: np.ndarray, top_level: int, ints: np.ndarray, floats: np.ndarray) -> int:
    """Write the filters of minifying Jacobians (see :class:`Footprints`); return the top level used.

    ``J = R(theta) diag(s1, s2) R(phi)^T``: with ``u1 + i v1 = (s1 + s2) e^{i (theta + phi)}``
    and ``u2 + i v2 = (s1 - s2) e^{i (theta - phi)}``, ``s1, s2`` are the half sum and
    difference of their moduli ``p, q``, and the major axis ``e^{i theta}`` points along
    ``(|w| + Re w, Im w)``, or ``(Im w, |w| - Re w)`` when ``Re w < 0``, with
    ``w = (u1 + i v1)(u2 + i v2)`` (the compiled footprints' formulas). Only ``+ - * /``,
    sqrt, floor, ceil and frexp are used: the same bits on every machine.

    Parameters
    ----------
    jacobians : (m, 4) float64 ndarray
        ``j00, j01, j10, j11`` of each minifying triangle.
    top_level : int
        Highest level to use.
    ints : (m, 3) int32 ndarray
    floats : (m, 3) float32 ndarray
        Written: as :attr:`Footprints.ints` and :attr:`Footprints.floats`.
    """
    if jacobians.shape[0] == 0:
        return 0
    a, b, c, d = jacobians.T
    u1, v1, u2, v2 = a + d, c - b, a - d, c + b
    p, q = np.sqrt(u1 * u1 + v1 * v1), np.sqrt(u2 * u2 + v2 * v2)
    slack = AA_START * AA_START - 1.0            # the interpolation's own reach, in quadrature
    s1, s2 = (p + q) / 2.0, np.abs(p - q) / 2.0
    m1 = np.sqrt(np.maximum(s1 * s1 - slack, 1.0))
    # beyond AA_MAX_STEPS probes m2 apart, a coarser level (m2 grows)
    reach, start = TENT_REACH, AA_START
    m2 = np.maximum(np.sqrt(np.maximum(s2 * s2 - slack, 1.0)),
                    reach * m1 / np.sqrt(AA_MAX_STEPS ** 2 + (reach * start) ** 2))
    radius = reach * np.sqrt(np.maximum(m1 * m1 - (start * m2) ** 2, 0.0))    # none below m1 = AA_START m2
    k = np.where(radius < 1e-3, 1, np.clip(np.ceil(radius / m2 - 1e-9), 2, AA_MAX_STEPS))
    wr, wi, modulus = u1 * u2 - v1 * v2, u1 * v2 + v1 * u2, p * q
    ax, ay = np.where(wr >= 0, modulus + wr, wi), np.where(wr >= 0, wi, modulus - wr)
    norm = np.sqrt(ax * ax + ay * ay)
    flat = ~(norm > 0)                                       # isotropic: any axis
    ax, ay, norm = np.where(flat, 1.0, ax), np.where(flat, 0.0, ay), np.where(flat, 1.0, norm)
    spacing = radius / k / norm
    base, frac = pyramid_level(m2, top_level)
    ints[:, 0], ints[:, 1], ints[:, 2] = k, base, frac > 1e-4
    floats[:, 0], floats[:, 1], floats[:, 2] = spacing * ax, spacing * ay, frac
    return int((ints[:, 1] + ints[:, 2]).max())


def pyramid_level(m2: np.ndarray, top_level: int) -> tuple[np.ndarray, np.ndarray]:
    """The level ``b`` for footprints ``m2`` (>= 1) and the weight of level ``b + 1``.

    ``b`` is the level whose scale (:data:`LEVEL_SCALES`, times 2 an octave) is the
    largest below ``m2``; the weight of ``b + 1`` rises linearly in ``m2`` from 0 to 1
    over the middle of the interval between their scales (:data:`BLEND_MARGIN` of it at
    each end has one level alone), near 1 it is ``b + 1`` alone; ``b`` at most
    ``top_level`` (then with weight 0).
    """
    mantissa, exponent = np.frexp(m2)                        # m2 = 2 x 2^(exponent - 1), x in [1, 2)
    x = 2.0 * mantissa
    r = np.searchsorted(LEVEL_SCALES, x, side="right") - 1
    lo, hi = LEVEL_SCALES[r], LEVEL_SCALES[r + 1]
    base = (exponent.astype(np.int64) - 1) * LEVELS_PER_OCTAVE + r
    frac = np.clip(((x - lo) / (hi - lo) - BLEND_MARGIN) / (1.0 - 2.0 * BLEND_MARGIN), 0.0, 1.0)
    up = frac > 1.0 - 1e-4                                   # all on b + 1: that level alone
    base, frac = np.where(up, base + 1, base), np.where(up, 0.0, frac)
    top = base >= top_level
    return np.where(top, top_level, base), np.where(top, 0.0, frac)


def _alone(aatri: np.ndarray, ints: np.ndarray):
    """``alone(level)``: per probe of ``level`` (in aa_probes' order), whether its pixel has it
    alone (no tent along a major axis)."""
    tri = aatri[aatri >= 0]
    k, base, blend = ints[tri, 0], ints[tri, 1], ints[tri, 2] > 0
    return lambda level: np.repeat(k == 1, 2 * k - 1)[np.repeat((base == level) | (blend & (base + 1 == level)),
                                                                2 * k - 1)]


def filter_band(pyramid: Pyramid, foot: Footprints, aatri: np.ndarray, bx: np.ndarray, by: np.ndarray,
                flat: np.ndarray, scratch, interp: int = cv2.INTER_CUBIC) -> None:
    """Write the filtered value of a band's minified pixels.

    Each pixel averages 2k-1 probes ``j * step`` (j = -(k-1) .. k-1, tent
    weights) around its source position along its footprint's major axis, on
    pyramid level b and, blended in with its weight, b + 1. The probes of each
    level are laid out in one (rows, :data:`COMPACT_WIDTH`) map for one
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
    interp : int
        The cv2 interpolation the levels are sampled with (the user's; INTER_LANCZOS4 samples
        the probes of tents, ``k > 1``, with INTER_CUBIC).
    """
    counts = np.zeros(foot.max_level + 2, np.int64)
    _raster.aa_count(aatri, foot.ints, counts)
    offsets = np.zeros(counts.size + 1, np.int64)
    np.cumsum(-(-counts // COMPACT_WIDTH) * COMPACT_WIDTH, out=offsets[1:])
    px, py = scratch("px", offsets[-1], np.float32), scratch("py", offsets[-1], np.float32)
    _raster.aa_probes(aatri, bx, by, foot.ints, foot.floats, offsets, px, py)
    image = pyramid[0]
    channels = 1 if image.ndim == 2 else image.shape[2]
    used = np.flatnonzero(counts)
    for level in used:                       # the padding after a level's probes: its first probe
        a, b = offsets[level], offsets[level + 1]
        px[a + counts[level]:b], py[a + counts[level]:b] = px[a], py[a]
        if level > 0:
            _to_level(px[a:b], py[a:b], int(level))
    alone = _alone(aatri, foot.ints) if interp == cv2.INTER_LANCZOS4 else None
    if used.size == 1 and alone is None:     # one level: its samples are all of them (no copy)
        samples = pyramid.sample(int(used[0]), px, py, interp)
    else:
        samples = np.empty((offsets[-1], channels), image.dtype)
        for level in used:
            a, b = offsets[level], offsets[level + 1]
            if alone is None:
                samples[a:b] = pyramid.sample(int(level), px[a:b], py[a:b], interp)
                continue
            single = alone(level)            # Lanczos for a probe alone, cubic for the tents' probes
            for pick, flag in ((np.flatnonzero(single), interp), (np.flatnonzero(~single), cv2.INTER_CUBIC)):
                if pick.size:
                    samples[a + pick] = pyramid.sample(int(level), px[a + pick], py[a + pick], flag)
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

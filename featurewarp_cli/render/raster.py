"""Forward mesh -> inverse map (rasterized deformed triangles) -> resampled image.

:func:`render` is the whole stage: it walks the output canvas in bands of rows,
rasterizes the deformed triangles that reach each band into float32 maps of
source positions, resamples the band with :func:`cv2.remap` and writes it into
the output, so that no full-canvas map is ever held. On the way it prefilters
where the warp shrinks the image and feathers the mesh's silhouette (see
:mod:`featurewarp_cli.render.antialias`). :func:`inverse_map` and
:func:`resample` are the two halves without antialiasing, kept for callers that
want the map itself.

An image with alpha that is not wholly opaque is resampled premultiplied (its colour times
its alpha, 16-bit), so that the colour under transparent pixels stays out of the edges.

Each pixel centre inside a deformed triangle gets the affine interpolation of
that triangle's source corners. Shared edges are computed identically by both
triangles, so there are no cracks; where two triangles claim a pixel (an edge
through its centre, or a fold) the later one in rasterizing order (triangles
stably sorted by first row) wins, in :func:`render` and :func:`inverse_map`
alike.

The per-triangle and per-pixel loops (triangle setup, scanline filling, the
filter's footprints, probes and sums) are the compiled module
:mod:`featurewarp_cli.render._raster`, which ``pip install`` builds (a C
compiler is required). The tests check it against a plain barycentric
rasterizer and numpy's SVD (``tests/reference_render.py``).
"""

from __future__ import annotations

import os
import sys
import threading
from concurrent.futures import ThreadPoolExecutor

import cv2
import numpy as np

from . import _raster
from .antialias import Footprints, Silhouette, filter_band
from .pyramid import COMPACT_WIDTH, Pyramid, sample_points
from .remap import remap

INTERPOLATION = {"nearest": cv2.INTER_NEAREST, "linear": cv2.INTER_LINEAR, "cubic": cv2.INTER_CUBIC,
                 "lanczos": cv2.INTER_LANCZOS4}

#: Output pixels per band (rows are grouped so that a band holds about this many).
BAND_PIXELS = 1 << 18
#: Bands rendered at once (the compiled loops and OpenCV release the GIL).
#: 12 MP at cell 4 (swirl 180) on the 2-core machine takes about 0.5 s of CPU
#: antialiased; two threads bring it to about 0.3 s. The output does not depend on it.
THREADS = min(2, os.cpu_count() or 1)


class Triangles:
    """The triangles of a mesh that reach the canvas, in rasterizing order.

    The non-degenerate triangles that reach the canvas (``index`` into the
    mesh's triangles), stably sorted by first row, with their first and last
    rows (``ylo``, ``yhi``) and nodes (``corners``). :meth:`records` gives
    their scanline bounds and inverse affine maps, a range at a time.

    Parameters
    ----------
    source, target : (N, 2) ndarray
        Node positions in the input image and on the canvas.
    triangles : (M, 3) ndarray of int
        Node indices (any strides).
    canvas : (int, int)
        Output (width, height).
    """

    #: Columns of :meth:`records`: the two lower and two upper x-bounds ``k + m y`` of a
    #: triangle's interior on a row, its inverse map ``source = s0 + J (p - p0)``.
    FIELDS = ("lk0", "lm0", "lk1", "lm1", "uk0", "um0", "uk1", "um1",
              "j00", "j01", "j10", "j11", "px0", "py0", "sx0", "sy0")
    J = slice(8, 12)

    def __init__(self, source, target, triangles, canvas):
        self.canvas = width, height = tuple(int(c) for c in canvas)
        self.target = np.ascontiguousarray(target, dtype=np.float64).reshape(-1, 2)
        self.source = np.ascontiguousarray(source, dtype=np.float64).reshape(-1, 2)
        triangles = np.asarray(triangles, dtype=np.int64).reshape(-1, 3)     # any strides
        m = triangles.shape[0]
        index, ylo, yhi = np.empty(m, np.int64), np.empty(m, np.int64), np.empty(m, np.int64)
        corners = np.empty((m, 3), np.int32)
        self.count = _raster.triangles(self.target, triangles, width, height, index, ylo, yhi, corners)
        self.index, self.ylo, self.yhi = index[:self.count], ylo[:self.count], yhi[:self.count]
        self.corners = corners[:self.count]
        self.tallest = int((self.yhi - self.ylo).max()) if self.count else 0

    def in_rows(self, y0: int, y1: int) -> np.ndarray:
        """(n,) int64: the triangles (numbered in rasterizing order) with a row in [y0, y1)."""
        a = int(np.searchsorted(self.ylo, y0 - self.tallest, side="left"))
        b = int(np.searchsorted(self.ylo, y1 - 1, side="right"))
        return a + np.flatnonzero(self.yhi[a:b] >= y0)

    def records(self, sel: np.ndarray, out: np.ndarray | None = None) -> np.ndarray:
        """(len(sel), 16) float64: the :data:`FIELDS` of triangles ``sel``, in ``out`` (an
        array of at least that many float64) if given."""
        size = (sel.size, len(self.FIELDS))
        rec = np.empty(size) if out is None else out[:size[0] * size[1]].reshape(size)
        _raster.records(self.target, self.source, self.corners, *self.canvas, sel, rec)
        return rec


def inverse_map(source: np.ndarray, target: np.ndarray, triangles: np.ndarray,
                canvas: tuple[int, int]) -> tuple[np.ndarray, np.ndarray]:
    """Source position of every canvas pixel, by rasterizing the deformed triangles.

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
    tris = Triangles(source, target, triangles, canvas)
    for a in range(0, tris.count, 1 << 16):        # in order, a bounded number of records at a time
        sel = np.arange(a, min(tris.count, a + (1 << 16)))
        _raster.rasterize(tris.records(sel), tris.ylo[sel], tris.yhi[sel], 0, height, width,
                          mapx, mapy, None, None)
    covered = mapx > -0.75
    coords = np.stack([mapx, mapy], axis=1).reshape(height, width, 2)
    return coords, covered.reshape(height, width)


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


class _BandRenderer:
    """Renders :func:`render`'s output one band of rows at a time (from several threads).

    Calling it with a band's first row fills those rows of ``out`` and returns
    whether they all came out opaque. ``fill`` is the background as a float64
    pixel (None: transparent); ``holes`` (a dict, when alpha is added only
    after the fact) collects each band's uncovered pixels.
    """

    def __init__(self, image, tris, silhouette, out, interp, fill, rows, holes, antialias):
        self.image, self.tris, self.silhouette, self.out = image, tris, silhouette, out
        self.flag = INTERPOLATION[interp]
        self.fill, self.rows, self.holes, self.antialias = fill, rows, holes, antialias
        self.channels = 1 if image.ndim == 2 else image.shape[2]
        self.out_channels = 1 if out.ndim == 2 else out.shape[2]
        self.pyramid = Pyramid(image)
        self.scratch = _Scratch()
        self.premultiplied = False

    def __call__(self, y0: int) -> bool:
        height, width = self.out.shape[:2]
        y1 = min(height, y0 + self.rows)
        bx, by, foot, aatri, marked = self._rasterize(y0, y1, width)
        coverage = self._coverage(bx, by, y0, y1, width)
        band = self.out[y0:y1]
        flat = band.reshape(bx.size, self.out_channels)
        if self.out_channels != self.channels:
            band[..., 3] = np.iinfo(band.dtype).max
        self._sample(bx, by, aatri, marked, band, flat)
        if marked:
            filter_band(self.pyramid, foot, aatri, bx, by, flat, self.scratch, self.flag)
        if self.premultiplied:
            straighten(flat)
        return True if coverage is None else self._apply_coverage(coverage, flat, y0)

    def _rasterize(self, y0: int, y1: int, width: int):
        """The band's source positions ``bx``, ``by`` (flat, -1 where uncovered); with
        antialiasing also the footprints of its triangles, the number of the minifying
        triangle on each pixel (``aatri``, -1: none) and how many pixels have one."""
        size = (y1 - y0) * width
        bx, by = self.scratch("bx", size, np.float32), self.scratch("by", size, np.float32)
        bx.fill(-1.0)
        by.fill(-1.0)
        sel = self.tris.in_rows(y0, y1)
        rec = self.tris.records(sel, self.scratch("rec", sel.size * len(Triangles.FIELDS), np.float64))
        foot = Footprints(rec, top_level=self.pyramid.top_level) if self.antialias and sel.size else None
        aatri = None
        if foot is not None:
            aatri = self.scratch("aatri", size, np.int32)
            aatri.fill(-1)
        marked = _raster.rasterize(rec, self.tris.ylo[sel], self.tris.yhi[sel], y0, y1, width, bx, by,
                                   None if foot is None else foot.index, aatri)
        return bx, by, foot, aatri, marked

    def _coverage(self, bx, by, y0: int, y1: int, width: int) -> np.ndarray | None:
        """Coverage of the band's pixels (None: all 1): 0 where no triangle holds the pixel
        centre, ``0.5 +- d`` within half a pixel of the silhouette, where the pixels
        outside take the source position of the nearest boundary point (in ``bx``, ``by``)."""
        uncovered = np.flatnonzero(bx < -0.75)
        near = np.zeros(0, np.int64)
        if self.silhouette is not None:
            near, dist, src = self.silhouette.band(y0, y1, width)
        if not (uncovered.size or near.size):
            return None
        coverage = np.ones(bx.size, np.float32)
        coverage[uncovered] = 0.0
        if near.size:
            inside = bx[near] > -0.75
            coverage[near] = np.where(inside, 0.5 + dist, 0.5 - dist)
            outside = ~inside
            bx[near[outside]] = src[outside, 0]
            by[near[outside]] = src[outside, 1]
        return coverage

    def _sample(self, bx, by, aatri, marked: int, band, flat) -> None:
        """The plain cv2.remap samples of the band; only of the pixels that the filter
        leaves when it takes most of the band."""
        width = band.shape[1]
        if marked > bx.size // 4:
            px = self.scratch("px", bx.size + COMPACT_WIDTH, np.float32)
            py = self.scratch("py", bx.size + COMPACT_WIDTH, np.float32)
            n = _raster.gather(aatri, bx, by, px, py)
            if n:
                m = -(-n // COMPACT_WIDTH) * COMPACT_WIDTH
                px[n:m] = py[n:m] = 0.0
                values = sample_points(self.image, px[:m], py[:m], self.flag)[:n]
                _raster.scatter(aatri, values, self.channels, flat, self.out_channels)
        elif self.out_channels == self.channels:
            remap(self.image, bx.reshape(-1, width), by.reshape(-1, width), self.flag, dst=band)
        else:
            out = remap(self.image, bx.reshape(-1, width), by.reshape(-1, width), self.flag)
            band[..., :3] = out[..., None] if self.channels == 1 else out

    def _apply_coverage(self, coverage, flat, y0: int) -> bool:
        """Partial coverage into alpha, or a blend with the background; returns whether
        the band stays opaque."""
        partial = np.flatnonzero(coverage < 1.0)
        cov = coverage[partial][:, None].astype(np.float64)
        dtype = flat.dtype
        if self.fill is not None:
            values = flat[partial].astype(np.float64)
            if self.out_channels == 4:        # over an opaque fill, weighted by the pixel's own alpha too
                top = float(np.iinfo(dtype).max)
                alpha = values[:, 3:] / top * cov
                values[:, 3:] = (alpha + (1.0 - cov)) * top
                values[:, :3] = ((values[:, :3] * alpha + self.fill[None, :3] * (1.0 - cov))
                                 / np.maximum(alpha + (1.0 - cov), 1e-12))
                flat[partial] = np.rint(values).astype(dtype)
                return True
            flat[partial] = np.rint(values * cov + self.fill[None, :] * (1.0 - cov)).astype(dtype)
            return True
        if self.out_channels == 4:          # opaque still where every alpha rounds to the top
            alpha = flat[partial, 3].astype(np.float64)
            flat[partial, 3] = np.rint(alpha * cov[:, 0]).astype(dtype)
            flat[partial[cov[:, 0] <= 0]] = 0
            return bool(np.all(flat[partial, 3] == np.iinfo(dtype).max))
        flat[partial[cov[:, 0] <= 0]] = 0             # no alpha (yet): uncovered pixels become 0
        if self.holes is not None:
            self.holes[y0] = partial
        return True


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
    interp : {'nearest', 'linear', 'cubic', 'lanczos'}
    background : (r, g, b) tuple of 0..255, or None
        Fill colour where no triangle lands; None means transparent (an alpha
        channel is added when the image has none and some pixel is not fully
        covered).
    antialias : bool
        Prefilter where the map shrinks the image and feather the mesh's
        silhouette (default). False gives exactly ``resample(image,
        *inverse_map(...))``, but for an image with alpha that is not wholly
        opaque, which is resampled premultiplied (:func:`premultiply`).
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
    if image.ndim == 3 and image.shape[2] == 2:     # gray + alpha: as BGRA, for the silhouette's alpha
        return _gray_alpha(image, (source, target, triangles, canvas, interp, background), antialias, band_pixels,
                           threads)
    if image.dtype not in (np.uint8, np.uint16):
        raise ValueError(f"image must be uint8 or uint16, not {image.dtype}")
    width, height = (int(c) for c in canvas)
    given, (image, premultiplied) = image.dtype, premultiply(image) if interp != "nearest" else (image, False)
    with ThreadPoolExecutor(1) as helper:       # the silhouette's setup beside the triangles'
        silhouette = helper.submit(Silhouette, source, target, triangles) if antialias else None
        tris = Triangles(source, target, triangles, (width, height))
        silhouette = silhouette.result() if antialias else None
    channels = 1 if image.ndim == 2 else image.shape[2]
    # Alpha is added up front when the background is transparent and some pixel may be
    # less than fully covered. Without antialiasing a pixel is covered or not: render
    # without alpha, note the uncovered pixels (holes) and add alpha at the end if any.
    maybe_partial = silhouette is None or silhouette.inside_canvas(width, height) or tris.count == 0
    add = background is None and channels in (1, 3) and maybe_partial
    holes = {} if add and silhouette is None else None
    add = add and holes is None
    out_channels = 4 if add else channels
    out = np.empty((height, width) if out_channels == 1 else (height, width, out_channels), image.dtype)
    fill = None if background is None else np.array(fill_value(background, out), dtype=np.float64)
    rows = max(1, min(height, (band_pixels or BAND_PIXELS) // max(width, 1)))
    bands = _BandRenderer(image, tris, silhouette, out, interp, fill, rows, holes, antialias)
    bands.premultiplied = premultiplied
    starts = range(0, height, rows)
    workers = min(threads if threads is not None else THREADS, len(starts))
    if workers > 1:
        with ThreadPoolExecutor(workers) as pool:
            all_opaque = all(list(pool.map(bands, starts)))
    else:
        all_opaque = all([bands(y0) for y0 in starts])
    if add and all_opaque:
        out = np.ascontiguousarray(out[:, :, :channels] if channels > 1 else out[:, :, 0])
    if holes:
        out = add_alpha(out)
        for y0, pixels in holes.items():
            out.reshape(-1, 4)[y0 * width + pixels] = 0
    return _zero_under_transparent(cv2.convertScaleAbs(out, alpha=1 / 257) if out.dtype != given else out)


def _zero_under_transparent(out: np.ndarray) -> np.ndarray:
    """``out`` with the colour of every pixel whose alpha is 0 set to 0 (in place), as the
    README promises: a sliver of a triangle's coverage, or a premultiplied 16-bit alpha under
    half a level, rounds the alpha to 0 and left the colour (3 pixels of a 976 x 538 arc)."""
    if out.ndim != 3 or out.shape[2] not in (2, 4):
        return out
    bits = 8 * out.dtype.itemsize * out.shape[2]
    packed = out.dtype.kind == "u" and out.dtype.isnative and out.flags.c_contiguous and bits in (16, 32, 64)
    if packed and sys.byteorder == "little":
        # One pixel as one unsigned integer, its alpha the top bits: 0.19 s -> 0.01 s at 15 MP
        pixels = out.view(f"<u{bits // 8}").reshape(out.shape[:2])
        np.copyto(pixels, 0, where=pixels < 1 << (bits - 8 * out.dtype.itemsize))
    else:
        np.copyto(out[:, :, :-1], 0, where=out[:, :, -1:] == 0)
    return out


def _gray_alpha(image: np.ndarray, args: tuple, antialias: bool, band_pixels, threads) -> np.ndarray:
    """:func:`render` of a gray + alpha ``image`` (``args``: its other positional arguments) as
    BGRA, given back as gray + alpha (a fill's gray is its luma)."""
    bgra = render(cv2.merge([image[:, :, 0]] * 3 + [image[:, :, 1]]), *args, antialias=antialias,
                  band_pixels=band_pixels, threads=threads)
    return np.dstack([cv2.cvtColor(np.ascontiguousarray(bgra[:, :, :3]), cv2.COLOR_BGR2GRAY), bgra[:, :, 3]])


def _opaque(image: np.ndarray) -> bool:
    """Whether an image's last channel (its alpha) is its dtype's largest value everywhere."""
    return bool(np.all(image[:, :, -1] == np.iinfo(image.dtype).max))


def premultiply(image: np.ndarray) -> tuple[np.ndarray, bool]:
    """An image with alpha, its colour multiplied by its alpha, for resampling.

    Resampling then weighs a pixel's colour by how opaque it is, so the colour under alpha 0
    (often black, or a painter's leftovers) counts for nothing; resampled straight, it made a
    dark or coloured fringe along a cut-out's edges. :func:`straighten` undoes it.

    Parameters
    ----------
    image : (h, w) or (h, w, C) ndarray, uint8 or uint16
        BGRA (C = 4) is premultiplied unless wholly opaque (:func:`render` gives gray + alpha as BGRA).

    Returns
    -------
    image : ndarray
        16-bit where it was premultiplied (8-bit samples times 257, so that colours at low
        alpha keep their precision); else ``image`` itself.
    done : bool
        Whether it was premultiplied.
    """
    if image.ndim != 3 or image.shape[2] != 4 or _opaque(image):
        return image, False
    wide = image.astype(np.uint16) * np.uint16(257) if image.dtype == np.uint8 else image.copy()
    alpha = np.ascontiguousarray(wide[:, :, -1])
    colour = cv2.multiply(np.ascontiguousarray(wide[:, :, :3]), cv2.merge([alpha] * 3), scale=1 / 65535)
    return np.concatenate([colour, alpha[:, :, None]], axis=2), True


def straighten(flat: np.ndarray) -> None:
    """Divide premultiplied 16-bit pixels ((n, C), alpha last; in place) by their alpha
    (:func:`premultiply`): 0 where the alpha is, clipped where an interpolation's overshoot
    left the colour above it."""
    alpha = flat[:, -1:].astype(np.float32)
    colour = flat[:, :-1] * (np.float32(65535) / np.maximum(alpha, 1))
    flat[:, :-1] = np.where(alpha > 0, np.minimum(np.rint(colour), 65535), 0)


# --------------------------------------------------------------------------- resample

def resample(image: np.ndarray, coords: np.ndarray, covered: np.ndarray,
             interp: str = "cubic", background=None) -> np.ndarray:
    """Sample ``image`` at ``coords``; fill uncovered pixels with ``background``.

    Parameters
    ----------
    image : (h, w) or (h, w, C) ndarray, uint8 or uint16
    coords, covered : as returned by :func:`inverse_map`
    interp : {'nearest', 'linear', 'cubic', 'lanczos'}
    background : (r, g, b) tuple of 0..255, or None
        Fill colour where no triangle lands; None means transparent (an alpha
        channel is added when the image has none and some pixel is uncovered).

    Returns
    -------
    ndarray
        Same dtype as ``image``; same channels, plus alpha where needed.
    """
    out = remap(image, np.ascontiguousarray(coords[..., 0]), np.ascontiguousarray(coords[..., 1]),
                INTERPOLATION[interp])
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


def under_colour(image: np.ndarray, rgba) -> np.ndarray:
    """A BGR(A) or grey image with a translucent (r, g, b, a) colour (0..255) laid under it
    (Porter-Duff "over"): what was transparent becomes the colour, partly covered pixels
    blend, opaque ones stay. Returns BGRA of the image's dtype."""
    image = add_alpha(image)
    top = float(np.iinfo(image.dtype).max)
    alpha = image[..., 3:].astype(np.float64) / top
    colour = np.array([rgba[2], rgba[1], rgba[0]], np.float64) * top / 255
    under = rgba[3] / 255 * (1 - alpha)
    out_alpha = alpha + under
    rgb = (image[..., :3] * alpha + colour * under) / np.maximum(out_alpha, 1e-12)
    return np.round(np.concatenate([rgb, out_alpha * top], axis=2)).astype(image.dtype)

"""The minification filter's pyramid (:mod:`featurewarp_cli.render.antialias`): levels of
the source eighth of an octave apart, built exactly, whole or in windows, and sampled.

Level ``8 o + r`` is octave ``o`` (the source halved ``o`` times by a Lanczos-3 kernel,
:data:`HALVING_TAPS`) low-passed by the Lanczos-3 kernel ``SUBLEVEL_TAPS[r - 1]`` to
``2^(-r/8)`` of its band (``r > 0``; the same size as its octave). The kernels' taps are
integers, so that every sum is exact and the bytes do not depend on the machine.
"""

from __future__ import annotations

import threading
import weakref

import cv2
import numpy as np

from .remap import KERNEL_REACH, remap

#: Pyramid levels an octave, and the footprint (source pixels) each level of an octave
#: is made for: 2^(r/8), exactly the scales the kernels of SUBLEVEL_TAPS were made with.
LEVELS_PER_OCTAVE = 8
LEVEL_SCALES = np.array([1.0, 1.0905077326652577, 1.189207115002721, 1.2968395546510096, 1.4142135623730951,
                         1.5422108254079407, 1.681792830507429, 1.8340080864093424, 2.0])
#: Lanczos-3 low-pass kernels (centre tap, then outwards; integers summing to
#: 2^TAP_BITS) with cutoff 2^(-r/8) of the band, for levels r = 1 .. 7 of an octave.
SUBLEVEL_TAPS = ((118, 9, -5, 1), (108, 17, -10, 3), (100, 24, -13, 3), (90, 30, -13, 2), (84, 34, -12, -1, 1),
                 (76, 37, -9, -4, 2), (70, 38, -5, -7, 2, 1))
#: Lanczos-3 at half the band for halving: taps at +-0.5, +-1.5, ... from the new pixel's
#: centre (level pixel i sits on source 2i + 0.5, as cv2.resize places it).
HALVING_TAPS = (57, 17, -9, -4, 2, 1)
TAP_BITS = 7
#: A level within an octave is built whole (and kept) for a band whose probes reach this
#: share of it; below, just the window they reach is filtered for the band.
WHOLE_LEVEL_SHARE = 0.5
#: ... or once the windows filtered for it add up to this many times its size: a shrink's
#: bands filter each level about 1.3 times over in windows (their margins), and keep no
#: full-size copy (a 12 MP 16-bit RGBA image: 96 MB a level).
WINDOWS_PER_LEVEL = 2.0
#: Rows of a 16-bit level filtered at once hold about this many values (bounds the float64 buffers).
STRIPE_VALUES = 1 << 20
#: Width of the (rows, width) maps that :func:`sample_points` samples scattered points with.
COMPACT_WIDTH = 4096

def _separable(image: np.ndarray, taps: tuple, halve: bool) -> np.ndarray:
    """``image`` filtered along both axes by a symmetric integer kernel, every second
    pixel kept when ``halve`` (level pixel i on source 2i + 0.5).

    The kernel's taps (centre, then outwards; sum 2^TAP_BITS) make every sum an integer
    times 2^(-2 TAP_BITS) of fewer than 2^24 units for 8 bits (OpenCV's float32 buffers)
    and 2^53 for 16 bits (float64, in stripes of rows): exact, so that the bits do not
    depend on the machine, its SIMD or the threads. Borders are replicated.
    """
    taps = np.asarray(taps, np.float64) * 2.0 ** -TAP_BITS
    kernel = np.concatenate([taps[:0:-1], taps] if not halve else [taps[::-1], taps])
    if halve and (image.shape[0] % 2 or image.shape[1] % 2):       # a last pixel of its own
        image = cv2.copyMakeBorder(image, 0, image.shape[0] % 2, 0, image.shape[1] % 2, cv2.BORDER_REPLICATE)
    step = 2 if halve else 1
    if image.dtype == np.uint8:
        out = cv2.sepFilter2D(image, -1, kernel.astype(np.float32), kernel.astype(np.float32),
                              borderType=cv2.BORDER_REPLICATE)
        return np.ascontiguousarray(out[step - 1::step, step - 1::step]) if halve else out
    height = image.shape[0]
    out = np.empty((height // step, image.shape[1] // step) + image.shape[2:], image.dtype)
    one, reach = np.ones(1), kernel.size // 2 + 1
    stripe = max(2, STRIPE_VALUES // max(1, image[:1].size)) // 2 * 2
    for y0 in range(0, height, stripe):
        y1 = min(height, y0 + stripe)
        a, b = max(0, y0 - reach), min(height, y1 + reach)
        part = cv2.sepFilter2D(image[a:b], cv2.CV_64F, kernel, one, borderType=cv2.BORDER_REPLICATE)
        part = cv2.sepFilter2D(np.ascontiguousarray(part[:, step - 1::step]), cv2.CV_64F, one, kernel,
                               borderType=cv2.BORDER_REPLICATE)[y0 - a + step - 1:y1 - a:step]
        out[y0 // step:y1 // step] = np.clip(np.rint(part), 0, 65535).reshape(out[y0 // step:y1 // step].shape)
    return out


class Pyramid:
    """The filter's pyramid of the source: level ``8 o + r`` is octave ``o`` (the source
    halved ``o`` times, :data:`HALVING_TAPS`) low-passed by ``SUBLEVEL_TAPS[r - 1]``
    (``r > 0``; same size as its octave). Built on demand (thread-safe).

    Level ``l``'s pixel ``i`` sits on source ``(i + 0.5) 2^o - 0.5``, ``o = l // 8``;
    :attr:`top_level` is the first level of a 1 x 1 octave.
    """

    def __init__(self, image: np.ndarray):
        self.octaves = _ahead(image) or [image]
        self.levels = {0: image}
        self.spent = {}                      # pixels of each level filtered in windows so far
        self.lock = threading.Lock()
        self.top_level = LEVELS_PER_OCTAVE * max(1, int(max(image.shape[:2]) - 1).bit_length())

    def octave(self, o: int) -> np.ndarray:
        """The source halved ``o`` times (call with the lock held)."""
        while len(self.octaves) <= o:
            self.octaves.append(_separable(self.octaves[-1], HALVING_TAPS, True))
        return self.octaves[o]

    def __getitem__(self, level: int) -> np.ndarray:
        with self.lock:
            if level not in self.levels:
                o, r = divmod(level, LEVELS_PER_OCTAVE)
                self.levels[level] = (self.octave(o) if r == 0
                                      else _separable(self.octave(o), SUBLEVEL_TAPS[r - 1], False))
            return self.levels[level]

    def sample(self, level: int, px: np.ndarray, py: np.ndarray, interp: int) -> np.ndarray:
        """:func:`sample_points` of level ``level`` at ``(px, py)`` (its pixels).

        A level within an octave that is not built yet is filtered over the window the points
        reach only (plus the kernels' reach: the same values), unless that window is
        :data:`WHOLE_LEVEL_SHARE` of the octave or more, or the windows filtered so far add
        up to :data:`WINDOWS_PER_LEVEL` levels (then it is built whole and kept): a few pixels
        shrunk far, or a band's rows, do not cost a whole full-size level, nor its memory.
        """
        o, r = divmod(level, LEVELS_PER_OCTAVE)
        with self.lock:
            base = self.octave(o)
            image = base if r == 0 else self.levels.get(level)
        if image is None:
            height, width = base.shape[:2]
            reach, margin = KERNEL_REACH + 1, len(SUBLEVEL_TAPS[r - 1])
            with np.errstate(invalid="ignore"):
                x0, x1, y0, y1 = (int(np.clip(np.floor(v), 0, top)) for v, top in (
                    (np.nanmin(px) - reach, width - 1), (np.nanmax(px) + reach + 1, width),
                    (np.nanmin(py) - reach, height - 1), (np.nanmax(py) + reach + 1, height)))
            area = max(0, x1 - x0) * max(0, y1 - y0)
            with self.lock:                  # windows that add up to the level cost as much: build it
                self.spent[level] = spent = self.spent.get(level, 0) + area
            if area < WHOLE_LEVEL_SHARE * width * height and spent < WINDOWS_PER_LEVEL * width * height and area > 0:
                a0, b0 = max(0, x0 - margin), max(0, y0 - margin)
                part = _separable(base[b0:min(height, y1 + margin), a0:min(width, x1 + margin)],
                                  SUBLEVEL_TAPS[r - 1], False)[y0 - b0:y1 - b0, x0 - a0:x1 - a0]
                return sample_points(part, px - np.float32(x0), py - np.float32(y0), interp)
            image = self[level]
        return sample_points(image, px, py, interp)


#: Octaves that :func:`prepare` builds ahead (the halvings: the levels within an octave are
#: filtered in windows, as the bands need them).
AHEAD_OCTAVES = 3
_prepared: list = []            # [weak reference to the holder of prepare()'s octaves]; taken by Pyramid
_started = [None]               # id of the image a Pyramid was made of without them: its prepare() drops them
_prepared_lock = threading.Lock()


def prepare(image: np.ndarray, holder) -> None:
    """Build the first :data:`AHEAD_OCTAVES` octaves of ``image``'s pyramid now, kept as
    ``holder.octaves`` (the command line calls it from the decoding thread, which then has
    nothing to do while the mesh is solved, with its run's decoding as the holder: they go
    with it, whether the run renders, is refused or fails); the next :class:`Pyramid` made of
    this very array starts with them, unless one was made before they were ready. The octaves
    are the same bytes however they are made, so whether they are ready in time changes the
    render's time only (12 MP swirl 180: 0.08 s of its 0.4). Nothing for an image the renderer
    resamples otherwise (alpha: premultiplied; other dtypes)."""
    if image.dtype not in (np.uint8, np.uint16) or not (image.ndim == 2 or image.shape[2] == 3):
        return
    octaves = [image]
    try:
        for _ in range(AHEAD_OCTAVES):
            if max(octaves[-1].shape[:2]) <= 1:
                break
            octaves.append(_separable(octaves[-1], HALVING_TAPS, True))
    except Exception:                # (memory): only time was at stake, the render builds them
        return
    with _prepared_lock:
        if _started[0] == id(image):             # its render began without them (once: ids are reused)
            _started[0] = None
            return
        holder.octaves = (image, octaves)
        _prepared[:] = [weakref.ref(holder)]


def _ahead(image: np.ndarray) -> list | None:
    """The octaves :func:`prepare` built for ``image`` (the same array), once (None: none; a
    prepare() of it still running then drops its own)."""
    with _prepared_lock:
        holder = _prepared.pop()() if _prepared else None
        found = getattr(holder, "octaves", None)
        if holder is not None:
            holder.octaves = None
        if found is not None and found[0] is image:
            return list(found[1])
        _started[0] = id(image)
    return None


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


def _to_level(px: np.ndarray, py: np.ndarray, level: int) -> None:
    """Probes that the compiled aa_probes placed at ``source 2^-level`` moved (in place) to
    level ``level``'s pixels, ``(source + 0.5) 2^-o - 0.5`` (powers of two: one rounding)."""
    o = level // LEVELS_PER_OCTAVE
    scale, shift = np.float32(2.0 ** (level - o)), np.float32(0.5 * 2.0 ** -o - 0.5)
    for p in (px, py):
        p *= scale
        p += shift

"""Forward mesh -> inverse map (rasterized deformed triangles) -> resampled image."""

from __future__ import annotations

import cv2
import numpy as np

INTERPOLATION = {"linear": cv2.INTER_LINEAR, "cubic": cv2.INTER_CUBIC, "lanczos": cv2.INTER_LANCZOS4}

_CHUNK = 1 << 22          # candidate (triangle, pixel) pairs per vectorized batch
_EPS = 1e-7               # barycentric tolerance: shared edges belong to both triangles


def inverse_map(source: np.ndarray, target: np.ndarray, triangles: np.ndarray,
                canvas: tuple[int, int]) -> tuple[np.ndarray, np.ndarray]:
    """Source position of every canvas pixel, by rasterizing the deformed triangles.

    Each pixel centre inside a target triangle gets the barycentric interpolation
    of that triangle's source corners. Shared edges are tested with a small
    tolerance, so there are no cracks between triangles.

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
    coords = np.full((height * width, 2), -1.0, dtype=np.float32)
    covered = np.zeros(height * width, dtype=bool)

    p = target[triangles]                                       # (M, 3, 2)
    lo = np.ceil(p.min(axis=1)).astype(np.int64)
    hi = np.floor(p.max(axis=1)).astype(np.int64)
    lo = np.maximum(lo, 0)
    hi = np.minimum(hi, [width - 1, height - 1])
    box = np.maximum(hi - lo + 1, 0)
    e1, e2 = p[:, 1] - p[:, 0], p[:, 2] - p[:, 0]
    det = e1[:, 0] * e2[:, 1] - e1[:, 1] * e2[:, 0]
    box[np.abs(det) < 1e-12] = 0
    count = box[:, 0] * box[:, 1]
    keep = np.flatnonzero(count)
    if keep.size == 0:
        return coords.reshape(height, width, 2), covered.reshape(height, width)

    inv = 1.0 / det[keep]
    # Barycentric b1, b2 as affine functions of the pixel position: b = gx*x + gy*y + g0.
    b1 = np.stack([e2[keep, 1], -e2[keep, 0]], 1) * inv[:, None]
    b2 = np.stack([-e1[keep, 1], e1[keep, 0]], 1) * inv[:, None]
    p0 = p[keep, 0]
    b1 = np.column_stack([b1, -(b1 * p0).sum(1)])
    b2 = np.column_stack([b2, -(b2 * p0).sum(1)])
    s = source[triangles[keep]]
    s0, d1, d2 = s[:, 0], s[:, 1] - s[:, 0], s[:, 2] - s[:, 0]
    lo, box, count = lo[keep], box[keep], count[keep]

    ends = np.cumsum(count)
    bounds = np.searchsorted(ends, np.arange(_CHUNK, ends[-1] + _CHUNK, _CHUNK), side="right")
    start = 0
    for stop in np.unique(np.append(bounds, keep.size)):
        stop = max(stop, start + 1)
        if start >= keep.size:
            break
        _raster_chunk(slice(start, stop), lo, box, count, b1, b2, s0, d1, d2, width, coords, covered)
        start = stop
    return coords.reshape(height, width, 2), covered.reshape(height, width)


def _raster_chunk(sel, lo, box, count, b1, b2, s0, d1, d2, width, coords, covered):
    """Rasterize triangles ``sel`` into ``coords`` / ``covered`` (flat, in place)."""
    n = count[sel]
    tri = np.repeat(np.arange(sel.start, sel.stop), n)
    local = np.arange(n.sum()) - np.repeat(np.cumsum(n) - n, n)
    bw = box[tri, 0]
    x = (lo[tri, 0] + local % bw).astype(np.float64)
    y = (lo[tri, 1] + local // bw).astype(np.float64)
    u = b1[tri, 0] * x + b1[tri, 1] * y + b1[tri, 2]
    v = b2[tri, 0] * x + b2[tri, 1] * y + b2[tri, 2]
    inside = (u >= -_EPS) & (v >= -_EPS) & (u + v <= 1.0 + _EPS)
    tri, u, v = tri[inside], u[inside], v[inside]
    pixel = y[inside].astype(np.int64) * width + x[inside].astype(np.int64)
    coords[pixel] = s0[tri] + u[:, None] * d1[tri] + v[:, None] * d2[tri]
    covered[pixel] = True


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

"""``cv2.remap`` for images and maps of any size.

OpenCV's remap asserts that the source and the destination have fewer than 32767
(``SHRT_MAX``) pixels per side. :func:`remap` splits a larger destination into tiles
and gives each tile only the part of the source its map reaches (plus the reach of the
interpolation kernel), so the result is the same as one call would give.
"""

from __future__ import annotations

import cv2
import numpy as np

#: Largest side, source or destination, that one ``cv2.remap`` call accepts.
LIMIT = 32766
#: How far beyond a sample position the interpolation kernels read (Lanczos-4: 4 px).
KERNEL_REACH = 4


def remap(image: np.ndarray, mx: np.ndarray, my: np.ndarray, interp: int,
          dst: np.ndarray | None = None) -> np.ndarray:
    """``cv2.remap(image, mx, my, interp, borderMode=cv2.BORDER_REPLICATE)``, any size.

    Parameters
    ----------
    image : (h, w) or (h, w, C) ndarray
    mx, my : (H, W) float32 ndarray
        Source x and y of every destination pixel.
    interp : int
        A cv2 interpolation flag.
    dst : (H, W[, C]) ndarray, optional
        Where to write (returned).

    Returns
    -------
    (H, W[, C]) ndarray
    """
    if max(mx.shape) <= LIMIT and max(image.shape[:2]) <= LIMIT:
        out = cv2.remap(image, mx, my, interp, dst=dst, borderMode=cv2.BORDER_REPLICATE)
        if dst is not None and out is not dst and not np.shares_memory(out, dst):
            dst[...] = out
        return dst if dst is not None else out
    out = dst if dst is not None else np.empty(mx.shape + image.shape[2:], image.dtype)
    _tile(image, mx, my, interp, out)
    return out


def _halves(mx: np.ndarray):
    """The two halves of a map's index space along its longer side."""
    h, w = mx.shape
    if h >= w:
        return (slice(0, h // 2), slice(None)), (slice(h // 2, h), slice(None))
    return (slice(None), slice(0, w // 2)), (slice(None), slice(w // 2, w))


def _tile(image: np.ndarray, mx: np.ndarray, my: np.ndarray, interp: int, out: np.ndarray) -> None:
    """Fill ``out`` tile by tile: halve the destination until it and the source window its
    map reaches both fit one call."""
    height, width = image.shape[:2]
    if max(mx.shape) <= LIMIT:
        x0 = int(np.clip(np.floor(np.nanmin(mx)) - KERNEL_REACH, 0, width - 1))
        x1 = int(np.clip(np.ceil(np.nanmax(mx)) + KERNEL_REACH + 1, x0 + 1, width))
        y0 = int(np.clip(np.floor(np.nanmin(my)) - KERNEL_REACH, 0, height - 1))
        y1 = int(np.clip(np.ceil(np.nanmax(my)) + KERNEL_REACH + 1, y0 + 1, height))
        if (x1 - x0 <= LIMIT and y1 - y0 <= LIMIT) or mx.size == 1:
            window = image[y0:y1, x0:x1]
            out[...] = cv2.remap(window, np.ascontiguousarray(mx - x0, np.float32),
                                 np.ascontiguousarray(my - y0, np.float32), interp,
                                 borderMode=cv2.BORDER_REPLICATE).reshape(out.shape)
            return
    for part in _halves(mx):
        _tile(image, mx[part], my[part], interp, out[part])

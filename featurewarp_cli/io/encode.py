"""Encoding results: pixels -> the bytes of a PNG, JPEG, WebP, TIFF or BMP file.

Every format goes through OpenCV's encoder with every setting pinned, so that the
same pixels always give the same bytes. PNG: deflate level 1 with zlib's run-length
strategy and the Paeth filter on every row, the fastest of OpenCV's settings that keeps
photographs small (12 MP swirl output: 8.54 MB in 0.41 s; level 3 with adaptive filters:
9.61 MB in 0.93 s); flat graphics come out about 1.8x the size of level 3's (README,
"Dependencies").
"""

from __future__ import annotations

import cv2
import numpy as np

from . import ImageError
from .capture import captured_stderr
from .decode import gray_alpha_to_bgra
from .depth import to_eight_bit
from .formats import FORMATS

#: OpenCV encoder parameters by format name.
SETTINGS = {
    "png": [cv2.IMWRITE_PNG_COMPRESSION, 1, cv2.IMWRITE_PNG_STRATEGY, cv2.IMWRITE_PNG_STRATEGY_RLE,
            cv2.IMWRITE_PNG_FILTER, cv2.IMWRITE_PNG_FILTER_PAETH],
    "jpg": [cv2.IMWRITE_JPEG_QUALITY, 95, cv2.IMWRITE_JPEG_PROGRESSIVE, 0, cv2.IMWRITE_JPEG_OPTIMIZE, 0],
    # 101: lossless (libwebp may still clear the colour under fully transparent pixels)
    "webp": [cv2.IMWRITE_WEBP_QUALITY, 101],
    "tiff": [cv2.IMWRITE_TIFF_COMPRESSION, 5],                     # 5: LZW
    "bmp": [],
}


def flatten(image: np.ndarray, rgb=(255, 255, 255)) -> np.ndarray:
    """Composite a BGRA image over an opaque (r, g, b) colour (0..255); other images unchanged."""
    if image.ndim != 3 or image.shape[2] != 4:
        return image
    top = np.iinfo(image.dtype).max
    alpha = image[:, :, 3:].astype(np.float64) / top
    background = np.array(rgb[::-1], np.float64) * top / 255
    out = image[:, :, :3] * alpha + background * (1 - alpha)
    return np.round(out).astype(image.dtype)


def encode_image(image: np.ndarray, fmt: str, background=(255, 255, 255)) -> bytes:
    """Encode ``image`` as format ``fmt`` (a name of :data:`FORMATS`) with fixed settings.

    Parameters
    ----------
    image : (h, w) or (h, w, C) ndarray, uint8 or uint16, C in 1..4, BGR(A) channel order
        Gray + alpha (C = 2) is stored as BGRA.
    fmt : str
    background : (r, g, b)
        Colour that alpha is composited over for formats without alpha.

    Returns
    -------
    bytes
        The file; the same pixels always give the same bytes.

    Raises
    ------
    ImageError
        For samples other than uint8 and uint16, or more than 4 channels.
    """
    if image.dtype not in (np.uint8, np.uint16):
        raise ImageError(f"cannot encode {image.dtype} samples as {fmt}")
    if image.ndim == 3 and not 1 <= image.shape[2] <= 4:
        raise ImageError(f"cannot encode {image.shape[2]} channels as {fmt}")
    image = gray_alpha_to_bgra(image)
    if not FORMATS[fmt].alpha:
        image = flatten(image, background)
    if FORMATS[fmt].eight_bit:
        image = to_eight_bit(image)
    with captured_stderr():
        ok, buf = cv2.imencode(FORMATS[fmt].extension, image, SETTINGS[fmt])
    if not ok:
        raise ImageError(f"cannot encode the result as {fmt}")
    return buf.tobytes()

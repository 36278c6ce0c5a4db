"""Reading images and masks, parsing colours, and writing outputs atomically."""

from __future__ import annotations

import os
import tempfile

import cv2
import numpy as np

#: Output formats by extension: (OpenCV extension, has alpha, encoder parameters).
FORMATS = {
    ".png": (".png", True, [cv2.IMWRITE_PNG_COMPRESSION, 6]),
    ".jpg": (".jpg", False, [cv2.IMWRITE_JPEG_QUALITY, 95]),
    ".jpeg": (".jpg", False, [cv2.IMWRITE_JPEG_QUALITY, 95]),
    ".webp": (".webp", True, [cv2.IMWRITE_WEBP_QUALITY, 101]),
    ".tif": (".tiff", True, []),
    ".tiff": (".tiff", True, []),
    ".bmp": (".bmp", False, []),
}

COLOURS = {
    "white": (255, 255, 255), "black": (0, 0, 0), "red": (255, 0, 0), "green": (0, 128, 0),
    "lime": (0, 255, 0), "blue": (0, 0, 255), "yellow": (255, 255, 0), "cyan": (0, 255, 255),
    "magenta": (255, 0, 255), "gray": (128, 128, 128), "grey": (128, 128, 128),
    "orange": (255, 165, 0), "purple": (128, 0, 128), "pink": (255, 192, 203),
    "brown": (165, 42, 42), "navy": (0, 0, 128), "silver": (192, 192, 192),
}


class ImageError(Exception):
    """An image or mask that cannot be read, decoded or written."""


def output_format(path: str) -> tuple[str, bool, list]:
    """Encoder extension, alpha support and parameters for an output path."""
    ext = os.path.splitext(path)[1].lower()
    if ext not in FORMATS:
        known = ", ".join(sorted(FORMATS))
        raise ValueError(f"unknown output format {ext or '(no extension)'!r} for {path}; use one of {known}")
    return FORMATS[ext]


def parse_colour(text: str):
    """``#rrggbb``, ``#rgb``, a colour name, or ``transparent`` / ``none`` (-> None).

    Returns
    -------
    tuple of int (r, g, b) in 0..255, or None for transparent.
    """
    t = text.strip().lower()
    if t in ("transparent", "none"):
        return None
    if t in COLOURS:
        return COLOURS[t]
    hexdigits = t[1:] if t.startswith("#") else ""
    if len(hexdigits) == 3:
        hexdigits = "".join(c * 2 for c in hexdigits)
    if len(hexdigits) == 6:
        try:
            return tuple(int(hexdigits[i : i + 2], 16) for i in (0, 2, 4))
        except ValueError:
            pass
    raise ValueError(f"{text!r} is not a colour (use #rrggbb, a name such as white, or transparent)")


def read_image(path: str) -> np.ndarray:
    """Decode an image file keeping its depth and alpha (OpenCV channel order).

    Raises
    ------
    ImageError
        When the file is missing, empty or cannot be decoded.
    """
    try:
        data = np.fromfile(path, dtype=np.uint8)
    except OSError as err:
        raise ImageError(f"cannot read {path}: {err.strerror or err}") from None
    return decode_image(data, path)


def decode_image(data: np.ndarray, name: str) -> np.ndarray:
    """Decode image bytes (``(n,) uint8``); ``name`` is used in error messages."""
    if data.size == 0:
        raise ImageError(f"{name} is empty")
    image = cv2.imdecode(data, cv2.IMREAD_UNCHANGED)
    if image is None:
        raise ImageError(f"{name} is not an image that can be decoded (corrupt or unsupported format)")
    if image.dtype not in (np.uint8, np.uint16):
        raise ImageError(f"{name} has unsupported sample type {image.dtype}")
    if image.ndim == 3 and image.shape[2] == 2:      # gray + alpha: encoders want BGRA
        gray, alpha = image[:, :, 0], image[:, :, 1]
        image = np.dstack([gray, gray, gray, alpha])
    return image


def mask_from_image(image: np.ndarray) -> np.ndarray:
    """Boolean feature mask: gray value >= 128 (alpha, if any, is ignored)."""
    if image.ndim == 3:
        image = cv2.cvtColor(image[:, :, :3], cv2.COLOR_BGR2GRAY) if image.shape[2] >= 3 else image[:, :, 0]
    if image.dtype == np.uint16:
        return image >= 128 * 257
    return image >= 128


def encode_image(image: np.ndarray, path: str) -> bytes:
    """Encode ``image`` in the format named by ``path``'s extension."""
    ext, _, params = output_format(path)
    if ext in (".jpg", ".bmp") and image.dtype != np.uint8:
        image = (image // 257).astype(np.uint8)
    if ext == ".jpg" and image.ndim == 3 and image.shape[2] == 4:
        image = image[:, :, :3]
    ok, buf = cv2.imencode(ext, image, params)
    if not ok:
        raise ImageError(f"cannot encode the result as {ext}")
    return buf.tobytes()


def write_atomic(path: str, data: bytes) -> None:
    """Write ``data`` to ``path`` through a temporary file in the same directory.

    A failure at any point leaves no partial file and leaves an existing ``path`` untouched.
    """
    directory = os.path.dirname(os.path.abspath(path))
    fd, tmp = tempfile.mkstemp(prefix=".featurewarp-", suffix=".tmp", dir=directory)
    try:
        with os.fdopen(fd, "wb") as fh:
            fh.write(data)
        if os.path.exists(path):
            os.chmod(tmp, os.stat(path).st_mode & 0o777)
        else:
            umask = os.umask(0)
            os.umask(umask)
            os.chmod(tmp, 0o666 & ~umask)
        os.replace(tmp, path)
    except BaseException:
        if os.path.exists(tmp):
            os.unlink(tmp)
        raise

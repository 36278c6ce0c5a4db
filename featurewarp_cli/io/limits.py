"""The limit on an input's pixels: one default, one check, and OpenCV's decoders told of it.

Headers are checked with Pillow before any pixel is decoded (see
:mod:`featurewarp_cli.io.decode`). For the formats whose header Pillow cannot read
(Radiance HDR, PAM, OpenEXR) OpenCV's own check is the fallback: its decoders refuse
images above ``OPENCV_IO_MAX_IMAGE_PIXELS``, a variable OpenCV reads once, when it is
imported. This module imports neither OpenCV nor Pillow.
"""

from __future__ import annotations

import os
import sys

from . import ImageError

#: Default limit on width * height of an input (``--max-pixels``).
MAX_PIXELS = 200_000_000
#: The environment variable that limits OpenCV's decoders (read when cv2 is imported).
OPENCV_VARIABLE = "OPENCV_IO_MAX_IMAGE_PIXELS"


def check_pixels(width: int, height: int, name: str, max_pixels: int | None) -> None:
    """Raise ImageError if a ``width`` x ``height`` image is empty or above ``max_pixels``.

    Parameters
    ----------
    width, height : int
    name : str
        What the image is, for the message (a path, ``stdin``, ``the output canvas``).
    max_pixels : int or None
        Largest accepted width * height; None: no limit.
    """
    if width < 1 or height < 1:
        raise ImageError(f"{name} has no pixels ({width}x{height})")
    if max_pixels is not None and width * height > max_pixels:
        raise ImageError(f"{name} is {width}x{height} = {width * height} pixels, above the limit "
                         f"of {max_pixels} (--max-pixels)")


def limit_opencv_decoders(max_pixels: int | None, replace: bool = True) -> bool:
    """Make OpenCV's decoders refuse images of more than ``max_pixels`` pixels.

    Sets ``OPENCV_IO_MAX_IMAGE_PIXELS``, which OpenCV reads once, when ``cv2`` is
    imported: call this before anything imports ``cv2``.

    Parameters
    ----------
    max_pixels : int or None
        None leaves OpenCV's own default (2**30).
    replace : bool
        False keeps a value the user already set in the environment.

    Returns
    -------
    bool
        False when OpenCV was already imported (the limit it has stays).
    """
    if "cv2" in sys.modules:
        return False
    if max_pixels is not None and (replace or OPENCV_VARIABLE not in os.environ):
        os.environ[OPENCV_VARIABLE] = str(max_pixels)
    return True


def opencv_limit() -> int:
    """The pixel limit OpenCV's decoders were given (its default 2**30 when none was)."""
    try:
        return int(os.environ.get(OPENCV_VARIABLE, 1 << 30))
    except ValueError:
        return 1 << 30

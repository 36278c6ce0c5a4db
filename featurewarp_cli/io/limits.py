"""The limits on an input's pixels and on a command's memory, and OpenCV's decoders told of them.

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

#: Default limit on width * height of an input (``--max-pixels``): every single-shot camera
#: (the largest, 151 MP); stitched panoramas and pixel-shift composites need the option. At
#: 200 MP a 580 KB PNG or a 4 KB AVIF of 14 000 x 14 000 was accepted and cost 12 s CPU and
#: 1.3-3.3 GB; a 160 MP photo costs 11-13 s and 2 GB (README, Limits).
MAX_PIXELS = 160_000_000
#: The largest ``--max-pixels`` accepted (2^40: beyond it OpenCV's decoder limit, a 64-bit
#: count it parses, overflowed and aborted the process).
MAX_PIXELS_LIMIT = 1 << 40
#: The environment variable that limits OpenCV's decoders (read when cv2 is imported).
OPENCV_VARIABLE = "OPENCV_IO_MAX_IMAGE_PIXELS"
#: Peak bytes per grid node of a solve (factor, guard, quality), measured: 1.1 kB (12 MP,
#: --cell 1, 12 M nodes, 13.5 GB) to 2.4 kB (an 830 000-node guard run, 2.0 GB).
NODE_BYTES = 2500
#: Peak bytes per pixel of input (decoded, mask, prefilter pyramid) and of output (the
#: canvas, its encoded copy), for 16-bit RGBA, the widest kind; with alpha that is not wholly
#: opaque the input is resampled from a premultiplied 16-bit copy (8 bytes more a pixel).
INPUT_PIXEL_BYTES = 32
OUTPUT_PIXEL_BYTES = 16


def physical_memory() -> int:
    """Bytes of memory the machine has (8 GiB where the system does not say)."""
    try:
        return os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES")
    except (ValueError, OSError, AttributeError):
        return 8 << 30


#: Default memory budget of one command (``--max-memory``): half of the machine's memory.
MAX_MEMORY = physical_memory() // 2


def parse_size(text: str) -> int:
    """Bytes from ``text``: a number with an optional K, M, G or T suffix (powers of 1024).

    >>> parse_size("512M"), parse_size("2G"), parse_size("1e9")
    (536870912, 2147483648, 1000000000)
    """
    value = str(text).strip().upper().removesuffix("B").removesuffix("I")
    scale = 1
    if value and value[-1] in "KMGT":
        scale, value = 1 << (10 * ("KMGT".index(value[-1]) + 1)), value[:-1]
    try:
        number = float(value) * scale
    except ValueError:
        raise ValueError(f"{text!r} is not a size (a number of bytes, or with K, M, G, T)") from None
    if not (number >= 1 and number < 1 << 60):
        raise ValueError(f"{text!r} is not a size of at least 1 byte")
    return int(number)


def size_text(size: int, apart_from: int | None = None) -> str:
    """``size`` bytes for a message: ``1.5 GiB``, ``37 MiB``, ``900 bytes``; with more digits
    where three would read the same as ``apart_from`` (a limit it is compared with: "10.02 MiB,
    above the limit of 10 MiB", not "10 MiB, above the limit of 10 MiB")."""
    def text(value: int, digits: int) -> str:
        for unit, shift in (("GiB", 30), ("MiB", 20), ("KiB", 10)):
            if value >= 1 << shift:
                return f"{value / (1 << shift):.{digits}g} {unit}"
        return f"{value} bytes"
    digits = 3
    while apart_from is not None and size != apart_from and digits < 12 and \
            text(size, digits) == text(apart_from, digits):
        digits += 1
    return text(size, digits)


def node_budget(width: int, height: int, canvas: tuple[int, int], max_memory: int | None) -> int | None:
    """Grid nodes a command may use within ``max_memory`` bytes, after the images' share
    (:data:`INPUT_PIXEL_BYTES`, :data:`OUTPUT_PIXEL_BYTES`); None without a budget.

    Raises ImageError when the images alone exceed the budget."""
    if max_memory is None:
        return None
    images = image_bytes(width, height) + canvas[0] * canvas[1] * OUTPUT_PIXEL_BYTES
    if images > max_memory:
        raise ImageError(f"a {width}x{height} input warped onto a {canvas[0]}x{canvas[1]} canvas needs about "
                         f"{size_text(images, max_memory)}, above the memory limit of {size_text(max_memory)} "
                         "(--max-memory)")
    return int((max_memory - images) // NODE_BYTES)


def image_bytes(width: int, height: int) -> int:
    """Peak bytes a ``width`` x ``height`` input takes once decoded (:data:`INPUT_PIXEL_BYTES`
    a pixel: the image, its mask, the prefilter pyramid)."""
    return width * height * INPUT_PIXEL_BYTES


def check_memory(width: int, height: int, name: str, max_memory: int | None) -> None:
    """Raise ImageError, before decoding, if a ``width`` x ``height`` input alone needs more
    than ``max_memory`` bytes (:func:`image_bytes`; None: no limit). A 4 KB AVIF of 14 000 x
    14 000 pixels was decoded (3.3 GB) before the memory limit refused it."""
    if max_memory is not None and image_bytes(width, height) > max_memory:
        raise ImageError(f"{name} is {width}x{height}: decoding and warping it needs about "
                         f"{size_text(image_bytes(width, height), max_memory)}, above the memory limit of "
                         f"{size_text(max_memory)} (--max-memory)")


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


def check_size(width: int, height: int, name: str, max_pixels: int | None, max_memory: int | None) -> None:
    """What a header's size must pass before decoding: :func:`check_pixels`, :func:`check_memory`."""
    check_pixels(width, height, name, max_pixels)
    check_memory(width, height, name, max_memory)


def fits(width: int, height: int, max_pixels: int | None, max_memory: int | None) -> bool:
    """Whether a ``width`` x ``height`` input passes :func:`check_size`."""
    try:
        check_size(width, height, "", max_pixels, max_memory)
    except ImageError:
        return False
    return True


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

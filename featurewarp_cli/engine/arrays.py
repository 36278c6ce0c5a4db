"""The Python API's image arrays: RGB(A) in, RGB(A) out, any common dtype, checked.

The renderer works on uint8 or uint16 samples and takes a background colour as
(r, g, b) for images in OpenCV's BGR order. The API speaks RGB(A), as scikit-image
and Pillow do: :func:`prepare` and :func:`finish` convert at its boundary only.

Rules
-----
- Channels: 1 (grey), 2 (grey + alpha), 3 (RGB) or 4 (RGBA); anything else is a
  ValueError. A grey image stays grey.
- Samples: uint8 and uint16 as they are; bool, other integers (values must fit
  uint16; returned clipped to their type) and floats in [0, 1] (scikit-image's convention,
  rendered at 16 bits and returned in the input's float dtype, float16 included).
- Background: None (uncovered pixels transparent: alpha is added where needed), an
  (r, g, b) tuple of 0..255 integers, or colour text (``"white"``, ``"#ff8800"``).
- Mask (as on the command line): bool as it is; a 0/1 mask marks its 1s; other integers at
  or above 128 (32896 for uint16, 64 for int8); floats at or above 0.5.
"""

from __future__ import annotations

import numpy as np


def background_rgb(background) -> tuple[int, int, int] | None:
    """The API's background as (r, g, b) of 0..255, or None (ValueError for anything else)."""
    if background is None:
        return None
    if isinstance(background, str):
        from ..io.colours import parse_colour

        return parse_colour(background)
    try:
        values = tuple(background)
    except TypeError:
        values = ()
    if len(values) != 3 or not all(isinstance(v, (int, np.integer)) and 0 <= v <= 255 for v in values):
        raise ValueError(f"background must be (r, g, b) with integers 0..255, a colour name or None, "
                         f"not {background!r}")
    return tuple(int(v) for v in values)


def prepare(image: np.ndarray, background) -> tuple[np.ndarray, tuple | None, np.dtype]:
    """(samples the renderer takes, its background argument, the dtype to return)."""
    image = np.asarray(image)
    channels = 1 if image.ndim == 2 else (image.shape[2] if image.ndim == 3 else 0)
    if channels not in (1, 2, 3, 4):
        raise ValueError(f"image must be (h, w) or (h, w, C) with C in 1..4, not shape {image.shape}")
    dtype = image.dtype
    if dtype == bool:
        samples = image.astype(np.uint8) * 255
    elif np.issubdtype(dtype, np.floating):
        if not np.all(np.isfinite(image)) or image.min(initial=0) < 0 or image.max(initial=0) > 1:
            raise ValueError("a float image must hold values in [0, 1]")
        samples = np.round(image.astype(np.float64) * 65535.0).astype(np.uint16)   # float16 overflows
    elif dtype in (np.uint8, np.uint16):
        samples = image
    elif np.issubdtype(dtype, np.integer):
        if image.min(initial=0) < 0 or image.max(initial=0) > 65535:
            raise ValueError(f"{dtype} image values must fit 0..65535 (uint16)")
        samples = image.astype(np.uint16)
    else:
        raise ValueError(f"image dtype {dtype} is not supported (use uint8, uint16, bool, integers or "
                         f"floats in [0, 1])")
    rgb = background_rgb(background)
    if rgb is not None and channels >= 3:
        rgb = rgb[::-1]                  # the renderer puts (r, g, b) into BGR order: undo it for RGB
    return np.ascontiguousarray(samples), rgb, dtype


def finish(out: np.ndarray, channels: int, dtype: np.dtype) -> np.ndarray:
    """The rendered samples in the API's terms: grey + alpha for a grey input that gained
    alpha, and the caller's dtype."""
    if channels == 1 and out.ndim == 3 and out.shape[2] == 4:
        out = np.ascontiguousarray(out[..., [0, 3]])       # grey stays grey: (grey, alpha)
    if dtype == bool:
        return out >= 128
    if np.issubdtype(dtype, np.floating):
        scale = 65535.0 if out.dtype == np.uint16 else 255.0
        return (out / scale).astype(dtype)
    if dtype not in (np.uint8, np.uint16):
        if np.iinfo(dtype).max < 65535:                     # int8's, int16's opaque alpha and fills: their largest
            out = np.minimum(out, np.iinfo(dtype).max)
        return out.astype(dtype)
    return out


def mask_array(mask, shape: tuple[int, int]) -> np.ndarray | None:
    """The mask rule of the API and the command line: bool as is; integers whose largest value is
    1 (a 0/1 mask, as ``cv2.threshold(..., 1, ...)`` gives) mark their 1s, other integers mark
    values at or above 128 (32896 for uint16, 64 for int8: 128/255 of their range; an int64
    0/255 mask, as ``mask.astype(int) * 255`` gives, marked nothing at 128/255 of its type's
    maximum); floats mark values at or above 0.5."""
    if mask is None:
        return None
    mask = np.asarray(mask)
    if mask.shape != shape:
        raise ValueError(f"mask is {mask.shape[1] if mask.ndim > 1 else '?'}x{mask.shape[0]}, "
                         f"image is {shape[1]}x{shape[0]}")
    if mask.dtype == bool:
        return mask
    if np.issubdtype(mask.dtype, np.integer):
        if mask.size and mask.max() == 1 and mask.min() >= 0:
            return mask == 1
        top = int(np.iinfo(mask.dtype).max)
        return mask >= (32896 if mask.dtype == np.uint16 else 128 if top >= 255 else 128 * top / 255)
    if np.issubdtype(mask.dtype, np.floating):
        return mask >= 0.5
    raise ValueError(f"mask dtype {mask.dtype} is not supported")

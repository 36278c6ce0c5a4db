"""The Python API's image arrays: RGB(A) in, RGB(A) out, any common dtype, checked.

The renderer works on uint8 or uint16 samples and takes a background colour as
(r, g, b) for images in OpenCV's BGR order. The API speaks RGB(A), as scikit-image
and Pillow do: :func:`prepare` and :func:`finish` convert at its boundary only.

Rules
-----
- Shape: (h, w) or (h, w, C) with C channels: 1 (grey), 2 (grey + alpha), 3 (RGB) or 4
  (RGBA); anything else is a ValueError naming the shape. Anything ``np.asarray`` makes an
  array of is taken (a ``PIL.Image`` too). A grey image stays grey, (h, w, 1) staying (h, w, 1).
- Samples: uint8 and uint16 as they are; bool; other integers on the 8-bit scale (0..255,
  opaque alpha and white 255) when every value is within 0..255, else on the 16-bit scale
  (0..65535; cast 16-bit data to uint16 to be sure of its scale), returned in their type,
  clipped to it; floats in [0, 1] (scikit-image's convention, rendered at 16 bits and
  returned in the input's float dtype, float16 included).
- Background: None (uncovered pixels transparent: alpha is added where needed), an
  (r, g, b) tuple of 0..255 integers, one integer 0..255 (a grey), or colour text
  (``"white"``, ``"#ff8800"``). A grey image is filled with the colour's luma.
- Mask (as on the command line): bool as it is; a 0/1 mask marks its 1s; other integers at
  or above 128 (32896 for uint16, 64 for int8); floats at or above 0.5. A (h, w, 1) mask is
  a (h, w) one; an RGB(A) or grey + alpha mask (uint8 or uint16) is read as a mask file is:
  its gray composited over black (:func:`featurewarp_cli.io.decode.mask_from_image`). A
  path (``str`` or ``os.PathLike``) is read as ``--mask`` reads it.
"""

from __future__ import annotations

import os

import numpy as np


def background_rgb(background) -> tuple[int, int, int] | None:
    """The API's background as (r, g, b) of 0..255, or None (ValueError for anything else)."""
    if background is None:
        return None
    if isinstance(background, str):
        from ..io.colours import parse_colour

        return parse_colour(background)
    if isinstance(background, (int, np.integer)) and not isinstance(background, bool) and 0 <= background <= 255:
        return (int(background),) * 3                  # a grey level
    try:
        values = tuple(background)
    except TypeError:
        values = ()
    if len(values) != 3 or not all(isinstance(v, (int, np.integer)) and 0 <= v <= 255 for v in values):
        raise ValueError(f"background must be (r, g, b) with integers 0..255, a grey 0..255, a colour name or "
                         f"None, not {background!r}")
    return tuple(int(v) for v in values)


def check_size(width, height, who: str = "FeatureWarper") -> None:
    """ValueError unless ``width`` and ``height`` are whole numbers of pixels, at least 1 (0 was
    taken and failed in the factorization, -5 with numpy's "negative dimensions")."""
    for name, value in (("width", width), ("height", height)):
        if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value < 1:
            raise ValueError(f"{who}: {name}={value!r}; use a whole number of pixels, at least 1")


#: PIL modes whose arrays are not the pixels (a palette's indices, CMYK, other colour spaces),
#: and the mode each is converted to first; "P" becomes RGBA where it has a transparent entry.
PIL_CONVERSIONS = {"P": "RGB", "PA": "RGBA", "CMYK": "RGB", "YCbCr": "RGB", "HSV": "RGB", "RGBX": "RGB",
                   "RGBa": "RGBA", "La": "LA"}


def check_warp(warp, width: int, height: int, who: str = "FeatureWarper.solve") -> None:
    """TypeError unless ``warp`` is a warp made for a size (a callable with ``width``, ``height``
    and ``canvas``: a preset's instance, a HandleWarp), naming what to pass instead (a class or
    a name failed with AttributeError: no attribute 'width'); ValueError if it is for another
    size than ``width`` x ``height``."""
    if isinstance(warp, type) or not (callable(warp) and all(hasattr(warp, a) for a in ("width", "height", "canvas"))):
        what = (f"the class {warp.__name__}: make it for the image, {warp.__name__}({width}, {height})"
                if isinstance(warp, type) else f"{warp!r}: featurewarp_cli.load_warp({warp!r})({width}, {height}) "
                "makes a preset from its name" if isinstance(warp, str) else f"{type(warp).__name__} {warp!r}")
        raise TypeError(f"{who}: warp must be a warp made for the image (a preset's instance), not {what}")
    if (warp.width, warp.height) != (width, height):
        raise ValueError(f"warp is for {warp.width}x{warp.height}, warper for {width}x{height}")
    check_canvas(warp)


def check_canvas(warp) -> None:
    """ValueError naming a warp's ``canvas`` unless it is (width, height) of whole pixels, at
    least 1 a side (a plugin's (0, 0) failed in the rasterizer with "buffer sizes do not match",
    (640.5, 480) with a TypeError deep in the render). The renderer takes sides beyond OpenCV's
    limits (it tiles); the memory budget, where one is given, refuses a canvas too large."""
    canvas, name = warp.canvas, getattr(warp, "name", "") or type(warp).__name__
    try:
        sides = tuple(canvas)
    except TypeError:
        sides = ()
    if len(sides) != 2 or not all(isinstance(v, (int, np.integer)) and not isinstance(v, bool)
                                  and v >= 1 for v in sides):
        raise ValueError(f"{name}: canvas must be (width, height), whole pixels of at least 1, "
                         f"not {canvas!r} (set it in _setup)")


def _pil_pixels(image, what: str = "image"):
    """A PIL image in a mode whose array is its pixels (:data:`PIL_CONVERSIONS`; CMYK by PIL's
    own formula, not a profile); anything else as it is. ValueError for L*a*b*."""
    mode = getattr(image, "mode", None)
    if not (type(image).__module__.startswith("PIL.") and hasattr(image, "convert")):
        return image
    if mode == "LAB":
        raise ValueError(f"{what} is a PIL image in mode LAB: convert it to RGB first (PIL.ImageCms)")
    if mode == "P" and "transparency" in image.info:
        return image.convert("RGBA")
    return image.convert(PIL_CONVERSIONS[mode]) if mode in PIL_CONVERSIONS else image


def check_cell_and_flags(cell, **flags) -> None:
    """ValueError for a ``cell`` that is not a number of pixels of at least 1 (``True`` was a
    1 px grid), or a flag that is not a bool (``injective="no"`` was taken as true)."""
    if cell is not None and (isinstance(cell, bool) or not (isinstance(cell, (int, float, np.number))
                                                             and cell >= 1 and np.isfinite(cell))):
        raise ValueError(f"cell must be a number of pixels, at least 1, not {cell!r}")
    for name, value in flags.items():
        if not isinstance(value, (bool, np.bool_)):
            raise ValueError(f"{name} must be True or False, not {value!r}")


def as_array(value, what: str) -> np.ndarray:
    """``np.asarray(value)`` (a PIL image in its pixels: :func:`_pil_pixels`), or a one-line error
    naming ``what`` and the type it could not take."""
    if isinstance(value, (str, bytes, os.PathLike)) and what == "image":
        raise TypeError(f"image must be an array (h, w) or (h, w, C), not a path or text ({value!r}): read it "
                        f"first (PIL.Image.open, cv2.imread, imageio)")
    if what in ("image", "mask"):         # a palette mask's array is its indices, not its grey
        value = _pil_pixels(value, what)
    try:
        return np.asarray(value)
    except (ValueError, TypeError) as err:          # ragged lists, objects numpy cannot read
        raise ValueError(f"{what} is not an array NumPy can read ({type(value).__name__}: {err})") from None


def prepare(image, background) -> tuple[np.ndarray, tuple | None, np.dtype]:
    """(samples the renderer takes, its background argument, the dtype to return).

    Every check of the image and the background is here, so that a caller can make them
    before the solve."""
    image = as_array(image, "image")
    channels = 1 if image.ndim == 2 else (image.shape[2] if image.ndim == 3 else 0)
    if channels not in (1, 2, 3, 4):
        batch = " (one image at a time: image[0] for a batch of one)" if image.ndim == 4 else ""
        raise ValueError(f"image must be (h, w) or (h, w, C) with C in 1..4, not shape {image.shape}{batch}")
    if image.shape[0] < 1 or image.shape[1] < 1:
        raise ValueError(f"image has no pixels (shape {image.shape})")
    dtype = image.dtype                  # returned as given, big-endian included
    image = native_order(image)          # ">u2" is not np.uint16: 16-bit data below 256 took the 8-bit scale
    if image.dtype == bool:
        samples = image.astype(np.uint8) * 255
    elif np.issubdtype(image.dtype, np.floating):
        if not np.all(np.isfinite(image)) or image.min(initial=0) < 0 or image.max(initial=0) > 1:
            raise ValueError(f"a float image must hold values in [0, 1] (its range is {image.min()}..{image.max()}; "
                             f"divide 0..255 data by 255)")
        samples = np.round(image.astype(np.float64) * 65535.0).astype(np.uint16)   # float16 overflows
    elif image.dtype in (np.uint8, np.uint16):
        samples = image
    elif np.issubdtype(image.dtype, np.integer):
        low, high = image.min(initial=0), image.max(initial=0)
        if low < 0 or high > 65535:
            raise ValueError(f"{dtype} image values must fit 0..65535 (uint16), not {low}..{high}")
        samples = image.astype(np.uint8 if high <= 255 else np.uint16)     # 8-bit data keeps the 8-bit scale
    else:
        raise ValueError(f"image dtype {dtype} is not supported (use uint8, uint16, bool, integers or "
                         f"floats in [0, 1])")
    rgb = background_rgb(background)
    if rgb is not None and channels >= 3:
        rgb = rgb[::-1]                  # the renderer puts (r, g, b) into BGR order: undo it for RGB
    return np.ascontiguousarray(samples), rgb, dtype


def native_order(array: np.ndarray) -> np.ndarray:
    """``array`` in the machine's byte order (a big-endian one converted: PIL's ``I;16B``, FITS data)."""
    return array if array.dtype.isnative else array.astype(array.dtype.newbyteorder("="))


def finish(out: np.ndarray, channels: int, dtype: np.dtype, channel_axis: bool = False) -> np.ndarray:
    """The rendered samples in the API's terms: grey + alpha for a grey input that gained
    alpha, a channel axis for an (h, w, 1) input (``channel_axis``), and the caller's dtype."""
    if channels == 1 and out.ndim == 3 and out.shape[2] == 4:
        out = np.ascontiguousarray(out[..., [0, 3]])       # grey stays grey: (grey, alpha)
    if channel_axis and out.ndim == 2:
        out = out[..., None]
    if dtype == bool:
        return out >= 128
    if np.issubdtype(dtype, np.floating):
        scale = 65535.0 if out.dtype == np.uint16 else 255.0
        return (out / scale).astype(dtype)
    if dtype not in (np.uint8, np.uint16):
        if np.iinfo(dtype).max < np.iinfo(out.dtype).max:   # int8's, int16's opaque alpha and fills: their largest
            out = np.minimum(out, np.iinfo(dtype).max)
        return out.astype(dtype)
    return out


def mask_array(mask, shape: tuple[int, int]) -> np.ndarray | None:
    """The mask rule of the API and the command line: bool as is; integers whose largest value is
    1 (a 0/1 mask, as ``cv2.threshold(..., 1, ...)`` gives) mark their 1s, other integers mark
    values at or above 128 (32896 for uint16, 64 for int8: 128/255 of their range; an int64
    0/255 mask, as ``mask.astype(int) * 255`` gives, marked nothing at 128/255 of its type's
    maximum); floats mark values at or above 0.5. A (h, w, 1) mask is a (h, w) one; one with
    2 to 4 channels, and a path, are read as a mask file (:func:`colour_mask`, :func:`mask_file`).
    ``shape`` is the image's (h, w)."""
    if mask is None:
        return None
    if isinstance(mask, (str, os.PathLike)):
        return mask_file(mask, shape)
    mask = native_order(as_array(mask, "mask"))
    if mask.ndim == 3 and mask.shape[2] == 1:
        mask = mask[..., 0]
    if mask.ndim not in (2, 3) or mask.ndim == 3 and not 2 <= mask.shape[2] <= 4:
        raise ValueError(f"mask must be (h, w), or (h, w, C) with C in 1..4 as an image file's, not shape {mask.shape}")
    if mask.shape[:2] != shape:
        raise ValueError(f"mask is {mask.shape[1]}x{mask.shape[0]}, image is {shape[1]}x{shape[0]}")
    if mask.ndim == 3:
        return colour_mask(mask)
    if mask.dtype == bool:
        return mask
    if np.issubdtype(mask.dtype, np.integer):
        if mask.size and mask.max() == 1 and mask.min() >= 0:
            return mask == 1
        top = int(np.iinfo(mask.dtype).max)
        return mask >= (32896 if mask.dtype == np.uint16 else 128 if top >= 255 else 128 * top / 255)
    if np.issubdtype(mask.dtype, np.floating):
        if not np.isfinite(mask).all():          # NaN marked nothing, in silence: a plain warp
            raise ValueError("mask holds NaN or infinite values: use 0 and 1, or 0.0 to 1.0")
        return mask >= 0.5
    raise ValueError(f"mask dtype {mask.dtype} is not supported (use bool, integers or floats)")


def colour_mask(mask: np.ndarray) -> np.ndarray:
    """A grey + alpha, RGB or RGBA mask (uint8 or uint16) read as ``--mask`` reads such a file."""
    from ..io.decode import gray_alpha_to_bgra, mask_from_image

    if mask.dtype not in (np.uint8, np.uint16):
        raise ValueError(f"a mask with {mask.shape[2]} channels must be uint8 or uint16 (as an image file's), "
                         f"not {mask.dtype}: pass one channel, (h, w)")
    bgr = [2, 1, 0, 3][:mask.shape[2]] if mask.shape[2] >= 3 else [0, 1]
    return mask_from_image(gray_alpha_to_bgra(np.ascontiguousarray(mask[..., bgr])))


def mask_file(path, shape: tuple[int, int]) -> np.ndarray:
    """The mask in the image file ``path``, read as ``--mask`` reads it, checked against ``shape`` (h, w)."""
    from ..io import ImageError
    from ..io.decode import mask_from_image, read_image

    try:
        marked = mask_from_image(read_image(os.fspath(path)))
    except ImageError as err:
        raise ValueError(f"mask: {err}") from None
    if marked.shape != shape:
        raise ValueError(f"mask {os.fspath(path)} is {marked.shape[1]}x{marked.shape[0]}, image is {shape[1]}x{shape[0]}")
    return marked

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

from . import ImageError, tiff
from .capture import captured_stderr
from .decode import gray_alpha_to_bgra
from .depth import to_eight_bit
from .formats import FORMATS

#: OpenCV encoder parameters by format name.
SETTINGS = {
    "png": [cv2.IMWRITE_PNG_COMPRESSION, 1, cv2.IMWRITE_PNG_STRATEGY, cv2.IMWRITE_PNG_STRATEGY_RLE,
            cv2.IMWRITE_PNG_FILTER, cv2.IMWRITE_PNG_FILTER_PAETH],
    "jpg": [cv2.IMWRITE_JPEG_QUALITY, 95, cv2.IMWRITE_JPEG_PROGRESSIVE, 0, cv2.IMWRITE_JPEG_OPTIMIZE, 0],
    # 101: lossless; with alpha it goes through Pillow (:func:`_pillow_encode`): OpenCV's libwebp
    # call fills the colour under fully transparent pixels with nearby colour (not the 0 the
    # warp leaves there, which PNG and TIFF keep), so the same result as PNG and WebP differed
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


def stored_form(image: np.ndarray, fmt: str) -> tuple[int, int]:
    """(channels, bits per sample) of ``image`` as :func:`encode_image` stores it as ``fmt``:
    gray + alpha as BGRA, alpha laid over the background where ``fmt`` has none, 8 bits where
    it holds no more."""
    channels = 1 if image.ndim == 2 else int(image.shape[2])
    channels = 4 if channels == 2 else channels
    if channels == 4 and not FORMATS[fmt].alpha:
        channels = 3
    if channels == 1 and fmt in ("webp", "gif"):       # no gray form: colour (WebP), a palette (GIF)
        channels = 3
    return channels, 8 if FORMATS[fmt].eight_bit else 8 * image.dtype.itemsize


#: Formats whose ICC profile and EXIF block are kept (through Pillow, for 8-bit samples).
METADATA_FORMATS = {"jpg": "JPEG", "png": "PNG", "webp": "WEBP", "tiff": "TIFF"}


def encode_image(image: np.ndarray, fmt: str, background=(255, 255, 255), quality: int | None = None,
                 icc: bytes | None = None, exif: bytes | None = None) -> bytes:
    """Encode ``image`` as format ``fmt`` (a name of :data:`FORMATS`) with fixed settings.

    Parameters
    ----------
    image : (h, w) or (h, w, C) ndarray, uint8 or uint16, C in 1..4, BGR(A) channel order
        Gray + alpha (C = 2) is stored as BGRA.
    fmt : str
    background : (r, g, b)
        Colour that alpha is composited over for formats without alpha.
    quality : int, optional
        1..100 for JPEG (default 95) and WebP (lossy when given; default lossless); other
        formats ignore it.
    icc, exif : bytes, optional
        An ICC profile and an EXIF block to store (JPEG, PNG, WebP, TIFF with 8-bit samples,
        written by Pillow; OpenCV's encoders drop them).

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
    if fmt == "gif":
        return _gif(image)
    lossless_alpha = fmt == "webp" and quality is None and image.ndim == 3 and image.shape[2] == 4
    if (icc or exif or lossless_alpha) and fmt in METADATA_FORMATS and image.dtype == np.uint8:
        return _pillow_encode(image, fmt, quality, icc, exif)
    settings = list(SETTINGS[fmt])
    if quality is not None and fmt in ("jpg", "webp"):
        settings[1] = int(quality)
    with captured_stderr():
        ok, buf = cv2.imencode(FORMATS[fmt].extension, image, settings)
    if not ok:
        raise ImageError(f"cannot encode the result as {fmt}")
    if fmt == "tiff" and image.ndim == 3 and image.shape[2] == 4:
        return tiff.with_alpha_tag(buf.tobytes())
    return buf.tobytes()


def _gif(image: np.ndarray) -> bytes:
    """8-bit gray or BGR pixels as a GIF by Pillow: gray as a gray palette, colour quantised to
    an adaptive palette of 256 (median cut, Floyd-Steinberg dither). OpenCV's GIF encoder
    takes a fixed palette: on the astronaut under ``arc --angle 200`` a mean error of 20.7
    levels, and a band of bright yellow along the outline (the adaptive palette: 3.0)."""
    import io

    from PIL import Image

    buffer = io.BytesIO()
    if image.ndim == 2:
        Image.fromarray(image).save(buffer, "GIF")
    else:
        Image.fromarray(cv2.cvtColor(image, cv2.COLOR_BGR2RGB)).quantize(256).save(buffer, "GIF")
    return buffer.getvalue()


def rgb_order(image: np.ndarray) -> np.ndarray:
    """BGR(A) pixels in Pillow's order, RGB(A); gray as it is."""
    if image.ndim == 2:
        return image
    return cv2.cvtColor(image, cv2.COLOR_BGRA2RGBA if image.shape[2] == 4 else cv2.COLOR_BGR2RGB)


def webp_options(quality: int | None) -> dict:
    """Pillow's WebP settings: lossy at ``quality``, else lossless keeping the colour under
    transparent pixels as given (libwebp's ``exact``) at OpenCV's effort (70)."""
    return {"quality": quality} if quality else {"lossless": True, "quality": 70, "exact": True}


def _pillow_encode(image: np.ndarray, fmt: str, quality: int | None, icc: bytes | None,
                   exif: bytes | None) -> bytes:
    """8-bit BGR(A) or grey pixels as ``fmt`` bytes with their ICC profile and EXIF, by Pillow,
    with the same settings as OpenCV's path where Pillow has them. Lossless WebP keeps the colour
    under transparent pixels as given (libwebp's ``exact``) with OpenCV's effort (70): about as
    fast and small as OpenCV's (arc of the astronaut, 976x538: 0.23 s, 399 kB against 0.21 s, 398 kB)."""
    import io

    from PIL import Image

    image = rgb_order(image)
    options = {"icc_profile": icc} if icc and icc_space(icc) == ("RGB " if image.ndim == 3 else "GRAY") else {}
    if exif and fmt == "tiff":
        exif = _tiff_exif(exif)
    if exif:
        options["exif"] = exif
    options.update({"jpg": {"quality": quality or 95, "optimize": False, "progressive": False},
                    "png": {"compress_level": 1},
                    "webp": webp_options(quality),
                    "tiff": {"compression": "tiff_lzw"}}[fmt])
    buffer = io.BytesIO()
    with captured_stderr() as printed:
        try:
            Image.fromarray(image).save(buffer, METADATA_FORMATS[fmt], **options)
        except Exception as err:  # whatever an encoder raises on metadata it cannot write
            reason = "; ".join(printed) or f"{type(err).__name__}: {err}"
            raise ImageError(f"cannot encode the result as {fmt} with the input's metadata ({reason})") from None
    return buffer.getvalue()


def icc_space(icc: bytes) -> str | None:
    """The colour space an ICC profile's pixels are in (``'RGB '``, ``'GRAY'``, ``'CMYK'``,
    ``'Lab '``...; bytes 16-19 of its header), None for a block too short to be one. Only a
    profile of the written pixels' space is kept: a CMYK JPEG's profile on the RGB pixels it
    is decoded to, or an RGB profile on a grey PNG, makes viewers show wrong colours (and
    libpng warn about the file)."""
    return icc[16:20].decode("latin-1") if len(icc) >= 128 else None


def _tiff_exif(exif: bytes) -> bytes | None:
    """An EXIF block as a TIFF written through libtiff can hold it: the main directory's
    descriptive tags (:func:`featurewarp_cli.io.decode.descriptive_exif`); None if broken or empty."""
    from PIL import Image

    from .decode import descriptive_exif

    try:
        whole = Image.Exif()
        whole.load(exif)
        kept = descriptive_exif(whole)
        return kept.tobytes() if len(kept) else None
    except Exception:  # a broken block is not kept
        return None

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

from . import ImageError, metadata, profiles, tiff
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


def keeps_gray_alpha(image: np.ndarray, fmt: str) -> bool:
    """Whether :func:`encode_image` writes ``image`` as gray + alpha: 8-bit gray + alpha
    pixels (C = 2) as PNG or TIFF (by Pillow; it writes that form at 8 bits only, so 16-bit
    gray + alpha goes out as BGRA, as every other format's does)."""
    return image.ndim == 3 and image.shape[2] == 2 and image.dtype == np.uint8 and fmt in ("png", "tiff")


def stored_form(image: np.ndarray, fmt: str, transparent: bool = False) -> tuple[int, int]:
    """(channels, bits per sample) of ``image`` as :func:`encode_image` stores it as ``fmt``:
    gray + alpha as BGRA where ``fmt`` has no 8-bit gray + alpha form (:func:`keeps_gray_alpha`),
    alpha laid over the background where ``fmt`` has none (a GIF keeps it, cut at half, where
    ``transparent``: its background None), 8 bits where it holds no more."""
    channels = 1 if image.ndim == 2 else int(image.shape[2])
    channels = 4 if channels == 2 and not keeps_gray_alpha(image, fmt) else channels
    if channels == 4 and not FORMATS[fmt].alpha and not (fmt == "gif" and transparent):
        channels = 3
    if channels == 1 and fmt in ("webp", "gif"):       # no gray form: colour (WebP), a palette (GIF)
        channels = 3
    return channels, 8 if FORMATS[fmt].eight_bit else 8 * image.dtype.itemsize


#: Formats whose ICC profile, EXIF, XMP and resolution are kept: by Pillow for 8-bit samples;
#: 16-bit PNG and TIFF by OpenCV, their chunks or tags added (:mod:`featurewarp_cli.io.metadata`).
METADATA_FORMATS = {"jpg": "JPEG", "png": "PNG", "webp": "WEBP", "tiff": "TIFF"}
#: JPEG quality from which the chroma is not subsampled (4:4:4), as ImageMagick does; below it
#: 4:2:0. At the default 95, 4:2:0 put the result 0.90 % RMSE off the lossless one (ImageMagick's
#: 4:4:4: 0.62 %) and bled saturated red edges.
FULL_CHROMA_QUALITY = 90


def full_chroma(quality: int | None) -> bool:
    """Whether a JPEG at ``quality`` (None: the default 95) keeps its chroma whole (4:4:4)."""
    return (quality or 95) >= FULL_CHROMA_QUALITY


def encode_image(image: np.ndarray, fmt: str, background=(255, 255, 255), quality: int | None = None,
                 icc: bytes | None = None, exif: bytes | None = None, *, xmp: bytes | None = None,
                 dpi: tuple[float, float] | None = None) -> bytes:
    """Encode ``image`` as format ``fmt`` (a name of :data:`FORMATS`) with fixed settings.

    Parameters
    ----------
    image : (h, w) or (h, w, C) ndarray, uint8 or uint16, C in 1..4, BGR(A) channel order
        Gray + alpha (C = 2) is stored as such where :func:`keeps_gray_alpha`, else as BGRA.
    fmt : str
    background : (r, g, b) or None
        Colour that alpha is composited over for formats without alpha; None: white, but a GIF's
        pixels are transparent where alpha is under half.
    quality : int, optional
        1..100 for JPEG (default 95) and WebP (lossy when given; default lossless); other
        formats ignore it.
    icc, exif : bytes, optional
        An ICC profile and an EXIF block to store (JPEG, PNG, WebP, TIFF). A grey profile on
        pixels written in colour is turned into the RGB one of its tone
        (:func:`featurewarp_cli.io.profiles.for_pixels`); one of another space is left out.
    xmp : bytes, optional
        An XMP packet to store (JPEG up to :data:`featurewarp_cli.io.metadata.JPEG_XMP_BYTES`,
        PNG, WebP, TIFF); a longer one is left out of a JPEG (:func:`featurewarp_cli.io.metadata.unkept`
        says so).
    dpi : (float, float), optional
        A resolution in pixels per inch to store (JPEG, PNG, TIFF, BMP; WebP only in its EXIF).
        :class:`featurewarp_cli.io.metadata.Metadata` gives all four: ``**kept.keywords()``.

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
    gray_alpha = keeps_gray_alpha(image, fmt)   # OpenCV writes 1, 3 or 4 channels: Pillow's LA
    image = image if gray_alpha else gray_alpha_to_bgra(image)
    if not FORMATS[fmt].alpha and not (fmt == "gif" and background is None):     # GIF: 1-bit alpha
        image = flatten(image, background or (255, 255, 255))
    if FORMATS[fmt].eight_bit:
        image = to_eight_bit(image)
    if fmt == "gif":
        return _gif(image)
    lossless_alpha = fmt == "webp" and quality is None and image.ndim == 3 and image.shape[2] == 4
    exif, xmp, dpi = bytes(exif) if exif else None, bytes(xmp) if xmp else None, dpi or None
    exif = exif and metadata.sized_exif(exif, image.shape[1], image.shape[0])
    given = icc or exif or xmp or dpi
    icc = profiles.for_pixels(icc, 1 if image.ndim == 2 or gray_alpha else image.shape[2])
    if fmt == "jpg" and xmp and metadata.jpeg_xmp_unfit(xmp):
        xmp = None                                # said before the work (metadata.unkept)
    if (given or lossless_alpha or gray_alpha) and fmt in METADATA_FORMATS and image.dtype == np.uint8:
        data = _pillow_encode(image, fmt, quality, icc, exif, xmp, dpi)
        return metadata.tiff_with_exif_directories(data, exif) if fmt == "tiff" else data
    settings = list(SETTINGS[fmt])
    if quality is not None and fmt in ("jpg", "webp"):
        settings[1] = int(quality)
    if fmt == "jpg":
        settings += [cv2.IMWRITE_JPEG_SAMPLING_FACTOR, cv2.IMWRITE_JPEG_SAMPLING_FACTOR_444 if full_chroma(quality)
                     else cv2.IMWRITE_JPEG_SAMPLING_FACTOR_420]
    with captured_stderr():
        ok, buf = cv2.imencode(FORMATS[fmt].extension, image, settings)
    if not ok:
        raise ImageError(f"cannot encode the result as {fmt}")
    data = buf.tobytes()
    if fmt == "png" and (icc or exif or xmp or dpi):
        return metadata.png_with(data, icc, exif, xmp, dpi)
    if fmt == "tiff":
        return _tagged_tiff(data, image.ndim == 3 and image.shape[2] == 4, icc, exif, xmp, dpi)
    return metadata.bmp_with(data, dpi) if fmt == "bmp" else data


def _tagged_tiff(data: bytes, alpha: bool, icc: bytes | None, exif: bytes | None, xmp: bytes | None,
                 dpi) -> bytes:
    """OpenCV's TIFF with ExtraSamples naming its alpha, and the metadata libtiff's writer in
    OpenCV leaves out, set in its directory (:func:`featurewarp_cli.io.tiff.with_tags`): the
    ICC profile, the XMP packet, the EXIF's descriptive tags and the resolution."""
    if not (icc or exif or xmp or dpi):
        return tiff.with_alpha_tag(data) if alpha else data
    tags = {tiff.EXTRA_SAMPLES: (tiff.SHORT, [tiff.UNASSOCIATED])} if alpha else {}
    tags.update(_exif_tags(exif))
    if dpi and metadata.X_RESOLUTION not in tags:
        tags.update({tag: (tiff.RATIONAL, [metadata.rational(value).as_integer_ratio()])
                     for tag, value in zip((metadata.X_RESOLUTION, metadata.Y_RESOLUTION), dpi)})
        tags[metadata.RESOLUTION_UNIT] = (tiff.SHORT, [2])
    if icc:
        tags[34675] = (tiff.UNDEFINED, icc)
    if xmp:
        tags[700] = (tiff.BYTE, xmp)
    tagged = tiff.with_tags(data, tags)
    if tagged is None:
        raise ImageError("cannot store the input's metadata in the TIFF (over 4 GiB); use --strip")
    return metadata.tiff_with_exif_directories(tagged, exif)


def _exif_tags(exif: bytes | None) -> dict:
    """An EXIF block's descriptive tags (:data:`featurewarp_cli.io.metadata.TIFF_DESCRIPTIVE_TAGS`)
    as :func:`featurewarp_cli.io.tiff.with_tags` takes them: text as ASCII, resolutions as
    RATIONAL, numbers as SHORT; {} for none or a broken block."""
    from PIL import Image

    if not exif:
        return {}
    whole = Image.Exif()
    try:
        whole.load(exif)
        kept = metadata.descriptive_exif(whole)
    except Exception:  # a broken block is not kept
        return {}
    tags = {}
    for tag, value in kept.items():
        if isinstance(value, str):
            tags[tag] = (tiff.ASCII, value.encode("utf-8") + b"\0")
        elif tag in (metadata.X_RESOLUTION, metadata.Y_RESOLUTION):
            try:
                tags[tag] = (tiff.RATIONAL, [metadata.rational(float(value)).as_integer_ratio()])
            except (TypeError, ValueError, ZeroDivisionError):
                continue
        elif isinstance(value, int) and 0 <= value < 65536:
            tags[tag] = (tiff.SHORT, [value])
    return tags


#: A GIF pixel under this alpha is transparent, one at or above it opaque (as ImageMagick cuts).
GIF_ALPHA_CUT = 128
#: The GIF palette index of transparent pixels (the other 255 are the picture's colours).
GIF_TRANSPARENT = 255


def _gif(image: np.ndarray) -> bytes:
    """8-bit gray, BGR or BGRA pixels as a GIF by Pillow (:func:`gif_picture`; BGRA: transparent
    where alpha is under :data:`GIF_ALPHA_CUT`)."""
    import io

    transparent = image.ndim == 3 and image.shape[2] == 4
    buffer = io.BytesIO()
    gif_picture(image, transparent).save(buffer, "GIF", **({"transparency": GIF_TRANSPARENT} if transparent else {}))
    return buffer.getvalue()


def gif_picture(image: np.ndarray, transparent: bool = False):
    """8-bit gray, BGR or BGRA pixels as one GIF picture (a Pillow image): gray as a gray palette,
    colour quantised to an adaptive palette of 256 (median cut, Floyd-Steinberg dither); with
    ``transparent``, a pixel whose alpha is under :data:`GIF_ALPHA_CUT` takes the index
    :data:`GIF_TRANSPARENT` and the colours 255 entries. OpenCV's GIF encoder takes a fixed
    palette: on the astronaut under ``arc --angle 200`` a mean error of 20.7 levels, and a band
    of bright yellow along the outline (the adaptive palette: 3.0)."""
    from PIL import Image

    if image.ndim == 2:
        return Image.fromarray(image)
    colour = Image.fromarray(rgb_order(np.ascontiguousarray(image[:, :, :3])))
    if not transparent:
        return colour.quantize(256)
    paletted = colour.quantize(GIF_TRANSPARENT)
    indices = np.asarray(paletted).copy()
    indices[image[:, :, 3] < GIF_ALPHA_CUT] = GIF_TRANSPARENT
    picture = Image.fromarray(indices, "P")
    palette = paletted.getpalette()[: 3 * GIF_TRANSPARENT]
    picture.putpalette(palette + [0] * (768 - len(palette)))
    return picture


def rgb_order(image: np.ndarray) -> np.ndarray:
    """BGR(A) pixels in Pillow's order, RGB(A); gray and gray + alpha as they are."""
    if image.ndim == 2 or image.shape[2] == 2:
        return image
    return cv2.cvtColor(image, cv2.COLOR_BGRA2RGBA if image.shape[2] == 4 else cv2.COLOR_BGR2RGB)


def webp_options(quality: int | None) -> dict:
    """Pillow's WebP settings: lossy at ``quality``, else lossless keeping the colour under
    transparent pixels as given (libwebp's ``exact``) at OpenCV's effort (70)."""
    return {"quality": quality} if quality else {"lossless": True, "quality": 70, "exact": True}


def _pillow_encode(image: np.ndarray, fmt: str, quality: int | None, icc: bytes | None,
                   exif: bytes | None, xmp: bytes | None = None, dpi=None) -> bytes:
    """8-bit BGR(A) or grey pixels as ``fmt`` bytes with their ICC profile (of their space,
    :func:`featurewarp_cli.io.profiles.for_pixels`), EXIF, XMP and resolution (where ``fmt``
    stores them), by Pillow, with the same settings as OpenCV's path where Pillow has them
    (JPEG: 4:4:4 from :data:`FULL_CHROMA_QUALITY`). Lossless WebP keeps the colour
    under transparent pixels as given (libwebp's ``exact``) with OpenCV's effort (70): about as
    fast and small as OpenCV's (arc of the astronaut, 976x538: 0.23 s, 399 kB against 0.21 s, 398 kB)."""
    import io

    from PIL import Image

    image = rgb_order(image)
    options = {"icc_profile": icc} if icc else {}
    if exif and fmt == "tiff":
        exif = _tiff_exif(exif)
    if exif:
        options["exif"] = exif
    options.update(_extra_options(fmt, exif, xmp, dpi))
    options.update({"jpg": {"quality": quality or 95, "optimize": False, "progressive": False,
                            "subsampling": 0 if full_chroma(quality) else 2},
                    "png": {"compress_level": 1},
                    "webp": webp_options(quality),
                    "tiff": {"compression": "tiff_lzw"}}[fmt])
    if fmt == "tiff":                            # LZW with the horizontal predictor, as OpenCV writes
        if "tiffinfo" not in options:            # which, given, Pillow writes instead of ``exif``
            options["tiffinfo"] = Image.Exif()
            options["tiffinfo"].load(exif)       # (nothing where exif is None)
        options["tiffinfo"][317] = 2             # 317: Predictor, 2: horizontal
    buffer = io.BytesIO()
    with captured_stderr() as printed:
        try:
            Image.fromarray(image).save(buffer, METADATA_FORMATS[fmt], **options)
        except Exception as err:  # whatever an encoder raises on metadata it cannot write
            reason = "; ".join(printed) or f"{type(err).__name__}: {err}"
            raise ImageError(f"cannot encode the result as {fmt} with the input's metadata ({reason})") from None
    return buffer.getvalue()


def _extra_options(fmt: str, exif: bytes | None, xmp: bytes | None, dpi) -> dict:
    """Pillow's options for the XMP packet and the resolution in ``fmt``: JPEG ``xmp`` and
    ``dpi`` (JFIF), PNG ``dpi`` (pHYs) and an iTXt chunk, WebP ``xmp`` (its resolution only in the
    EXIF), TIFF ``dpi`` where the EXIF states none and tag 700 (BYTE) beside the EXIF's tags."""
    from PIL import PngImagePlugin, TiffImagePlugin

    options, tags = {}, _exif_tags(exif) if fmt == "tiff" else {}
    if dpi and fmt in ("jpg", "png") or (fmt == "tiff" and dpi and metadata.X_RESOLUTION not in tags):
        options["dpi"] = dpi
    if xmp and fmt in ("jpg", "webp"):
        options["xmp"] = xmp
    elif xmp and fmt == "png":
        options["pnginfo"] = PngImagePlugin.PngInfo()
        options["pnginfo"].add_itxt("XML:com.adobe.xmp", xmp.decode("utf-8", "replace"))
    elif xmp and fmt == "tiff":
        directory = TiffImagePlugin.ImageFileDirectory_v2()
        for tag, (_, value) in tags.items():
            directory[tag] = value.rstrip(b"\0").decode("utf-8") if isinstance(value, bytes) else \
                (value[0] if not isinstance(value[0], tuple) else TiffImagePlugin.IFDRational(*value[0]))
        directory[700] = xmp
        directory.tagtype[700] = 1
        options["tiffinfo"] = directory
    return options


def _tiff_exif(exif: bytes) -> bytes | None:
    """An EXIF block as a TIFF written through libtiff can hold it: the main directory's
    descriptive tags (:func:`featurewarp_cli.io.metadata.descriptive_exif`); None if broken or empty."""
    from PIL import Image


    try:
        whole = Image.Exif()
        whole.load(exif)
        kept = metadata.descriptive_exif(whole)
        return kept.tobytes() if len(kept) else None
    except Exception:  # a broken block is not kept
        return None

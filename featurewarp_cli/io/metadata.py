"""The input's metadata that the output keeps: EXIF, XMP and resolution, read from its header
(the ICC profile is :mod:`featurewarp_cli.io.profiles`'), and written where Pillow does not.

The decoder's :class:`featurewarp_cli.io.decode.Header` holds each of them in a field of its
own (:func:`carried`); what the output keeps of them is a :class:`Metadata`, whose fields the
encoder (:func:`featurewarp_cli.io.encode.encode_image`) takes as keyword arguments. Written:

=========  =====================  =============================  ==============================
format     resolution             XMP                            by
=========  =====================  =============================  ==============================
JPEG       JFIF density           APP1 (up to 65 504 bytes)      Pillow
PNG        pHYs                   iTXt ``XML:com.adobe.xmp``     Pillow; 16-bit: chunks added
                                                                 to OpenCV's file
TIFF       X/YResolution          tag 700                        Pillow; 16-bit: tags added to
                                                                 OpenCV's directory
WebP       EXIF X/YResolution     XMP chunk                      Pillow
BMP        pixels per metre       (none)                         OpenCV, its header patched
=========  =====================  =============================  ==============================
"""

from __future__ import annotations

import re
import struct
import warnings
import zlib
from dataclasses import dataclass, field
from fractions import Fraction

from .png import make_chunk

#: The tags of a TIFF's first directory that describe the picture rather than its layout:
#: a TIFF's "EXIF" is that whole directory, and its layout tags (sample format, strips,
#: compression...) written into another file made it unreadable (float samples declared).
TIFF_DESCRIPTIVE_TAGS = (270, 271, 272, 274, 282, 283, 296, 305, 306, 315, 33432)
ORIENTATION, X_RESOLUTION, Y_RESOLUTION, RESOLUTION_UNIT = 0x0112, 282, 283, 296
#: The Exif directory's pointer, and its tags of the picture's width and height in pixels.
EXIF_IFD, PIXEL_X_DIMENSION, PIXEL_Y_DIMENSION = 0x8769, 0xA002, 0xA003
#: The GPS directory's pointer, the Exif directory's pointer to its interoperability one, and
#: YCbCrPositioning (of JPEG's layout: no loss where a TIFF leaves it out).
GPS_IFD, INTEROP_IFD, Y_CB_CR_POSITIONING = 0x8825, 0xA005, 0x0213
#: The most XMP bytes a JPEG holds: one APP1 segment less its name (Pillow refuses more).
JPEG_XMP_BYTES = 65504
#: Formats that keep no metadata at all.
BARE_FORMATS = {"bmp": "BMP", "gif": "GIF"}
#: An orientation in an XMP packet, as an attribute or an element (Pillow's exif_transpose
#: rewrites the same two forms).
_XMP_ORIENTATION = re.compile(rb'(tiff:Orientation(?:="|>))([0-9])')


@dataclass(frozen=True)
class Metadata:
    """The input's metadata that an output keeps (all None: nothing, as under ``--strip``).

    Attributes
    ----------
    icc : bytes or None
        The ICC colour profile of the decoded pixels.
    exif : bytes or None
        The EXIF block, its orientation set to 1 (the decoded pixels are upright).
    xmp : bytes or None
        The XMP packet, its orientation set to 1.
    dpi : (float, float) or None
        Horizontal and vertical resolution in pixels per inch.
    """

    icc: bytes | None = field(default=None, repr=False)
    exif: bytes | None = field(default=None, repr=False)
    xmp: bytes | None = field(default=None, repr=False)
    dpi: tuple[float, float] | None = None

    @classmethod
    def of(cls, header) -> Metadata:
        """What ``header`` (a :class:`featurewarp_cli.io.decode.Header`, or None) holds."""
        if header is None:
            return cls()
        return cls(header.icc, header.exif, header.xmp, header.dpi)

    def keywords(self) -> dict:
        """The fields as :func:`featurewarp_cli.io.encode.encode_image` takes them."""
        return {"icc": self.icc, "exif": self.exif, "xmp": self.xmp, "dpi": self.dpi}


def descriptive_exif(exif):
    """The tags of ``exif`` (a :class:`PIL.Image.Exif`)'s main directory listed in
    :data:`TIFF_DESCRIPTIVE_TAGS`: what of a TIFF's directory describes the picture, and what a
    TIFF written through libtiff can hold (it writes no sub-directory: a camera's Exif and GPS
    blocks made it fail with 'Bad LONG8 or IFD8 value' on stderr and a RuntimeError)."""
    from PIL import Image

    kept = Image.Exif()
    for tag in TIFF_DESCRIPTIVE_TAGS:
        if tag in exif:
            kept[tag] = exif[tag]
    return kept


def _with_directories(kept, whole):
    """``kept`` (a :class:`PIL.Image.Exif`) with the Exif and GPS directories of ``whole``."""
    for pointer in (EXIF_IFD, GPS_IFD):
        if directory := whole.get_ifd(pointer):
            kept.get_ifd(pointer).update(directory)
    return kept


def _upright_exif(image, oriented) -> bytes | None:
    """The image's EXIF block with its orientation set to 1, or None (none, or broken); of a
    TIFF, only its descriptive tags (:data:`TIFF_DESCRIPTIVE_TAGS`)."""
    if image.format not in oriented or (image.format == "PNG" and "exif" not in image.info):
        return None
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")            # a broken block is dropped, not reported
            exif = image.getexif()
        if image.format == "TIFF":                     # its camera and GPS directories too
            exif = _with_directories(descriptive_exif(exif), exif)
        if not len(exif):
            return None
        if ORIENTATION in exif:
            exif[ORIENTATION] = 1
        return exif.tobytes()
    except Exception:  # a broken EXIF block is not kept
        return None


def sized_exif(exif: bytes, width: int, height: int) -> bytes:
    """``exif`` with the pixel size it states (PixelXDimension, PixelYDimension) set to the
    output's: a warp changes the size, and the input's stayed (viewers and asset managers read
    it). A block that states none, or cannot be read, as it is."""
    from PIL import Image

    try:
        whole = Image.Exif()
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            whole.load(exif)
            camera = whole.get_ifd(EXIF_IFD)
            if not {PIXEL_X_DIMENSION, PIXEL_Y_DIMENSION} & set(camera):
                return exif
            for tag, size in ((PIXEL_X_DIMENSION, width), (PIXEL_Y_DIMENSION, height)):
                if tag in camera:                 # only those stated: the block keeps its length
                    camera[tag] = int(size)
            return whole.tobytes()
    except Exception:  # a broken block is kept as it came (as decoding kept it)
        return exif


def left_out_of_tiff(exif: bytes) -> int:
    """How many tags of the EXIF block ``exif``'s main directory a TIFF output leaves out: it
    keeps :data:`TIFF_DESCRIPTIVE_TAGS` and the Exif and GPS directories
    (:func:`tiff_with_exif_directories`); YCbCrPositioning, of JPEG's layout, is no loss. 0 where
    the block cannot be read (the encoder keeps none of it either)."""
    from PIL import Image

    try:
        whole = Image.Exif()
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            whole.load(exif)
        return sum(tag not in TIFF_DESCRIPTIVE_TAGS + (EXIF_IFD, GPS_IFD, Y_CB_CR_POSITIONING) for tag in whole)
    except Exception:  # a broken block
        return 0


def tiff_with_exif_directories(data: bytes, exif: bytes | None) -> bytes:
    """A one-page TIFF ``data`` with the Exif and GPS directories of the EXIF block ``exif``
    (capture date, exposure... and GPS position; the descriptive tags are the first directory's
    own) written after it and pointed to from its first directory (tags 34665 and 34853), as a
    camera's TIFF holds them. ``data`` as it is where ``exif`` has neither, where it cannot be
    read, and for a BigTIFF (whose pointers are 8 bytes; one is written only past 4 GiB)."""
    from PIL import Image

    from . import tiff

    found = tiff.first_directory(data)
    if not exif or found is None or found[3]:
        return data
    try:
        whole, subs = Image.Exif(), Image.Exif()
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            whole.load(exif)
            for pointer in (EXIF_IFD, GPS_IFD):
                directory = dict(whole.get_ifd(pointer))
                if pointer == EXIF_IFD:            # a TIFF's size is its own tags' (libtiff: LONG only)
                    directory.pop(PIXEL_X_DIMENSION, None), directory.pop(PIXEL_Y_DIMENSION, None)
                    if INTEROP_IFD in directory:
                        directory[INTEROP_IFD] = dict(whole.get_ifd(INTEROP_IFD))
                if directory:
                    subs[pointer] = directory
        if not len(subs):
            return data
        subs.endian = found[0]                            # the file's byte order, not the camera's
        at = len(data) + len(data) % 2                    # the block's header starts on a word
        block = subs.tobytes(offset=at + 8)[6:]           # "Exif\0\0" off; offsets as placed at ``at``
        pointers = {pointer: (tiff.LONG, [value]) for pointer in (EXIF_IFD, GPS_IFD)
                    if (value := tiff.page_values(block, pointer)[0]) is not None}
    except Exception:  # a broken block: the descriptive tags only, as before
        return data
    return tiff.with_tags(data + b"\0" * (at - len(data)) + block, pointers) or data


def upright_xmp(xmp) -> bytes | None:
    """An XMP packet (bytes or str) with its tiff:Orientation set to 1; None for none."""
    if not xmp:
        return None
    packet = xmp.encode("utf-8") if isinstance(xmp, str) else bytes(xmp)
    return _XMP_ORIENTATION.sub(rb"\g<1>1", packet)


def _exif_resolution(exif) -> tuple[float, float] | None:
    """(x, y) pixels per inch from a TIFF directory's or EXIF block's resolution tags; None
    without them or where the unit is none (1). TIFF's default unit is the inch."""
    try:
        x, y = float(exif[X_RESOLUTION]), float(exif.get(Y_RESOLUTION, exif[X_RESOLUTION]))
        unit = exif.get(RESOLUTION_UNIT, 2)
    except (KeyError, TypeError, ValueError, ZeroDivisionError):
        return None
    if unit not in (2, 3) or not (x > 0 and y > 0) or x != x or y != y:
        return None
    return (x * 2.54, y * 2.54) if unit == 3 else (x, y)


#: The highest resolution kept (pixels per inch): every output stores it (a TIFF's rationals, PNG's
#: pHYs and BMP's pixels per metre are 32-bit; 4294967295 dpi failed the write), and a scanner
#: stops far below (12 800).
MOST_DPI = 100_000.0


def resolution(image) -> tuple[float, float] | None:
    """The resolution (pixels per inch) an opened image states: JFIF density in inches or
    centimetres, else its EXIF's (JPEG); pHYs in metres (PNG); its tags (TIFF); its EXIF (WebP);
    pixels per metre (BMP). None where it states none (Pillow's made-up 72 dpi for a JPEG whose
    EXIF has no resolution is not taken), or one that is not above 0 and at most
    :data:`MOST_DPI`."""
    stated = _stated_resolution(image)
    if stated is None or not all(0.0 < float(v) <= MOST_DPI for v in stated):
        return None
    return stated


def _stated_resolution(image) -> tuple[float, float] | None:
    """:func:`resolution` as the image states it, unchecked."""
    info = image.info
    try:
        if image.format in ("JPEG", "MPO") and info.get("jfif_unit") in (1, 2) and all(info.get("jfif_density", ())):
            x, y = info["jfif_density"]
            return (x * 2.54, y * 2.54) if info["jfif_unit"] == 2 else (float(x), float(y))
        if image.format in ("PNG", "BMP") and "dpi" in info:
            x, y = (float(v) for v in info["dpi"])
            return (x, y) if x > 0 and y > 0 else None
        if image.format == "TIFF":
            return _exif_resolution(image.tag_v2)
        if image.format in ("JPEG", "MPO", "WEBP") and "exif" in info:
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                return _exif_resolution(image.getexif())
    except Exception:  # broken values: no resolution
        return None
    return None


def _has_iptc(image) -> bool:
    """Whether an opened image holds an IPTC block (Photoshop resource 0x0404 of a JPEG, or a
    TIFF's tag 33723)."""
    if image.format == "TIFF":
        return 33723 in getattr(image, "tag_v2", {})
    return 0x0404 in (image.info.get("photoshop") or {})


def carried(image, oriented) -> tuple[bytes | None, bytes | None, tuple[float, float] | None, bool]:
    """What of an opened image's metadata the output keeps, besides its ICC profile.

    Parameters
    ----------
    image : PIL.Image.Image
        Opened, not decoded.
    oriented : set of str
        Pillow's names of the formats whose EXIF orientation is applied.

    Returns
    -------
    exif : bytes or None
        Its EXIF block, upright (:func:`_upright_exif`).
    xmp : bytes or None
        Its XMP packet, upright (:func:`upright_xmp`).
    dpi : (float, float) or None
        Its resolution in pixels per inch (:func:`resolution`).
    iptc : bool
        Whether it holds an IPTC block (which no output keeps).
    """
    return _upright_exif(image, oriented), upright_xmp(image.info.get("xmp")), resolution(image), _has_iptc(image)


def rational(value: float) -> Fraction:
    """A resolution as a fraction of small terms (a TIFF RATIONAL)."""
    return Fraction(value).limit_denominator(10000)


def png_with(data: bytes, icc: bytes | None, exif: bytes | None, xmp: bytes | None, dpi) -> bytes:
    """PNG bytes (OpenCV's) with an iCCP, pHYs, eXIf and iTXt XMP chunk after the IHDR, as
    Pillow writes them (the profile deflated by zlib at its default level: the same bytes)."""
    chunks = b""
    if icc:
        chunks += make_chunk(b"iCCP", b"ICC Profile\0\0" + zlib.compress(icc))
    if dpi:
        chunks += make_chunk(b"pHYs", struct.pack(">IIB", *(round(v / 0.0254) for v in dpi), 1))
    if exif:
        chunks += make_chunk(b"eXIf", exif[6:] if exif.startswith(b"Exif\0\0") else exif)
    if xmp:
        chunks += make_chunk(b"iTXt", b"XML:com.adobe.xmp\0\0\0\0\0" + xmp)
    at = 8 + 12 + int.from_bytes(data[8:12], "big")          # after the IHDR
    return data[:at] + chunks + data[at:]


def bmp_with(data: bytes, dpi) -> bytes:
    """BMP bytes with their pixels per metre set from ``dpi`` (OpenCV writes 0)."""
    if not dpi or len(data) < 46 or data[:2] != b"BM":
        return data
    return data[:38] + struct.pack("<2i", *(round(v / 0.0254) for v in dpi)) + data[46:]


def pillow_xmp_jpeg() -> bool:
    """Whether this Pillow writes a JPEG's XMP (``xmp=``, from Pillow 11)."""
    import PIL

    return int(PIL.__version__.split(".")[0]) >= 11


def jpeg_xmp_unfit(xmp: bytes) -> str | None:
    """Why the XMP packet ``xmp`` cannot go into a JPEG (too large for its segment, or a
    Pillow that writes none), or None where it can: one rule for the warning and the encoder."""
    if len(xmp) > JPEG_XMP_BYTES:
        return f"is more than a JPEG holds ({JPEG_XMP_BYTES})"
    return None if pillow_xmp_jpeg() else "cannot be written into a JPEG by this Pillow (Pillow 11 can)"


def unkept(header, fmt: str, strip: bool = False) -> list[str]:
    """Warnings for what of the input's colours and metadata the output cannot keep.

    Parameters
    ----------
    header : featurewarp_cli.io.decode.Header or None
        The input's header (None: nothing to say).
    fmt : str
        The output format name.
    strip : bool
        ``--strip``: the metadata is dropped on purpose, and only the colours are said.

    Returns
    -------
    list of str
        A CMYK input without a profile to convert it by; with metadata kept, a BMP or GIF
        output (which keeps none), an XMP packet too long for a JPEG, an IPTC block.
    """
    said = []
    if header is None:
        return said
    if getattr(header, "mode", None) == "CMYK" and not header.icc:
        said.append("the input is CMYK without a colour profile featurewarp can use: its colours are converted "
                    "to RGB without colour management and may be off (convert it to RGB with its profile first)")
    if strip:
        return said
    xmp = header.xmp
    held = [name for name, present in (("ICC profile", header.icc), ("EXIF", header.exif), ("XMP", xmp))
            if present]
    if fmt in BARE_FORMATS and held:
        return said + [f"{BARE_FORMATS[fmt]} output keeps none of the input's {', '.join(held)}: left out "
                       "(--strip leaves them out without this warning)"]
    if fmt == "tiff" and header.exif and (dropped := left_out_of_tiff(header.exif)):
        said.append(f"TIFF output keeps the EXIF's descriptive tags (make, model, artist, copyright...) and its "
                    f"camera and GPS data, not the input's {dropped} other main tag{'s' * (dropped > 1)} "
                    f"(JPEG, PNG and WebP keep them)")
    if fmt == "jpg" and xmp and (reason := jpeg_xmp_unfit(xmp)):
        said.append(f"the input's XMP ({len(xmp)} bytes) {reason}: left out")
    if header.iptc:
        said.append("the input's IPTC block is left out (no output keeps it; its XMP, where tools mirror the "
                    "IPTC fields, is kept)")
    return said

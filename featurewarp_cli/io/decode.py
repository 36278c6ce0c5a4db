"""Reading images and masks: bytes read once, the header checked, pixels decoded, turned upright.

``-`` stands for stdin. The bytes of an input are read once; Pillow reads the size
and the EXIF orientation from the header (it opens files lazily and decodes no
pixel), the size is checked against the caller's limit, and only then does OpenCV
decode the pixels (faster than Pillow here: 12 MP PNG 0.24 s against 0.33 s, JPEG
0.06 s against 0.15 s). For the formats OpenCV decodes but Pillow cannot read the
header of (Radiance HDR, PAM, OpenEXR), OpenCV's own limit applies
(:func:`featurewarp_cli.io.limits.limit_opencv_decoders`).

Importing this module turns off Pillow's own decompression-bomb limit
(``PIL.Image.MAX_IMAGE_PIXELS``) in the process: Pillow only reads headers here, and the
caller's ``max_pixels`` decides which sizes are accepted.
"""

from __future__ import annotations

import importlib
import io
import logging
import os
import re
import shlex
import sys
import threading
import warnings
from dataclasses import dataclass, field

import numpy as np

from . import ImageError, png, profiles, tiff
from .capture import captured_stderr
from .metadata import carried
from .limits import MAX_PIXELS, check_pixels, check_size, limit_opencv_decoders, opencv_limit, size_text

limit_opencv_decoders(MAX_PIXELS, replace=False)        # before cv2 loads; the CLI may have set it
import cv2  # noqa: E402
from PIL import Image  # noqa: E402

# Silence OpenCV's own log (level 0); before 4.13 the call is cv2.setLogLevel.
_LOGGING = getattr(cv2.utils, "logging", cv2)
_LOGGING.setLogLevel(0)
# Pillow logs what it makes of hostile headers ("More samples per pixel than can be decoded"):
# without a handler Python prints it on stderr, beside our one line; the error that follows says it.
logging.getLogger("PIL").addHandler(logging.NullHandler())
#: Scans (SOS markers, which entropy-coded data cannot contain) a JPEG may have: each costs a pass
#: over the image, so 10 000 of them in 376 KB took 13 s at 4 MP (libjpeg-turbo's advice: 500).
MAX_JPEG_SCANS = 500
#: What a decoder prints about data it decodes anyway, and refused: libjpeg's corrupt or missing
#: data, and libtiff's errors (an LZW or deflate strip that fails its check decodes to garbage,
#: 64-84 grey levels off on average) and its PackBits overruns, through OpenCV's log.
CORRUPT = re.compile(r"^(Corrupt JPEG.*|Premature end.*)|TIFF_Error (?!TIFF\w*Directory)(.*)"
                     r"|TIFF_Warning (.*(Corrupt|Discarding).*)")
#: One decode at a time: OpenCV's log level and the capture of file descriptor 2 are the process's.
_DECODING = threading.Lock()
Image.MAX_IMAGE_PIXELS = None           # the caller's max_pixels decides, not Pillow's default

# Pillow's header readers for the formats OpenCV decodes, imported one by one so that
# Image.open never loads all of Pillow's plugins. AVIF needs a Pillow with its AVIF plugin
# (recent releases; 9.3 has none): without it OpenCV's limit covers AVIF, as it does HDR,
# PAM and OpenEXR.
for _plugin in ("Avif", "Bmp", "Gif", "Jpeg", "Jpeg2K", "Png", "Ppm", "Sun", "Tiff", "WebP"):
    try:
        importlib.import_module(f"PIL.{_plugin}ImagePlugin")
    except ImportError:
        pass
#: Pillow's names of the formats whose header is read before decoding.
HEADER_FORMATS = tuple(name for name in ("PNG", "JPEG", "WEBP", "TIFF", "BMP", "GIF", "PPM", "SUN",
                                         "JPEG2000", "AVIF") if name in Image.OPEN)
#: Formats whose EXIF orientation is applied (OpenCV's TIFF decoder turns TIFFs itself; MPO
#: is a camera's multi-picture JPEG).
ORIENTED = {"JPEG", "MPO", "PNG", "WEBP", "TIFF"}
#: Formats that OpenCV decodes as stored, so that they are turned upright here.
TURNED_HERE = ORIENTED - {"TIFF"}
#: Formats whose CMYK pixels are converted to sRGB through their ICC profile (littlecms); OpenCV's
#: conversion ignores it (a CMYK product shot came out 10.6 % RMSE off, orange turned red).
CMYK_MANAGED = {"JPEG", "MPO"}
_EXIF_ORIENTATION = 0x0112

#: EXIF orientation (2..8) -> the array operation that shows the image upright.
ORIENTATIONS = {
    2: lambda a: a[:, ::-1],
    3: lambda a: a[::-1, ::-1],
    4: lambda a: a[::-1],
    5: lambda a: a.swapaxes(0, 1),
    6: lambda a: np.rot90(a, -1),
    7: lambda a: np.rot90(a, 2).swapaxes(0, 1),
    8: lambda a: np.rot90(a, 1),
}


@dataclass(frozen=True)
class Header:
    """What an image's header says, read without decoding a pixel.

    Attributes
    ----------
    format : str
        Pillow's name of the format (``PNG``, ``JPEG`` ...).
    width, height : int
        The stored size.
    orientation : int
        EXIF orientation 1..8 (1: upright as stored).
    animated : bool
        More than one frame or page (animated GIF, PNG or WebP, multi-page TIFF); the
        decoders take the first.
    icc : bytes or None
        The ICC colour profile of the decoded pixels, for the output to keep (of a CMYK
        JPEG: sRGB, which :func:`decode_image` converts it to through its own, if usable).
    exif : bytes or None
        The EXIF block (its orientation set to 1: the decoded pixels are upright), for the
        output to keep.
    mode : str or None
        Pillow's mode of the stored pixels (``RGB``, ``CMYK``, ``I;16``...).
    xmp : bytes or None
        The XMP packet (its orientation set to 1), for the output to keep.
    dpi : (float, float) or None
        The resolution in pixels per inch, for the output to keep.
    iptc : bool
        The file holds an IPTC block (which no output keeps: a warning says so).
    """

    format: str
    width: int
    height: int
    orientation: int = 1
    animated: bool = False
    icc: bytes | None = field(default=None, repr=False)
    exif: bytes | None = field(default=None, repr=False)
    mode: str | None = field(default=None, repr=False)
    xmp: bytes | None = field(default=None, repr=False)
    dpi: tuple[float, float] | None = field(default=None, repr=False)
    iptc: bool = field(default=False, repr=False)

    @property
    def upright_size(self) -> tuple[int, int]:
        """(width, height) once turned upright: an orientation of 5..8 swaps them."""
        return (self.height, self.width) if self.orientation >= 5 else (self.width, self.height)


#: The first bytes of every format the decoders read (a stream from stdin that starts with
#: none of them is refused after its first bytes, not read to its end: ``< /dev/zero``).
SIGNATURES = (b"\x89PNG", b"\xff\xd8\xff", b"GIF87a", b"GIF89a", b"BM", b"II*\x00", b"MM\x00*", b"II+\x00",
              b"MM\x00+", b"RIFF", b"\x00\x00\x00\x0cjP", b"\xff\x4f\xff\x51", b"P1", b"P2", b"P3", b"P4", b"P5",
              b"P6", b"P7", b"PF", b"Pf", b"#?RADIANCE", b"#?RGBE", b"v/1\x01", b"\x59\xa6\x6a\x95")
#: Formats of float samples, which the pipeline cannot warp: refused from their first bytes,
#: before OpenCV decodes them (a 196 MP Radiance HDR of 12 MB took 36 s and 4.6 GB to be
#: refused afterwards, and OpenCV's HDR decoder leaves a copy of the input in /tmp when killed).
FLOAT_FORMATS = ((b"#?RADIANCE", "Radiance HDR"), (b"#?RGBE", "Radiance HDR"), (b"v/1\x01", "OpenEXR"),
                 (b"PF\n", "PFM"), (b"Pf\n", "PFM"))
#: ISO media (AVIF, HEIF): the brand box at byte 4.
_FTYP = b"ftyp"
_CHUNK = 1 << 20


def looks_like_image(head: bytes) -> bool:
    """Whether ``head`` (a file's first bytes) starts like a format the decoders read.

    Parameters
    ----------
    head : bytes

    Returns
    -------
    bool
    """
    return head.startswith(SIGNATURES) or head[4:8] == _FTYP


def path_problem(path: str) -> str:
    """Why ``path`` cannot be read as an image file (for a message: ``f"{path} {problem}"``).

    Parameters
    ----------
    path : str
        A path that is not a regular file.

    Returns
    -------
    str
        'does not exist', 'is a folder, not a file', or 'is a device, pipe or socket, not a
        regular file (...)'.
    """
    if not os.path.exists(path):
        return "does not exist"
    if os.path.isdir(path):
        return "is a folder, not a file"
    return "is a device, pipe or socket, not a regular file (use '-' to read a stream from stdin)"


def read_bytes(path: str, max_bytes: int | None = None) -> bytes:
    """The bytes of a file, or of stdin for ``-``.

    Parameters
    ----------
    path : str
    max_bytes : int, optional
        A stream from stdin longer than this is refused while it is read (the memory
        budget); one whose first bytes are no image format's is refused at once.

    Raises
    ------
    ImageError
        When the file cannot be read, or stdin is too long or not an image.
    """
    if path == "-":
        if sys.stdin is None or getattr(sys.stdin, "closed", False):
            raise ImageError("stdin is closed; pipe an image into it (or give a file name)")
        if sys.stdin.isatty():
            raise ImageError("stdin is a terminal; pipe an image into it (or give a file name)")
        return _read_stream(sys.stdin.buffer, max_bytes)
    try:
        with open(path, "rb") as fh:
            return fh.read()
    except OSError as err:
        raise ImageError(f"cannot read {path}: {err.strerror or err}") from None


def _read_stream(stream, max_bytes: int | None) -> bytes:
    """Read a stream to its end in chunks, refusing it once it is not an image or too long."""
    chunks, total = [], 0
    while True:
        chunk = stream.read(_CHUNK)
        if not chunk:
            break
        if not chunks and len(chunk) >= 16 and not looks_like_image(chunk):
            raise ImageError("stdin is not an image: its first bytes are no format featurewarp reads")
        chunks.append(chunk)
        total += len(chunk)
        if max_bytes is not None and total > max_bytes:
            raise ImageError(f"stdin holds more than the memory limit of {size_text(max_bytes)} (--max-memory)")
    return b"".join(chunks)


def _orientation(image: Image.Image, data: bytes) -> int:
    """EXIF orientation of an opened (not decoded) image; 1 when none applies."""
    if image.format not in ORIENTED:
        return 1
    try:
        if image.format == "PNG" and "exif" not in image.info:
            exif = Image.Exif()             # an eXIf chunk after the pixels: Pillow would decode them
            exif.load(png.chunk(data, b"eXIf") or b"")
        else:
            exif = image.getexif()
        value = exif.get(_EXIF_ORIENTATION, 1)
    except Exception:  # a broken EXIF block: the pixels are shown as stored
        return 1
    return value if value in ORIENTATIONS else 1


def read_header(data: bytes) -> Header | None:
    """Format, size and EXIF orientation from the header of image bytes; no pixel is decoded.

    Returns
    -------
    Header, or None when the format is none of :data:`HEADER_FORMATS` or the header is
    broken (the decoder then decides, within OpenCV's limit).

    Examples
    --------
    >>> import cv2, numpy as np
    >>> read_header(cv2.imencode(".png", np.zeros((3, 5), np.uint8))[1].tobytes())
    Header(format='PNG', width=5, height=3, orientation=1, animated=False)
    """
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")            # a broken tag is the decoder's to judge; set
            with Image.open(io.BytesIO(data), formats=HEADER_FORMATS) as image:   # before opening, where Pillow warns
                size = image.size
                if image.format == "TIFF":          # Pillow reports a turned TIFF's size as shown
                    size = image.tag_v2.get(256, size[0]), image.tag_v2.get(257, size[1])
                icc = image.info.get("icc_profile") or None
                if image.mode == "CMYK":                   # decoded to sRGB through its profile, or not managed
                    icc = profiles.srgb() if image.format in CMYK_MANAGED and profiles.cmyk_usable(icc) else None
                orientation = _orientation(image, data)     # before carried() sets the EXIF's to 1
                exif, xmp, dpi, iptc = carried(image, ORIENTED)
                return Header(image.format, *size, orientation, bool(getattr(image, "is_animated", False)), icc,
                              exif, image.mode, xmp, dpi, iptc)
    except Exception:  # UnidentifiedImageError, or whatever a broken header raises in a plugin
        return _png_header(data)


def png_size(data: bytes) -> tuple[int, int] | None:
    """(width, height) of PNG bytes from their IHDR, at a fixed place (nothing is decoded); None
    for bytes that are no PNG."""
    if not data.startswith(b"\x89PNG\r\n\x1a\n") or data[12:16] != b"IHDR" or len(data) < 24:
        return None
    return int.from_bytes(data[16:20], "big"), int.from_bytes(data[20:24], "big")


def _png_header(data: bytes) -> Header | None:
    """A PNG's size from its IHDR where Pillow gave up on the file's metadata (a text chunk over
    Pillow's limit): the size checks must not depend on a metadata chunk parsing (a 422 KB
    file decoded 432 MB under ``--max-memory 100M``). None for other bytes."""
    size = png_size(data)
    if size is None or not all(size):
        return None                                  # no PNG, or no pixels: the decoder says so
    return Header("PNG", *size, 1, png.chunk(data, b"acTL") is not None)


def gray_alpha_to_bgra(image: np.ndarray) -> np.ndarray:
    """A (h, w, 2) gray + alpha image as (h, w, 4) BGRA (what the encoders take); others unchanged."""
    if image.ndim == 3 and image.shape[2] == 2:
        gray, alpha = image[:, :, 0], image[:, :, 1]
        return np.dstack([gray, gray, gray, alpha])
    return image


def _without_log_prefix(message: str) -> str:
    """A decoder's message without OpenCV's log prefix and its source location."""
    text = re.sub(r"^\[[^\]]*\]\s+global\s+\S+\s+(TIFF_Error |TIFF_Warning )?", "", message)
    error = re.search(r"error: \([^)]*\) (.*)", text)
    return error.group(1) if error else text


def _opencv_decode(data: bytes, name: str) -> np.ndarray:
    """OpenCV's decoding of ``data`` as stored (depth and alpha kept); ImageError if it fails,
    or where the decoder said the data is corrupt (:data:`CORRUPT`) and decoded it anyway."""
    failure = None
    with _DECODING, captured_stderr() as messages:
        level = _LOGGING.setLogLevel(3)       # its warnings, where libtiff's errors reach it
        try:
            image = cv2.imdecode(np.frombuffer(data, np.uint8), cv2.IMREAD_UNCHANGED)
        except cv2.error as err:              # OpenCV's size limit (or another assertion)
            image, failure = None, str(err)
        finally:
            _LOGGING.setLogLevel(level if isinstance(level, int) else 0)   # the level before (it returns it)
    if failure and "CV_IO_MAX_IMAGE" in failure:
        raise ImageError(f"{name} is above the limit of {opencv_limit()} pixels of the decoder "
                         "(--max-pixels)")
    detail = f" ({_without_log_prefix(messages[-1])})" if messages else ""
    if image is None:
        raise ImageError(f"{name} cannot be decoded (corrupt, truncated or not a supported "
                         f"image){detail}")
    corrupt = [m for m in messages if CORRUPT.search(m)]
    if corrupt:
        said = CORRUPT.search(corrupt[0])
        raise ImageError(f"{name} is corrupt: {next(part for part in said.groups() if part)}")
    return image


def pnm_maxval(data: bytes) -> int | None:
    """The MAXVAL of a PGM, PPM or PAM header whose samples OpenCV leaves as stored; None for
    another format, and for a plain P2 or P3 of MAXVAL up to 255 (OpenCV scales those itself)."""
    if data[:2] in (b"P2", b"P3", b"P5", b"P6"):
        header = re.sub(rb"#[^\n\r]*", b" ", data[2:512]).split()        # comments, then numbers
        maxval = int(header[2]) if len(header) > 2 and header[2].isdigit() else None
        plain = data[:2] in (b"P2", b"P3")     # OpenCV scales those itself up to 255, not beyond
        return None if plain and maxval is not None and maxval <= 255 else maxval
    if data[:2] == b"P7":
        found = re.search(rb"\sMAXVAL\s+(\d+)", data[:1024])
        return int(found.group(1)) if found else None
    return None


def _full_range(image: np.ndarray, maxval: int | None, name: str) -> np.ndarray:
    """A PNM/PAM image whose samples run to ``maxval`` scaled to its type's full range (OpenCV
    keeps them as stored: MAXVAL 3 came out nearly black); samples above it are clipped."""
    if maxval is None:
        return image
    if maxval < 1:
        raise ImageError(f"{name} has MAXVAL {maxval}: a PNM or PAM image needs at least 1")
    top = np.iinfo(image.dtype).max
    if maxval >= top or image.dtype not in (np.uint8, np.uint16):
        return image
    scaled = np.minimum(image, maxval).astype(np.float64) * (top / maxval)
    return np.rint(scaled).astype(image.dtype)


def decode_image(data: bytes, name: str, max_pixels: int | None = MAX_PIXELS,
                 max_memory: int | None = None) -> np.ndarray:
    """Decode image bytes (format sniffed from them) keeping depth and alpha, upright.

    The size in the header is checked against ``max_pixels`` before decoding;
    JPEG, PNG and WebP are turned upright according to their EXIF orientation
    (OpenCV's TIFF decoder does it itself); gray + alpha, and a grey PNG with a transparent
    level (tRNS), become BGRA. Corrupt
    data that the decoder only warns about (libjpeg's "Corrupt JPEG data",
    "Premature end") is refused as well.

    Parameters
    ----------
    data : bytes
    name : str
        Used in error messages.
    max_pixels : int or None
        Largest accepted width * height; None: no limit.
    max_memory : int or None
        Memory budget in bytes: an image whose header claims more than it can hold
        (:func:`featurewarp_cli.io.limits.check_memory`) is refused before decoding.

    Returns
    -------
    (h, w) or (h, w, C) ndarray, uint8 or uint16, OpenCV channel order.

    Raises
    ------
    ImageError
        When the data is empty, too large, or cannot be decoded.
    """
    if len(data) == 0:
        raise ImageError(f"{name} is empty")
    for signature, kind in FLOAT_FORMATS:
        if data.startswith(signature):          # refused before OpenCV decodes it (through a temp file)
            raise ImageError(f"{name} cannot be decoded for warping: {kind} holds float samples; featurewarp "
                             f"warps 8- and 16-bit images (convert it first)")
    header = read_header(data)
    if header is not None:
        check_size(header.width, header.height, name, max_pixels, max_memory)
    if tiff.lab_pages(data):
        raise lab_error(name)
    scans = data.count(b"\xff\xda") if data.startswith(b"\xff\xd8") else 0
    if scans > MAX_JPEG_SCANS:
        raise ImageError(f"{name} has {scans} JPEG scans, above {MAX_JPEG_SCANS} (a progressive JPEG has about "
                         f"10; each scan costs a pass over the image): refused")
    image = _full_range(_opencv_decode(data, name), pnm_maxval(data), name)   # checks the data, either way
    if header is not None and header.mode == "CMYK" and header.icc:   # sRGB: converted through its profile
        image = profiles.cmyk_to_srgb(data, image.shape, name)
    image = tiff.straight_alpha(image, data, name)   # what OpenCV's TIFF reading does to alpha
    image = png.with_gray_transparency(image, data)   # a grey PNG's tRNS, which OpenCV leaves out
    if image.dtype not in (np.uint8, np.uint16):
        raise ImageError(f"{name} has unsupported sample type {image.dtype}")
    check_pixels(image.shape[1], image.shape[0], name, max_pixels)
    image = gray_alpha_to_bgra(image)
    if header is not None and header.orientation != 1 and header.format in TURNED_HERE:
        image = np.ascontiguousarray(ORIENTATIONS[header.orientation](image))
    return image


def lab_error(name: str, page: str = "") -> ImageError:
    """The refusal of a CIELab TIFF (``page``: which page of it, where not the first): OpenCV
    decodes L*a*b* to wrong colours with no error, and a mask's grey levels from it are off
    too (libtiff's conversion: greys 123-127 crossed the mask's 128, a 0/1 mask marked nothing)."""
    hint = "-" if name == "stdin" else shlex.quote(name)       # as the command line named it
    return ImageError(f"{name}{page} holds CIELab colours (a Lab TIFF), which featurewarp does not read; "
                      f"convert it to RGB first (ImageMagick: convert {hint} -colorspace sRGB rgb.tif)")


def read_image(path: str, max_pixels: int | None = MAX_PIXELS, max_bytes: int | None = None) -> np.ndarray:
    """Read and decode an image file (``-``: stdin, at most ``max_bytes``, the memory budget,
    which its header's size must also fit); see :func:`decode_image`."""
    return decode_image(read_bytes(path, max_bytes), "stdin" if path == "-" else path, max_pixels, max_bytes)


def brightest_gray(image: np.ndarray) -> tuple[int, bool]:
    """(the brightest gray of a mask image, composited over black as :func:`mask_from_image`
    reads it, rounded down on the 0..255 scale; whether its colour channels differ anywhere):
    what that compares with 128, for a message about a mask that marks nothing."""
    colour = image[:, :, :3] if image.ndim == 3 and image.shape[2] >= 3 else None
    tinted = colour is not None and bool(np.any(colour != colour[:, :, :1]))
    return int(np.floor(float(_mask_gray(image).max(initial=0)) * 255 / np.iinfo(image.dtype).max)), tinted


def _mask_gray(image: np.ndarray) -> np.ndarray:
    """A mask image's gray composited over black: its luma (its one channel for gray), times
    its alpha where it has four channels."""
    if image.ndim == 2:
        return image
    colour = image[:, :, :3] if image.shape[2] >= 3 else image[:, :, :1]
    gray = cv2.cvtColor(colour, cv2.COLOR_BGR2GRAY) if colour.shape[2] == 3 else colour[:, :, 0]
    if image.shape[2] == 4:
        gray = gray.astype(np.float64) * image[:, :, 3] / np.iinfo(image.dtype).max
    return gray


def mask_from_image(image: np.ndarray) -> np.ndarray:
    """Boolean feature mask: gray value >= 128 of the mask composited over black; a mask whose
    largest sample is 1 (a 0/1 mask, in one channel or in colour) marks its 1s, as the API
    does (:func:`featurewarp_cli.engine.arrays.mask_array`).

    Transparent pixels of a mask with alpha therefore never mark a feature.
    """
    top = np.iinfo(image.dtype).max
    threshold = 128 * top / 255                     # 128 or 32896: whole numbers, exact
    if image.ndim == 2:
        if image.size and image.max() == 1:
            return image == 1
        return image >= threshold
    colour = image[:, :, :3] if image.shape[2] >= 3 else image[:, :, :1]
    if colour.size and colour.max() == 1:                  # a 0/1 mask saved with colour channels
        marked = colour.max(axis=2) == 1
        return marked & (image[:, :, 3] > 0) if image.shape[2] == 4 else marked
    return _mask_gray(image) >= threshold

"""Reading images and masks, output formats, parsing colours, and writing outputs atomically.

``-`` stands for stdin (reading) or stdout (writing). An output may carry an
ImageMagick-style format prefix (``png:-``, ``jpg:out.bin``). Image sizes are read
from the file header before any pixel is decoded, so that oversized images are
refused cheaply.
"""

from __future__ import annotations

import contextlib
import os
import struct
import sys
import tempfile
import zlib

import cv2
import numpy as np

# Silence OpenCV's own log (level 0); before 4.13 the call is cv2.setLogLevel.
getattr(cv2.utils, "logging", cv2).setLogLevel(0)

#: Output formats by name: (OpenCV extension, has alpha, fixed encoder parameters).
#: Every encoder setting is pinned so that the same pixels always give the same bytes.
FORMATS = {
    "png": (".png", True, None),                                    # our own encoder: encode_png
    "jpg": (".jpg", False, [cv2.IMWRITE_JPEG_QUALITY, 95, cv2.IMWRITE_JPEG_PROGRESSIVE, 0,
                            cv2.IMWRITE_JPEG_OPTIMIZE, 0]),
    # 101: lossless (libwebp may still clear the colour under fully transparent pixels)
    "webp": (".webp", True, [cv2.IMWRITE_WEBP_QUALITY, 101]),
    "tiff": (".tiff", True, [cv2.IMWRITE_TIFF_COMPRESSION, 5]),    # 5: LZW
    "bmp": (".bmp", False, []),
}
#: Other spellings of the format names (also accepted as file extensions).
ALIASES = {"jpeg": "jpg", "tif": "tiff"}
#: Formats that only store 8-bit samples (16-bit results are scaled down).
EIGHT_BIT = {"jpg", "webp", "bmp"}

#: Default limit on width * height of an input (``--max-pixels``).
MAX_PIXELS = 200_000_000

COLOURS = {
    "white": (255, 255, 255), "black": (0, 0, 0), "red": (255, 0, 0), "green": (0, 128, 0),
    "lime": (0, 255, 0), "blue": (0, 0, 255), "yellow": (255, 255, 0), "cyan": (0, 255, 255),
    "magenta": (255, 0, 255), "gray": (128, 128, 128), "grey": (128, 128, 128),
    "orange": (255, 165, 0), "purple": (128, 0, 128), "pink": (255, 192, 203),
    "brown": (165, 42, 42), "navy": (0, 0, 128), "silver": (192, 192, 192),
}

#: EXIF orientation (2..8) -> the array operation that shows the image upright.
_ORIENTATIONS = {
    2: lambda a: a[:, ::-1],
    3: lambda a: a[::-1, ::-1],
    4: lambda a: a[::-1],
    5: lambda a: a.swapaxes(0, 1),
    6: lambda a: np.rot90(a, -1),
    7: lambda a: np.rot90(a, 2).swapaxes(0, 1),
    8: lambda a: np.rot90(a, 1),
}


class ImageError(Exception):
    """An image or mask that cannot be read, decoded or written."""


def format_name(text: str) -> str | None:
    """Canonical format name for ``png``, ``JPEG``, ``.tif`` ...; None if not an output format."""
    name = text.lower().lstrip(".")
    name = ALIASES.get(name, name)
    return name if name in FORMATS else None


def split_prefix(spec: str) -> tuple[str | None, str]:
    """Split an ImageMagick-style ``format:path`` into (format name, path).

    Only a known format name counts as a prefix, so ``C:/x.png`` or ``a:b.png``
    stay plain paths. Without a prefix the format is None.
    """
    head, sep, rest = spec.partition(":")
    if sep and rest and format_name(head) and not head.startswith("."):
        return format_name(head), rest
    return None, spec


def output_target(spec: str, fmt: str | None = None) -> tuple[str, str]:
    """Path and format name of an OUTPUT argument.

    The format comes from a ``png:``-style prefix, else ``fmt`` (``--format``),
    else the path's extension. ``-`` (stdout) needs a prefix or ``fmt``.

    Raises
    ------
    ValueError
        Unknown format, conflicting prefix and ``fmt``, or stdout without a format.
    """
    prefix, path = split_prefix(spec)
    wanted = format_name(fmt) if fmt else None
    if fmt and wanted is None:
        raise ValueError(f"unknown format {fmt!r}; use one of {', '.join(FORMATS)}")
    if prefix and wanted and prefix != wanted:
        raise ValueError(f"{spec} asks for {prefix} but --format says {wanted}")
    name = prefix or wanted
    if name is None:
        if path == "-":
            raise ValueError("writing to stdout ('-') needs --format or a prefix such as png:-")
        ext = os.path.splitext(path)[1]
        name = format_name(ext) if ext else None
        if name is None:
            known = ", ".join(sorted(set(FORMATS) | set(ALIASES)))
            raise ValueError(f"unknown output format {ext or '(no extension)'!r} for {path}; "
                             f"use one of {known}, or --format")
    return path, name


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


def read_bytes(path: str) -> bytes:
    """The bytes of a file, or of stdin for ``-``.

    Raises
    ------
    ImageError
        When the file cannot be read.
    """
    if path == "-":
        if sys.stdin.isatty():
            raise ImageError("stdin is a terminal; pipe an image into it (or give a file name)")
        return sys.stdin.buffer.read()
    try:
        with open(path, "rb") as fh:
            return fh.read()
    except OSError as err:
        raise ImageError(f"cannot read {path}: {err.strerror or err}") from None


def read_image(path: str, max_pixels: int | None = MAX_PIXELS) -> np.ndarray:
    """Read and decode an image file (``-``: stdin); see :func:`decode_image`."""
    return decode_image(read_bytes(path), "stdin" if path == "-" else path, max_pixels)


def _tiff_tags(data: bytes) -> dict[int, int]:
    """Integer tags of the first IFD of a TIFF structure (a TIFF file or an EXIF block)."""
    order = {b"II": "<", b"MM": ">"}.get(data[:2])
    if order is None:
        return {}
    tags: dict[int, int] = {}
    try:
        (offset,) = struct.unpack_from(order + "I", data, 4)
        (count,) = struct.unpack_from(order + "H", data, offset)
        for k in range(count):
            tag, kind, _, value = struct.unpack_from(order + "HHI4s", data, offset + 2 + 12 * k)
            if kind in (3, 4):                                     # SHORT, LONG
                tags[tag] = struct.unpack_from(order + ("H" if kind == 3 else "I"), value)[0]
    except struct.error:
        pass
    return tags


def _jpeg_segments(data: bytes):
    """Yield (marker, payload) of a JPEG's header segments, up to the start of scan."""
    i = 2
    while i + 4 <= len(data) and data[i] == 0xFF:
        marker = data[i + 1]
        if marker == 0xFF:                                          # fill byte
            i += 1
            continue
        if marker == 0x01 or 0xD0 <= marker <= 0xD8:               # markers without a length
            i += 2
            continue
        (length,) = struct.unpack_from(">H", data, i + 2)
        yield marker, data[i + 4 : i + 2 + length]
        if marker == 0xDA:
            return
        i += 2 + length


def image_size(data: bytes) -> tuple[int, int] | None:
    """(width, height) from the header of a PNG, JPEG, WebP, TIFF, BMP or GIF; None if unknown.

    Only the first bytes are parsed, no pixel is decoded.
    """
    try:
        if data[:8] == b"\x89PNG\r\n\x1a\n" and data[12:16] == b"IHDR":
            return struct.unpack_from(">II", data, 16)
        if data[:2] == b"\xff\xd8":
            for marker, payload in _jpeg_segments(data):
                if 0xC0 <= marker <= 0xCF and marker not in (0xC4, 0xC8, 0xCC):   # start of frame
                    height, width = struct.unpack_from(">HH", payload, 1)
                    return width, height
            return None
        if data[:4] == b"RIFF" and data[8:12] == b"WEBP":
            chunk = data[12:16]
            if chunk == b"VP8 ":
                width, height = struct.unpack_from("<HH", data, 26)
                return width & 0x3FFF, height & 0x3FFF
            if chunk == b"VP8L":
                (bits,) = struct.unpack_from("<I", data, 21)
                return (bits & 0x3FFF) + 1, ((bits >> 14) & 0x3FFF) + 1
            if chunk == b"VP8X":
                return 1 + int.from_bytes(data[24:27], "little"), 1 + int.from_bytes(data[27:30], "little")
            return None
        if data[:4] in (b"II*\x00", b"MM\x00*"):
            tags = _tiff_tags(data)
            return (tags[256], tags[257]) if 256 in tags and 257 in tags else None
        if data[:2] == b"BM" and struct.unpack_from("<I", data, 14)[0] >= 40:
            width, height = struct.unpack_from("<ii", data, 18)
            return width, abs(height)
        if data[:6] in (b"GIF87a", b"GIF89a"):
            return struct.unpack_from("<HH", data, 6)
    except struct.error:
        return None
    return None


def exif_orientation(data: bytes) -> int:
    """EXIF orientation (1..8) of a JPEG; 1 (upright) when it has none."""
    if data[:2] != b"\xff\xd8":
        return 1
    try:
        for marker, payload in _jpeg_segments(data):
            if marker == 0xE1 and payload[:6] == b"Exif\x00\x00":
                value = _tiff_tags(payload[6:]).get(0x0112, 1)
                return value if value in _ORIENTATIONS else 1
    except struct.error:
        pass
    return 1


@contextlib.contextmanager
def _captured_stderr():
    """Collect what C libraries (libpng, libjpeg) print on file descriptor 2 instead of showing it.

    Yields a list that holds the printed lines once the block has finished.
    """
    lines: list[str] = []
    sys.stderr.flush()                                              # our own messages stay visible
    try:
        saved = os.dup(2)
    except OSError:                                                 # no stderr at all
        yield lines
        return
    with tempfile.TemporaryFile() as tmp:
        os.dup2(tmp.fileno(), 2)
        try:
            yield lines
        finally:
            os.dup2(saved, 2)
            os.close(saved)
            tmp.seek(0)
            printed = [line for line in tmp.read().decode(errors="replace").splitlines() if line.strip()]
            # Our own notices (another thread may print while a decode runs) are shown after all.
            ours = [line for line in printed if line.startswith("featurewarp:")]
            if ours:
                sys.stderr.write("".join(line + "\n" for line in ours))
            lines.extend(line for line in printed if not line.startswith("featurewarp:"))


def check_pixels(width: int, height: int, name: str, max_pixels: int | None) -> None:
    """Raise ImageError if a ``width`` x ``height`` image is empty or above ``max_pixels``."""
    if width < 1 or height < 1:
        raise ImageError(f"{name} has no pixels ({width}x{height})")
    if max_pixels is not None and width * height > max_pixels:
        raise ImageError(f"{name} is {width}x{height} = {width * height} pixels, above the limit "
                         f"of {max_pixels} (--max-pixels)")


def decode_image(data: bytes, name: str, max_pixels: int | None = MAX_PIXELS) -> np.ndarray:
    """Decode image bytes (format sniffed from them) keeping depth and alpha.

    The size in the header is checked against ``max_pixels`` before decoding;
    JPEGs are turned upright according to their EXIF orientation; gray + alpha
    becomes BGRA. Corrupt data that the decoder only warns about (libjpeg's
    "Corrupt JPEG data", "Premature end") is refused as well.

    Parameters
    ----------
    data : bytes
    name : str
        Used in error messages.
    max_pixels : int or None
        Largest accepted width * height; None: no limit.

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
    size = image_size(data)
    if size is not None:
        check_pixels(*size, name, max_pixels)
    with _captured_stderr() as messages:
        image = cv2.imdecode(np.frombuffer(data, np.uint8), cv2.IMREAD_UNCHANGED)
    detail = f" ({messages[-1]})" if messages else ""
    if image is None:
        raise ImageError(f"{name} cannot be decoded (corrupt, truncated or not a supported "
                         f"image){detail}")
    corrupt = [m for m in messages if m.startswith(("Corrupt JPEG", "Premature end"))]
    if corrupt:
        raise ImageError(f"{name} is corrupt: {corrupt[0]}")
    if image.dtype not in (np.uint8, np.uint16):
        raise ImageError(f"{name} has unsupported sample type {image.dtype}")
    check_pixels(image.shape[1], image.shape[0], name, max_pixels)
    if image.ndim == 3 and image.shape[2] == 2:      # gray + alpha: encoders want BGRA
        gray, alpha = image[:, :, 0], image[:, :, 1]
        image = np.dstack([gray, gray, gray, alpha])
    orientation = exif_orientation(data)
    if orientation != 1:
        image = np.ascontiguousarray(_ORIENTATIONS[orientation](image))
    return image


def mask_from_image(image: np.ndarray) -> np.ndarray:
    """Boolean feature mask: gray value >= 128 of the mask composited over black.

    Transparent pixels of a mask with alpha therefore never mark a feature.
    """
    top = np.iinfo(image.dtype).max
    threshold = 128 * top / 255                     # 128 or 32896: whole numbers, exact
    if image.ndim == 2:
        return image >= threshold
    colour = image[:, :, :3] if image.shape[2] >= 3 else image[:, :, :1]
    gray = cv2.cvtColor(colour, cv2.COLOR_BGR2GRAY) if colour.shape[2] == 3 else colour[:, :, 0]
    if image.shape[2] == 4:
        gray = gray.astype(np.float64) * image[:, :, 3] / top
    return gray >= threshold


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

    16-bit images are scaled to 8 bits for formats that need it, and alpha is
    composited over ``background`` (r, g, b) for formats without alpha. PNG goes
    through :func:`encode_png`, the others through OpenCV.
    """
    ext, has_alpha, params = FORMATS[fmt]
    if not has_alpha:
        image = flatten(image, background)
    if fmt in EIGHT_BIT and image.dtype != np.uint8:
        image = ((image.astype(np.uint32) + 128) // 257).astype(np.uint8)
    if fmt == "png":
        return encode_png(image)
    with _captured_stderr():
        ok, buf = cv2.imencode(ext, image, params)
    if not ok:
        raise ImageError(f"cannot encode the result as {fmt}")
    return buf.tobytes()


# PNG writing. Every row gets the Paeth filter (computed with numpy on whole bands of
# rows), and bands of about PNG_BAND_BYTES are deflated in parallel threads (zlib
# releases the GIL) as independent raw-deflate pieces joined by sync flushes, as pigz
# does; the Adler-32 of the whole stream is combined from the pieces'. Deflate runs at
# level 1 with the strategy that suits the image (see _strategy): Z_RLE (matches at
# distance 1 only) for photographs, plain LZ77 for graphics. The band layout and the
# strategy depend on the pixels only, so the bytes do not depend on the number of threads.
# 12 MP swirl output (4000x3000 BGR): CPU seconds, MB (the threaded rows take about half
# their CPU time in wall time on 2 free cores):
#   cv2.imencode level 3 (adaptive filters)     1.1    9.67   (the former setting)
#   cv2.imencode level 1                        0.65  10.41
#   cv2.imencode level 1, Z_RLE                 0.68   8.63
#   Up filter + Z_RLE, 2 threads                0.41  10.55
#   Avg filter + Z_RLE, 2 threads               0.44   9.31
#   Paeth filter + level 1 LZ77, 2 threads      0.6   10.39
#   Paeth filter + Z_RLE, 2 threads             0.59   8.62   (chosen; ImageMagick: 8.7)
# (Paeth costs 0.25 CPU s in numpy, Z_RLE deflate 0.34.) Graphics (samples/shapes.png
# swirled, 640x480): cv2 level 3 264 KB; Paeth + Z_RLE 473 KB; Paeth + level 1 LZ77 302 KB
# (chosen there). Splitting into bands costs < 0.5 % in size.
PNG_BAND_BYTES = 1 << 18
#: Bytes per sample strip that :func:`_strategy` compresses both ways (three strips).
PNG_SAMPLE_BYTES = 1 << 16
#: Largest IDAT chunk written (the format allows 2**31 - 1).
PNG_MAX_CHUNK = 1 << 30
_PNG_COLOUR_TYPE = {1: 0, 2: 4, 3: 2, 4: 6}           # channels -> gray, gray+alpha, RGB, RGBA


def _png_chunk(kind: bytes, data: bytes) -> bytes:
    return struct.pack(">I", len(data)) + kind + data + struct.pack(">I", zlib.crc32(data, zlib.crc32(kind)))


def _paeth_band(image: np.ndarray, start: int, stop: int) -> np.ndarray:
    """Rows ``start:stop`` of a contiguous image as PNG data: each row its filter type byte (4)
    and its Paeth-filtered samples (RGB(A) order, big-endian), (rows, 1 + bytes) uint8."""
    first = max(start - 1, 0)
    src = image[first:stop].reshape(stop - first, image.shape[1], -1)      # (rows, w, C)
    size = image.dtype.itemsize
    src = src.view(np.uint8).reshape(src.shape + (size,))[..., ::-1]       # big-endian sample bytes
    bpp = src.shape[2] * size
    # Row 0 is the row above the band (zeros above the image); column 0 the zero left pixel.
    ext = np.zeros((stop - start + 1, (image.shape[1] + 1) * bpp), np.int16)
    dst = ext[stop - start + 1 - src.shape[0]:, bpp:].reshape(src.shape)
    dst[:, :, :3] = src[:, :, 2::-1] if src.shape[2] >= 3 else src        # BGR -> RGB
    dst[:, :, 3:] = src[:, :, 3:]                                          # alpha
    x, a, b, c = ext[1:, bpp:], ext[1:, :-bpp], ext[:-1, bpp:], ext[:-1, :-bpp]
    p = b - c                                            # Paeth: |p| = |b - c|, |q| = |a - c|,
    q = a - c                                            # |p + q| = |a + b - 2c|
    pc = np.abs(p + q)
    pa, pb = np.abs(p, out=p), np.abs(q, out=q)
    predictor = np.where(pb <= pc, b, c)
    np.copyto(predictor, a, where=pa <= np.minimum(pb, pc, out=pc))   # a wins ties, then b
    filtered = np.empty((stop - start, x.shape[1] + 1), np.uint8)
    filtered[:, 0] = 4
    np.subtract(x, predictor, out=filtered[:, 1:], casting="unsafe")     # modulo 256
    return filtered


def _deflate(data, strategy: int, last: bool = True) -> bytes:
    """Raw deflate (level 1) of ``data``, ending the stream or with a sync flush."""
    deflate = zlib.compressobj(1, zlib.DEFLATED, -15, 8, strategy)
    return deflate.compress(data) + deflate.flush(zlib.Z_FINISH if last else zlib.Z_SYNC_FLUSH)


def _strategy(image: np.ndarray) -> int:
    """zlib.Z_RLE or zlib.Z_DEFAULT_STRATEGY: the one that compresses three strips of the
    filtered image (at 1/6, 1/2 and 5/6 of its height) better; Z_RLE on a tie."""
    height = image.shape[0]
    rows = max(1, PNG_SAMPLE_BYTES // image[0].nbytes)
    sizes = {zlib.Z_RLE: 0, zlib.Z_DEFAULT_STRATEGY: 0}
    for start in sorted({min(height * k // 6, max(height - rows, 0)) for k in (1, 3, 5)}):
        filtered = _paeth_band(image, start, min(start + rows, height))
        for strategy in sizes:
            sizes[strategy] += len(_deflate(filtered, strategy))
    return min(sizes, key=sizes.get)


def _deflate_band(image: np.ndarray, start: int, stop: int, strategy: int, last: bool):
    """One band: (raw deflate bytes, Adler-32 and length of the filtered bytes)."""
    filtered = _paeth_band(image, start, stop)
    return _deflate(filtered, strategy, last), zlib.adler32(filtered), filtered.size


def _adler32_combine(first: int, second: int, length: int) -> int:
    """Adler-32 of ``A + B`` from those of A and B and B's length (as zlib's adler32_combine)."""
    base = 65521
    low = ((first & 0xFFFF) + (second & 0xFFFF) - 1) % base
    high = ((first >> 16) + (second >> 16) + length * ((first & 0xFFFF) - 1)) % base
    return low | high << 16


def encode_png(image: np.ndarray) -> bytes:
    """Lossless PNG of a (h, w) or (h, w, C) uint8/uint16 image, C in 1..4, BGR(A) channel order.

    Gray, gray + alpha, RGB and RGBA at 8 or 16 bits; IHDR, IDAT and IEND chunks
    only. The same pixels always give the same bytes.
    """
    if image.dtype not in (np.uint8, np.uint16):
        raise ImageError(f"cannot encode {image.dtype} samples as png")
    height, width = image.shape[:2]
    channels = 1 if image.ndim == 2 else image.shape[2]
    if channels not in _PNG_COLOUR_TYPE:
        raise ImageError(f"cannot encode {channels} channels as png")
    image = np.ascontiguousarray(image)
    rows = max(1, PNG_BAND_BYTES // (width * channels * image.dtype.itemsize))
    strategy = _strategy(image)
    jobs = [(image, start, min(start + rows, height), strategy, start + rows >= height)
            for start in range(0, height, rows)]
    workers = min(len(jobs), os.cpu_count() or 1)
    if workers > 1:
        from concurrent.futures import ThreadPoolExecutor

        with ThreadPoolExecutor(workers) as pool:
            pieces = list(pool.map(_deflate_band, *zip(*jobs)))
    else:
        pieces = [_deflate_band(*job) for job in jobs]
    adler = 1
    for _, piece_adler, length in pieces:
        adler = _adler32_combine(adler, piece_adler, length)
    stream = b"".join([b"\x78\x01", *(data for data, _, _ in pieces), struct.pack(">I", adler)])
    header = struct.pack(">IIBBBBB", width, height, 8 * image.dtype.itemsize, _PNG_COLOUR_TYPE[channels],
                         0, 0, 0)
    return b"".join([b"\x89PNG\r\n\x1a\n", _png_chunk(b"IHDR", header),
                     *(_png_chunk(b"IDAT", stream[i : i + PNG_MAX_CHUNK])
                       for i in range(0, len(stream), PNG_MAX_CHUNK)),
                     _png_chunk(b"IEND", b"")])


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


def write_output(path: str, data: bytes) -> None:
    """Write ``data`` to stdout for ``-``, else atomically to ``path``."""
    if path == "-":
        sys.stdout.buffer.write(data)
        sys.stdout.buffer.flush()
    else:
        write_atomic(path, data)


def check_writable(path: str) -> None:
    """Raise ValueError unless a file ``path`` can be created (its directory exists and is writable).

    Writability is probed by creating and removing a temporary file, which is
    also right for root and for read-only file systems.
    """
    directory = os.path.dirname(os.path.abspath(path))
    if not os.path.isdir(directory):
        raise ValueError(f"directory {directory} does not exist")
    if os.path.isdir(path):
        raise ValueError(f"{path} is a directory")
    try:
        tempfile.TemporaryFile(dir=directory).close()
    except OSError as err:
        raise ValueError(f"directory {directory} is not writable ({err.strerror or err})") from None

"""What OpenCV's TIFF codec leaves out about alpha: the tag that names it, and its own premultiplying.

OpenCV writes a fourth sample without ExtraSamples (libtiff and ImageMagick call it
unspecified; readers may ignore the transparency), and reads an 8-bit one whose ExtraSamples
says alpha (1: associated, 2: unassociated, what Photoshop, GIMP and Pillow write) through
libtiff's RGBA interface, which premultiplies it: colours came out darkened by their alpha.
"""

from __future__ import annotations

import struct

import numpy as np

from . import ImageError

#: ExtraSamples, and its values: associated (premultiplied) and unassociated alpha.
EXTRA_SAMPLES, ASSOCIATED, UNASSOCIATED = 338, 1, 2
#: PhotometricInterpretation, and its values for L*a*b* samples: CIELab, ICCLab, ITULab.
PHOTOMETRIC, LAB_PHOTOMETRICS = 262, (8, 9, 10)


def first_directory(data: bytes) -> tuple[str, int, list[bytes], bool] | None:
    """(byte order, offset, entries, big) of the first directory of a TIFF (12-byte entries) or a
    BigTIFF (``big``: 20-byte entries); None for other data or a directory beyond the data."""
    big = data[:4] in (b"II+\0", b"MM\0+")
    if not (big or data[:4] in (b"II*\0", b"MM\0*")) or len(data) < 16:
        return None
    order = "<" if data[:2] == b"II" else ">"
    offset, count, size = ("Q", "Q", 20) if big else ("I", "H", 12)
    (first,) = struct.unpack_from(order + offset, data, 8 if big else 4)
    start = first + struct.calcsize(count)
    if start > len(data):
        return None
    (entries,) = struct.unpack_from(order + count, data, first)
    if start + size * entries + struct.calcsize(offset) > len(data):
        return None
    return order, first, [data[start + size * k:start + size * (k + 1)] for k in range(entries)], big


def first_short(data: bytes, wanted: int) -> int | None:
    """The first value of the SHORT tag ``wanted`` on a TIFF's first page, or None (no such tag,
    not a TIFF)."""
    found = first_directory(data)
    if found is None:
        return None
    order, _, entries, big = found
    for entry in entries:
        tag, kind = struct.unpack_from(order + "HH", entry)
        (count,) = struct.unpack_from(order + ("Q" if big else "I"), entry, 4)
        if tag == wanted and kind == 3 and count >= 1:
            return struct.unpack_from(order + "H", entry, 12 if big else 8)[0]   # inline, left-justified
    return None


def extra_samples(data: bytes) -> int | None:
    """The first ExtraSamples value of a TIFF's first page, or None (no such tag, not a TIFF)."""
    return first_short(data, EXTRA_SAMPLES)


def holds_lab(data: bytes) -> bool:
    """Whether a TIFF's first page holds L*a*b* samples (read from its tag, also where Pillow
    cannot open the file, as a 16-bit CIELab TIFF)."""
    return first_short(data, PHOTOMETRIC) in LAB_PHOTOMETRICS


#: TIFF field types written here: (code, struct format of one value, or None for bytes).
BYTE, ASCII, SHORT, LONG, RATIONAL, UNDEFINED = (1, None), (2, None), (3, "H"), (4, "I"), (5, "II"), (7, None)


def with_alpha_tag(data: bytes) -> bytes:
    """A one-page TIFF of four samples per pixel (OpenCV's) with ExtraSamples = unassociated
    alpha (:func:`with_tags`); a file that has the tag as it is."""
    found = first_directory(data)
    if found is None or any(struct.unpack_from(found[0] + "H", entry)[0] == EXTRA_SAMPLES for entry in found[2]):
        return data
    return with_tags(data, {EXTRA_SAMPLES: (SHORT, [UNASSOCIATED])}) or data


def with_tags(data: bytes, tags: dict) -> bytes | None:
    """A one-page TIFF or BigTIFF (OpenCV's) with ``tags`` set in its first directory: {tag:
    (type, values)}, values a list of numbers (a list of pairs for RATIONAL) or bytes (ASCII with its
    NUL, UNDEFINED, BYTE). The directory is written again at the end with them (replacing tags of
    the same number), their data before it, and the header points at it; nothing else moves
    (the old directory stays, unreferenced). None for data that is no TIFF, or where a classic
    TIFF would grow past 4 GiB."""
    found = first_directory(data)
    if found is None:
        return None
    order, first, entries, big = found
    word, count, size = ("Q", "Q", 20) if big else ("I", "H", 12)
    inline = 8 if big else 4
    kept = [entry for entry in entries if struct.unpack_from(order + "H", entry)[0] not in tags]
    out = bytearray(data)
    for tag, ((code, form), values) in tags.items():
        if form is None:
            payload, number = bytes(values), len(values)
        else:
            flat = [part for value in values for part in (value if isinstance(value, tuple) else (value,))]
            payload, number = struct.pack(order + form[0] * len(flat), *flat), len(values)
        if len(payload) <= inline:
            value = payload.ljust(inline, b"\0")
        else:
            out += b"\0" * (len(out) % 2)                              # data starts on a word
            value = struct.pack(order + word, len(out))
            out += payload
        kept.append(struct.pack(order + "HH" + word, tag, code, number) + value)
    kept.sort(key=lambda entry: struct.unpack_from(order + "H", entry)[0])
    at = first + struct.calcsize(count) + size * len(entries)
    following = data[at:at + struct.calcsize(word)]                     # the next directory's offset
    out += b"\0" * (len(out) % 2)                                      # directories start on a word
    start = len(out)
    out += struct.pack(order + count, len(kept)) + b"".join(kept) + following
    if not big and len(out) >= 1 << 32:
        return None
    pointer = 8 if big else 4
    out[pointer:pointer + struct.calcsize(word)] = struct.pack(order + word, start)
    return bytes(out)


def straight_alpha(image: np.ndarray, data: bytes, name: str) -> np.ndarray:
    """OpenCV's decoding of the TIFF ``data`` with its alpha, straight (unassociated): 8-bit
    files that declare alpha were premultiplied by libtiff's RGBA reading (read again by Pillow,
    exactly, where it gives the same size; else divided back), 16-bit ones are as stored, which
    for associated alpha is premultiplied (divided back); gray + alpha, whose alpha OpenCV drops
    (and its depth), is read by Pillow at 8 bits and refused at 16. Else ``image`` as it is."""
    extra = extra_samples(data)
    if extra not in (ASSOCIATED, UNASSOCIATED):
        return image
    if image.ndim == 2 or image.shape[2] < 4:
        exact = pillow_rgba(data)
        if exact is None:
            raise ImageError(f"{name} is gray with alpha that featurewarp cannot read without losing the "
                             f"alpha and the depth (16 bits): convert it to RGBA first")
        return exact
    if image.dtype == np.uint16 and extra == UNASSOCIATED:
        return image
    if image.dtype == np.uint8:
        exact = pillow_rgba(data)
        if exact is not None and exact.shape == image.shape:
            return exact
    return unpremultiplied(image)


def pillow_rgba(data: bytes, index: int = 0, upright: bool = True) -> np.ndarray | None:
    """Page ``index`` as straight-alpha BGRA by Pillow, turned upright (as OpenCV's still
    decoding does; not as its pages come); None where it cannot."""
    import io

    from PIL import Image, ImageOps

    try:
        with Image.open(io.BytesIO(data)) as page:
            page.seek(index)
            rgba = np.asarray((ImageOps.exif_transpose(page) if upright else page).convert("RGBA"))
    except Exception:  # whatever a decoder raises: the division below instead
        return None
    return np.ascontiguousarray(rgba[:, :, [2, 1, 0, 3]])


def unpremultiplied(image: np.ndarray) -> np.ndarray:
    """BGRA whose colours are multiplied by their alpha, divided back (to within that rounding:
    +-0.5 * top / alpha levels; where alpha is 0 the colour is gone, left 0)."""
    top = float(np.iinfo(image.dtype).max)
    alpha = image[:, :, 3:].astype(np.float64)
    colour = image[:, :, :3] * np.divide(top, alpha, out=np.zeros_like(alpha), where=alpha > 0)
    out = image.copy()
    out[:, :, :3] = np.clip(np.rint(colour), 0, top).astype(image.dtype)
    return out

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
    (first,) = struct.unpack_from(order + ("Q" if big else "I"), data, 8 if big else 4)
    entries = _entries(data, first, order, big)
    return None if entries is None else (order, first, entries, big)


def _entries(data: bytes, at: int, order: str, big: bool) -> list[bytes] | None:
    """The entries of the directory at offset ``at``; None where it runs past the data."""
    offset, count, size = ("Q", "Q", 20) if big else ("I", "H", 12)
    start = at + struct.calcsize(count)
    if at <= 0 or start > len(data):
        return None
    (entries,) = struct.unpack_from(order + count, data, at)
    if start + size * entries + struct.calcsize(offset) > len(data):
        return None
    return [data[start + size * k:start + size * (k + 1)] for k in range(entries)]


def page_values(data: bytes, wanted: int, pages: int = 1) -> list[int | None]:
    """The first value of the SHORT or LONG tag ``wanted`` on each of a TIFF's first ``pages``
    pages, None on a page without it; [] for data that is no TIFF. The chain of directories
    ends at a broken or repeated offset."""
    found = first_directory(data)
    if found is None:
        return []
    order, at, entries, big = found
    word, values, seen = "Q" if big else "I", [], set()
    while entries is not None and len(values) < pages and at not in seen:
        seen.add(at)
        values.append(_value(entries, order, big, wanted))
        (at,) = struct.unpack_from(order + word, data, at + struct.calcsize("Q" if big else "H")
                                   + (20 if big else 12) * len(entries))
        entries = _entries(data, at, order, big)
    return values


def _value(entries: list[bytes], order: str, big: bool, wanted: int) -> int | None:
    """The first value of the SHORT or LONG tag ``wanted`` among a directory's entries."""
    for entry in entries:
        tag, kind = struct.unpack_from(order + "HH", entry)
        (count,) = struct.unpack_from(order + ("Q" if big else "I"), entry, 4)
        form = {1: "B", 3: "H", 4: "I", 6: "b", 8: "h", 9: "i"}.get(kind)    # any integer type: libtiff reads each
        if tag == wanted and form and count >= 1:
            return struct.unpack_from(order + form, entry, 12 if big else 8)[0]   # inline, left-justified
    return None


def extra_samples(data: bytes) -> int | None:
    """The first ExtraSamples value of a TIFF's first page, or None (no such tag, not a TIFF)."""
    return (page_values(data, EXTRA_SAMPLES) or [None])[0]


def lab_pages(data: bytes, pages: int = 1) -> list[int]:
    """The pages (0-based) among a TIFF's first ``pages`` that hold L*a*b* samples (CIELab,
    ICCLab, ITULab: their photometric tag, read also where Pillow cannot open the file, as a
    16-bit CIELab TIFF); [] for other data."""
    return [k for k, value in enumerate(page_values(data, PHOTOMETRIC, pages)) if value in LAB_PHOTOMETRICS]


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

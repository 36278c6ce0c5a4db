"""What OpenCV's TIFF codec leaves out about alpha: the tag that names it, and its own premultiplying.

OpenCV writes a fourth sample without ExtraSamples (libtiff and ImageMagick call it
unspecified; readers may ignore the transparency), and reads an 8-bit one whose ExtraSamples
says alpha (1: associated, 2: unassociated, what Photoshop, GIMP and Pillow write) through
libtiff's RGBA interface, which premultiplies it: colours came out darkened by their alpha.
"""

from __future__ import annotations

import struct

import numpy as np

#: ExtraSamples, and its values: associated (premultiplied) and unassociated alpha.
EXTRA_SAMPLES, ASSOCIATED, UNASSOCIATED = 338, 1, 2


def first_directory(data: bytes) -> tuple[str, int, list[bytes]] | None:
    """(byte order, offset, 12-byte entries) of a classic TIFF's first directory; None for
    other data, a BigTIFF, or a directory beyond the data."""
    if data[:4] not in (b"II*\0", b"MM\0*") or len(data) < 8:
        return None
    order = "<" if data[:2] == b"II" else ">"
    (first,) = struct.unpack_from(order + "I", data, 4)
    if first + 2 > len(data):
        return None
    (count,) = struct.unpack_from(order + "H", data, first)
    if first + 6 + 12 * count > len(data):
        return None
    return order, first, [data[first + 2 + 12 * k:first + 14 + 12 * k] for k in range(count)]


def extra_samples(data: bytes) -> int | None:
    """The first ExtraSamples value of a TIFF's first page, or None (no such tag, not a TIFF)."""
    found = first_directory(data)
    if found is None:
        return None
    order, _, entries = found
    for entry in entries:
        tag, kind, count = struct.unpack_from(order + "HHI", entry)
        if tag == EXTRA_SAMPLES and kind == 3 and count >= 1:
            return struct.unpack_from(order + "H", entry, 8)[0]      # inline: two SHORTs fit
    return None


def with_alpha_tag(data: bytes) -> bytes:
    """A one-page TIFF of four samples per pixel (OpenCV's) with ExtraSamples = unassociated
    alpha. The first directory is written again at the end with the tag, and the header points
    at it; nothing else moves (the old directory stays, unreferenced)."""
    found = first_directory(data)
    if found is None:
        return data
    order, first, entries = found
    if any(struct.unpack_from(order + "H", entry)[0] == EXTRA_SAMPLES for entry in entries):
        return data
    entries = sorted(entries + [struct.pack(order + "HHIHH", EXTRA_SAMPLES, 3, 1, UNASSOCIATED, 0)],
                     key=lambda entry: struct.unpack_from(order + "H", entry)[0])
    following = data[first + 2 + 12 * (len(entries) - 1):first + 6 + 12 * (len(entries) - 1)]
    start = len(data) + len(data) % 2                                    # directories start on a word
    directory = struct.pack(order + "H", len(entries)) + b"".join(entries) + following
    return data[:4] + struct.pack(order + "I", start) + data[8:] + b"\0" * (start - len(data)) + directory


def unpremultiplied(image: np.ndarray) -> np.ndarray:
    """8-bit BGRA whose colours libtiff multiplied by their alpha, divided back (to within its
    rounding: +-0.5 * 255 / alpha levels; where alpha is 0 the colour is gone, left 0)."""
    alpha = image[:, :, 3:].astype(np.float64)
    colour = image[:, :, :3] * np.divide(255.0, alpha, out=np.zeros_like(alpha), where=alpha > 0)
    out = image.copy()
    out[:, :, :3] = np.clip(np.rint(colour), 0, 255).astype(np.uint8)
    return out

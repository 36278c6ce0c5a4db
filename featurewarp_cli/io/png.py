"""PNG chunks read without decoding, and the transparency of a grey PNG that OpenCV leaves out.

A grey PNG (colour type 0, 1 to 16 bits) marks one grey level transparent with a tRNS chunk,
as an RGB PNG marks one colour. OpenCV's ``IMREAD_UNCHANGED`` gives an RGB PNG's tRNS as an
alpha channel (8 and 16 bits) and a palette's too, but a grey one's not: the transparent
pixels came out opaque, and ``--mask alpha`` said there was no alpha channel. Pillow reads
the tRNS value (``info["transparency"]``) but leaves a 16-bit grey image without alpha when
converted, and compares a 2- or 4-bit level unscaled with its 8-bit samples, so that nothing
came out transparent. :func:`with_gray_transparency` adds the alpha here, from the chunk.
"""

from __future__ import annotations

import struct
import zlib

import numpy as np

SIGNATURE = b"\x89PNG\r\n\x1a\n"
#: The IHDR's colour type of a grey image without alpha.
GRAY = 0


def chunk(data: bytes, kind: bytes, before: bytes = b"IEND") -> bytes | None:
    """The payload of the first chunk of type ``kind`` in PNG bytes.

    Parameters
    ----------
    data : bytes
        A PNG file.
    kind : bytes
        The chunk type, as ``b"eXIf"``.
    before : bytes
        The chunk type at which to stop looking (``b"IDAT"`` for a chunk that must come before
        the pixels).

    Returns
    -------
    bytes or None
        None where there is no such chunk. Chunk headers only are read, the pixels are skipped.
    """
    for name, start, length in _walk(data):
        if name == kind:
            return data[start:start + length]
        if name in (before, b"IEND"):
            return None
    return None


def _walk(data: bytes):
    """(type, payload start, payload length) of each chunk of PNG bytes, in order; headers only."""
    at = len(SIGNATURE)
    while at + 8 <= len(data):
        length, kind = struct.unpack(">I4s", data[at:at + 8])
        yield kind, at + 8, length
        at += 12 + length


def chunks(data: bytes) -> list[tuple[bytes, bytes]]:
    """A PNG's chunks as (type, payload), in order (the signature skipped)."""
    return [(kind, data[start:start + length]) for kind, start, length in _walk(data)]


def make_chunk(kind: bytes, payload: bytes) -> bytes:
    """One PNG chunk: length, type, payload and CRC."""
    return struct.pack(">I", len(payload)) + kind + payload + struct.pack(">I", zlib.crc32(kind + payload))


def with_gray_transparency(image: np.ndarray, data: bytes) -> np.ndarray:
    """A grey PNG's pixels with the alpha its tRNS chunk gives them.

    Parameters
    ----------
    image : (h, w) ndarray, uint8 or uint16
        OpenCV's decoding of ``data`` as stored (a bit depth under 8 scaled to 0..255, as
        libpng does).
    data : bytes
        The file.

    Returns
    -------
    ndarray
        (h, w, 2) grey + alpha (0 where the pixel is the tRNS level, opaque elsewhere) for a
        grey PNG with a tRNS chunk; ``image`` itself for any other file, or a chunk too short
        or out of the bit depth's range.
    """
    if image.ndim != 2 or not data.startswith(SIGNATURE) or len(data) < 29 or data[12:16] != b"IHDR" \
            or data[25] != GRAY:
        return image
    trns = chunk(data, b"tRNS", before=b"IDAT")
    depth = data[24]
    if trns is None or len(trns) < 2 or depth not in (1, 2, 4, 8, 16):
        return image
    level = int.from_bytes(trns[:2], "big")
    if level >= 1 << depth:                      # out of range (libpng warns): no pixel is that level
        return image
    if depth < 8:
        level *= 255 // ((1 << depth) - 1)       # as the samples were scaled
    top = np.iinfo(image.dtype).max
    alpha = np.where(image == level, 0, top).astype(image.dtype)
    return np.dstack([image, alpha])

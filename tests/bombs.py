"""Decompression bombs: a few bytes of header claiming a huge image, for every input format.

Each function returns the bytes of a file whose header claims ``width`` x ``height``
pixels while the data is a few kilobytes (built by hand: no encoder writes such files).
"""

from __future__ import annotations

import struct
import zlib


def png(width: int, height: int) -> bytes:
    """PNG: IHDR with the size, a small IDAT."""
    def chunk(kind: bytes, data: bytes) -> bytes:
        return struct.pack(">I", len(data)) + kind + data + struct.pack(">I", zlib.crc32(kind + data))

    return (b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", struct.pack(">IIBBBBB", width, height, 8, 2, 0, 0, 0))
            + chunk(b"IDAT", zlib.compress(bytes(1000))) + chunk(b"IEND", b""))


def jpeg(width: int, height: int, junk: bool = True) -> bytes:
    """Baseline JPEG frame of the size; ``junk``: a stray byte before the first segment, which
    some header readers stop at while libjpeg skips it."""
    out = b"\xff\xd8" + (b"\x00" if junk else b"")
    out += b"\xff\xdb" + struct.pack(">H", 67) + b"\x00" + bytes(range(1, 65))
    out += b"\xff\xc0" + struct.pack(">HBHHB", 11, 8, height, width, 1) + b"\x01\x11\x00"
    for table in (b"\x00", b"\x10"):
        out += b"\xff\xc4" + struct.pack(">H", 20) + table + b"\x01" + bytes(15) + b"\x00"
    return out + b"\xff\xda" + struct.pack(">HB", 8, 1) + b"\x01\x00\x00\x3f\x00" + bytes(2000) + b"\xff\xd9"


def tiff(width: int, height: int, duplicate_width: bool = False) -> bytes:
    """Classic TIFF with the size in SLONG tags (type 9); optionally a second, small width tag."""
    entries = [(256, 9, width), (257, 9, height), (258, 3, 8), (259, 3, 1), (262, 3, 1), (273, 4, 300),
               (277, 3, 1), (278, 4, height), (279, 4, width * height & 0xFFFFFFFF)]
    if duplicate_width:
        entries.insert(1, (256, 3, 10))
    ifd = struct.pack("<H", len(entries)) + b"".join(struct.pack("<HHII", t, k, 1, v) for t, k, v in entries)
    return b"II" + struct.pack("<HI", 42, 8) + ifd + struct.pack("<I", 0) + bytes(50000)


def bigtiff(width: int, height: int) -> bytes:
    """BigTIFF (version 43) with LONG8 size tags."""
    entries = [(256, 16, width), (257, 16, height), (258, 3, 8), (259, 3, 1), (262, 3, 1), (273, 16, 400),
               (277, 3, 1), (278, 16, height), (279, 16, width * height)]
    ifd = struct.pack("<Q", len(entries)) + b"".join(struct.pack("<HHQQ", t, k, 1, v) for t, k, v in entries)
    return b"II" + struct.pack("<HHHQ", 43, 8, 0, 16) + ifd + struct.pack("<Q", 0) + bytes(50000)


def hdr(width: int, height: int) -> bytes:
    """Radiance HDR: text header with the resolution line, a little run-length data."""
    return (b"#?RADIANCE\nFORMAT=32-bit_rle_rgbe\n\n" + f"-Y {height} +X {width}\n".encode()
            + b"\x02\x02\x2e\xe0" + b"\x80\x01" * 5000)


def pnm(width: int, height: int, magic: str = "P6") -> bytes:
    """Binary PPM (P6) or PGM (P5)."""
    return f"{magic}\n{width} {height}\n255\n".encode() + bytes(10000)


def pam(width: int, height: int) -> bytes:
    """PAM (P7)."""
    return (f"P7\nWIDTH {width}\nHEIGHT {height}\nDEPTH 3\nMAXVAL 255\nTUPLTYPE RGB\nENDHDR\n".encode()
            + bytes(10000))


def webp(width: int, height: int) -> bytes:
    """Lossless WebP (VP8L) header; at most 16384 per side."""
    bits = (min(width, 16384) - 1) | ((min(height, 16384) - 1) << 14)
    payload = b"\x2f" + struct.pack("<I", bits) + bytes(100)
    riff = b"WEBP" + b"VP8L" + struct.pack("<I", len(payload)) + payload
    return b"RIFF" + struct.pack("<I", len(riff)) + riff


#: name -> (file suffix, bytes) of a bomb claiming at least 16384 x 16384 pixels.
BOMBS = {
    "png": (".png", png(40000, 40000)),
    "jpeg-junk": (".jpg", jpeg(32000, 32000)),
    "jpeg": (".jpg", jpeg(32000, 32000, junk=False)),
    "tiff-slong": (".tif", tiff(20000, 20000)),
    "tiff-duplicate-width": (".tif", tiff(20000, 20000, duplicate_width=True)),
    "bigtiff": (".tif", bigtiff(20000, 20000)),
    "hdr": (".hdr", hdr(20000, 20000)),
    "ppm": (".ppm", pnm(30000, 30000)),
    "pgm": (".pgm", pnm(30000, 30000, "P5")),
    "pam": (".pam", pam(30000, 30000)),
    "webp": (".webp", webp(16384, 16384)),
}

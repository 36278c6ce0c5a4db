"""ICC colour profiles the output can keep: a CMYK input's colours through its own profile, an
sRGB profile to tag them with, and a grey profile turned into the RGB one of the same tone.

littlecms (Pillow's :mod:`PIL.ImageCms`) does the colour conversion; the profiles written here
are built byte for byte, the same bytes on every run (littlecms stamps the time into the
profiles it makes).
"""

from __future__ import annotations

import functools
import io
import struct

import numpy as np

#: The date stamped into the profiles made here (littlecms writes the time of the call).
PROFILE_DATE = struct.pack(">6H", 2000, 1, 1, 0, 0, 0)
#: sRGB's colorants adapted to the PCS white (D50) as the ICC publishes them: they add up to D50,
#: so that R = G = B maps to that white times the tone curve, as a grey profile maps its value.
SRGB_COLORANTS = {b"rXYZ": (0.4361, 0.2225, 0.0139), b"gXYZ": (0.3851, 0.7169, 0.0971),
                  b"bXYZ": (0.1431, 0.0606, 0.7141)}


def space(icc: bytes | None) -> str | None:
    """The colour space of an ICC profile's pixels (``'RGB '``, ``'GRAY'``, ``'CMYK'``...; bytes
    16-19 of its header), None for no profile or a block too short to be one."""
    return icc[16:20].decode("latin-1") if icc and len(icc) >= 128 else None


@functools.lru_cache(maxsize=1)
def srgb() -> bytes:
    """littlecms's sRGB profile, with a fixed date: what a CMYK input's colours are converted to."""
    from PIL import ImageCms

    made = ImageCms.ImageCmsProfile(ImageCms.createProfile("sRGB")).tobytes()
    return made[:24] + PROFILE_DATE + made[36:]


@functools.lru_cache(maxsize=4)
def _cmyk_transform(icc: bytes):
    """littlecms's transform from the CMYK profile ``icc`` to sRGB (relative colorimetric with
    black point compensation, Photoshop's default for a conversion), or None where the profile
    is not a usable CMYK one."""
    from PIL import ImageCms

    if space(icc) != "CMYK":
        return None
    try:
        source = ImageCms.ImageCmsProfile(io.BytesIO(icc))
        target = ImageCms.ImageCmsProfile(ImageCms.createProfile("sRGB"))
        return ImageCms.buildTransform(source, target, "CMYK", "RGB", ImageCms.Intent.RELATIVE_COLORIMETRIC,
                                       flags=ImageCms.Flags.BLACKPOINTCOMPENSATION)
    except Exception:  # PyCMSError, or whatever a broken profile raises: not usable
        return None


def cmyk_usable(icc: bytes | None) -> bool:
    """Whether a CMYK input's colours can be converted through its profile ``icc``."""
    return bool(icc) and _cmyk_transform(bytes(icc)) is not None


def cmyk_to_srgb(data: bytes, shape: tuple, name: str) -> np.ndarray:
    """The CMYK JPEG ``data`` (Adobe-inverted or not; YCCK, which libjpeg gives as CMYK) as 8-bit
    BGR in sRGB through its own profile, as stored (not turned), of ``shape`` (OpenCV's decoding).

    Raises
    ------
    ImageError
        Where Pillow cannot decode it as CMYK of that size or its profile is unusable (the
        header promised sRGB pixels: none are made up).
    """
    from PIL import Image, ImageCms

    from . import ImageError

    try:
        with Image.open(io.BytesIO(data)) as image:
            transform = _cmyk_transform(bytes(image.info.get("icc_profile") or b""))
            if image.mode == "CMYK" and transform is not None:
                rgb = np.asarray(ImageCms.applyTransform(image, transform))
                if rgb.shape == tuple(shape):
                    return np.ascontiguousarray(rgb[:, :, ::-1])
    except Exception:  # whatever a decoder or littlecms raises: said below
        pass
    raise ImageError(f"{name} is CMYK and its colours cannot be converted through its colour profile")


def _tags(icc: bytes) -> dict[bytes, bytes]:
    """An ICC profile's tags: {signature: the tag's bytes}; empty for a broken table."""
    try:
        (count,) = struct.unpack_from(">I", icc, 128)
        found = {}
        for k in range(min(count, 100)):
            signature, offset, size = struct.unpack_from(">4sII", icc, 132 + 12 * k)
            if offset + size > len(icc):
                return {}
            found[signature] = icc[offset:offset + size]
        return found
    except struct.error:
        return {}


def _xyz(values) -> bytes:
    """An ICC XYZType tag of one (X, Y, Z) in s15Fixed16."""
    return b"XYZ \0\0\0\0" + struct.pack(">3i", *(round(v * 65536) for v in values))


def _description(text: str, version: int) -> bytes:
    """A description tag: textDescriptionType (version 2) or multiLocalizedUnicodeType (4)."""
    if version >= 4:
        utf16 = text.encode("utf-16-be")
        return b"mluc\0\0\0\0" + struct.pack(">II2s2sII", 1, 12, b"en", b"US", len(utf16), 28) + utf16
    ascii_text = text.encode("ascii", "replace") + b"\0"
    return b"desc\0\0\0\0" + struct.pack(">I", len(ascii_text)) + ascii_text + bytes(4 + 4 + 2 + 1 + 67)


def rgb_from_gray(icc: bytes) -> bytes | None:
    """The RGB profile that shows grey pixels written as R = G = B exactly as the grey profile
    ``icc`` shows them: its tone curve (kTRC) for each channel, its white point and version,
    sRGB's colorants (which add up to the PCS white, so a grey maps to the same XYZ); None for a
    profile that is not a grey one with a tone curve. The same profile gives the same bytes."""
    if space(icc) != "GRAY":
        return None
    tags = _tags(icc)
    if b"kTRC" not in tags or b"wtpt" not in tags:
        return None
    version = icc[8]
    name = _description_text(tags.get(b"desc", b"")) or "grey"
    parts = [(b"desc", _description(f"RGB of {name}"[:60], version)), (b"wtpt", tags[b"wtpt"])]
    parts += [(sig, _xyz(value)) for sig, value in SRGB_COLORANTS.items()]
    parts += [(b"rTRC", tags[b"kTRC"]), (b"gTRC", tags[b"kTRC"]), (b"bTRC", tags[b"kTRC"])]
    if b"cprt" in tags:
        parts.append((b"cprt", tags[b"cprt"]))
    table, body = b"", b""
    at = 128 + 4 + 12 * len(parts)
    for signature, tag in parts:
        table += struct.pack(">4sII", signature, at + len(body), len(tag))
        body += tag + b"\0" * (-len(tag) % 4)
    header = bytearray(icc[:128])
    header[12:20] = b"mntrRGB "
    header[24:36] = icc[24:36]                        # the grey profile's own date: fixed bytes
    header[84:100] = bytes(16)                        # no profile ID (an MD5 that would be stale)
    whole = bytes(header) + struct.pack(">I", len(parts)) + table + body
    return struct.pack(">I", len(whole)) + whole[4:]


def _description_text(tag: bytes) -> str:
    """The text of a description tag (v2 ``desc`` or v4 ``mluc``), '' when unreadable."""
    try:
        if tag[:4] == b"desc":
            (size,) = struct.unpack_from(">I", tag, 8)
            return tag[12:12 + size].split(b"\0")[0].decode("ascii", "replace")
        if tag[:4] == b"mluc":
            size, offset = struct.unpack_from(">II", tag, 20)
            return tag[offset:offset + size].decode("utf-16-be", "replace")
    except (struct.error, UnicodeDecodeError):
        pass
    return ""


def for_pixels(icc: bytes | None, channels: int) -> bytes | None:
    """The profile to store with pixels of ``channels`` (1: grey, 3 or 4: colour) from the
    input's ``icc``: itself where its space matches; a grey profile turned into the RGB one of
    the same tone (:func:`rgb_from_gray`) for grey pixels written in colour (a canvas that gained
    transparency, WebP); else None (a CMYK profile on the RGB pixels it is decoded to, or an RGB
    profile on grey ones, would make viewers show wrong colours, and libpng warn)."""
    kind = space(icc)
    if kind is None:
        return None
    if kind == ("GRAY" if channels == 1 else "RGB "):
        return icc
    if kind == "GRAY" and channels in (3, 4):
        return rgb_from_gray(icc)
    return None

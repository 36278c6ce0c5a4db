"""Encoding animations: frames -> the bytes of an animated GIF, PNG (APNG) or WebP.

Every format is written by Pillow or assembled here, with every setting pinned, so that the
same frames always give the same bytes. GIF frames take the still GIF's adaptive palette
(:func:`featurewarp_cli.io.encode.encode_image`): OpenCV's animation writer used a fixed
8x8x4 colour cube with dithering, 19.7 levels RMS off the input at an identity frame of the
astronaut, false colour on grey photos and checkered flat logo colours. An APNG is the frames'
own PNGs (the first with the input's metadata) put together, so that its delay is the exact
fraction 1/fps (OpenCV wrote ``round(1000/fps)/1000`` s, which wrapped past 65.5 s).
"""

from __future__ import annotations

import io
import math
import struct
from fractions import Fraction

import numpy as np

from . import ImageError, metadata, png
from .encode import GIF_TRANSPARENT, encode_image, gif_picture, rgb_order, webp_options

#: The fastest frame rate a GIF plays as written: its delays are in 1/100 s, and browsers play
#: a delay under 2/100 s as 1/10 s (a 60 fps GIF ran six times too slowly).
GIF_MAX_FPS = 50.0


def frame_delays(fps: float, count: int, ticks: int) -> list[int]:
    """Each frame's delay in 1/``ticks`` s, so that frame k ends at k/fps rounded to a tick: the
    delays average 1/fps exactly (30 fps in 1/100 s: 3, 4, 3, 3, 4, 3 ...) instead of drifting.

    Examples
    --------
    >>> frame_delays(30, 6, 100), frame_delays(24, 3, 1000)
    ([3, 4, 3, 3, 4, 3], [42, 41, 42])
    """
    ends = [math.floor((k + 1) * ticks / fps + 0.5) for k in range(count)]
    return [max(1, end - start) for start, end in zip([0] + ends, ends)]


def delay_fraction(fps: float) -> tuple[int, int]:
    """An APNG delay (numerator, denominator), both 16-bit, nearest 1/``fps`` s.

    Examples
    --------
    >>> delay_fraction(24), delay_fraction(0.01), delay_fraction(29.97)
    ((1, 24), (100, 1), (100, 2997))
    """
    seconds = Fraction(1) / Fraction(fps).limit_denominator(1 << 20)
    largest = max(1, min(65535, math.floor(65535 / seconds)))      # the numerator stays 16-bit
    delay = seconds.limit_denominator(largest)
    return min(65535, max(1, delay.numerator)), delay.denominator


def gif_bytes(frames: list[np.ndarray], fps: float, transparent: bool) -> bytes:
    """An animated GIF of 8-bit BGR(A) ``frames`` at ``fps`` (at most :data:`GIF_MAX_FPS`), looping.

    Each frame has its own palette, as a still GIF: grey frames a grey one, others an adaptive
    one of 256 colours (median cut, Floyd-Steinberg dither). With ``transparent``, a pixel whose
    alpha is under half is transparent (the others opaque, their colour kept), and the colours
    come from 255 entries (:func:`featurewarp_cli.io.encode.gif_picture`). Identical consecutive
    frames are one frame shown as long as both (Pillow's writer).
    """
    grey = not transparent and all(np.array_equal(f[:, :, 0], f[:, :, 1]) and np.array_equal(f[:, :, 0], f[:, :, 2])
                                   for f in frames)
    images = [gif_picture(np.ascontiguousarray(frame[:, :, 0]) if grey else frame, transparent) for frame in frames]
    options = {"transparency": GIF_TRANSPARENT, "disposal": 2} if transparent else {}
    buffer = io.BytesIO()
    images[0].save(buffer, "GIF", save_all=True, append_images=images[1:], loop=0, optimize=False,
                   duration=[10 * d for d in frame_delays(min(fps, GIF_MAX_FPS), len(frames), 100)], **options)
    return buffer.getvalue()


def webp_bytes(frames: list[np.ndarray], fps: float, quality: int | None, icc: bytes | None = None,
               exif: bytes | None = None, xmp: bytes | None = None) -> bytes:
    """An animated WebP of 8-bit BGR(A) ``frames`` at ``fps``, looping, with the input's ICC
    profile, EXIF and XMP: lossless in libwebp's exact mode (the colour under transparent pixels
    kept too), or lossy at ``quality``."""
    from PIL import Image

    images = [Image.fromarray(rgb_order(frame)) for frame in frames]
    exif = exif and metadata.sized_exif(exif, *images[0].size)        # the frames' size, as encode_image
    kept = {key: value for key, value in (("icc_profile", icc), ("exif", exif), ("xmp", xmp)) if value}
    buffer = io.BytesIO()
    images[0].save(buffer, "WEBP", save_all=True, append_images=images[1:], loop=0,
                   duration=frame_delays(fps, len(frames), 1000), **webp_options(quality), **kept)
    return buffer.getvalue()


def apng_bytes(frames: list[np.ndarray], fps: float, **kept) -> bytes:
    """An animated PNG of 8-bit BGR(A) ``frames``, each shown 1/``fps`` s (:func:`delay_fraction`),
    looping: the frames' PNGs (:func:`featurewarp_cli.io.encode.encode_image`), the first with
    the metadata ``kept`` (``icc``, ``exif``, ``xmp``, ``dpi``) ahead of its pixels."""
    num, den = delay_fraction(fps)
    first = png.chunks(encode_image(frames[0], "png", **kept))
    at = next(k for k, (kind, _) in enumerate(first) if kind == b"IDAT")
    head, ihdr = first[1:at], first[0][1]
    out = [png.SIGNATURE, png.make_chunk(b"IHDR", ihdr)] + [png.make_chunk(kind, data) for kind, data in head]
    out.append(png.make_chunk(b"acTL", struct.pack(">II", len(frames), 0)))
    sequence = 0
    for index, frame in enumerate(frames):
        chunks = first if index == 0 else png.chunks(encode_image(frame, "png"))
        if chunks[0][1] != ihdr:
            raise ImageError("the animation's frames differ in size or colour type")
        out.append(png.make_chunk(b"fcTL", struct.pack(">IIIIIHHBB", sequence, frame.shape[1], frame.shape[0], 0, 0,
                                               num, den, 0, 0)))
        sequence += 1
        for kind, data in chunks:
            if kind == b"IDAT" and index == 0:
                out.append(png.make_chunk(kind, data))
            elif kind == b"IDAT":
                out.append(png.make_chunk(b"fdAT", struct.pack(">I", sequence) + data))
                sequence += 1
    tail = first[max(k for k, (kind, _) in enumerate(first) if kind == b"IDAT") + 1:]
    out += [png.make_chunk(kind, data) for kind, data in tail if kind != b"IEND"]
    return b"".join(out + [png.make_chunk(b"IEND", b"")])



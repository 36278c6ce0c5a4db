"""Output formats: their names, ImageMagick-style ``png:`` prefixes, and an OUTPUT's format.

Imports neither OpenCV nor Pillow (the command line builds its ``--format`` choice
from :data:`NAMES`). The encoders' settings live in :mod:`featurewarp_cli.io.encode`.
"""

from __future__ import annotations

import os
from typing import NamedTuple


class Format(NamedTuple):
    """What the pipeline needs to know of an output format."""

    extension: str      #: the extension OpenCV's encoder is chosen by
    alpha: bool         #: stores an alpha channel
    eight_bit: bool     #: stores 8-bit samples only (16-bit results are scaled down)
    largest_side: int | None = None     #: the encoder's limit on a side, in pixels (None: none in reach)


#: Output formats by canonical name.
FORMATS = {
    "png": Format(".png", alpha=True, eight_bit=False, largest_side=1_000_000),     # libpng's user limit
    "jpg": Format(".jpg", alpha=False, eight_bit=True, largest_side=65_500),        # libjpeg's
    "webp": Format(".webp", alpha=True, eight_bit=True, largest_side=16_383),
    "tiff": Format(".tiff", alpha=True, eight_bit=False),
    "bmp": Format(".bmp", alpha=False, eight_bit=True),
    "gif": Format(".gif", alpha=False, eight_bit=True, largest_side=65_535),  # one static frame, an adaptive palette (Pillow)
}
#: Other spellings of the format names (also accepted as file extensions).
ALIASES = {"jpeg": "jpg", "tif": "tiff"}
#: Every name ``--format`` accepts.
NAMES = ("png", "jpg", "jpeg", "webp", "tif", "tiff", "bmp", "gif")


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


def output_target(spec: str, fmt: str | None = None, other: str = "--format") -> tuple[str, str]:
    """Path and format name of an OUTPUT argument.

    The format comes from a ``png:``-style prefix, else ``fmt`` (``--format``),
    else the path's extension. ``-`` (stdout) needs a prefix or ``fmt``. ``other``: the way to
    name a format besides an extension that an error suggests (``diff`` has no ``--format``).

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
                             f"use one of {known}, or {other}")
    return path, name

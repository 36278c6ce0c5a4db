"""Colour text for the background of uncovered pixels (``--background``).

Pillow's :func:`PIL.ImageColor.getrgb` reads the CSS colour names and the ``#rgb``,
``#rrggbb``, ``#rrggbbaa``, ``rgb()``, ``rgba()`` and ``hsl()`` forms; an ``rgba()``
alpha written as CSS writes it (0.5, 50 %) is turned into Pillow's 0..255 first.
"""

from __future__ import annotations

import re

from PIL import ImageColor

#: rgba(...) whose alpha is a fraction or a percentage, as CSS writes it.
_CSS_ALPHA = re.compile(r"rgba\(\s*(\d+\s*,\s*\d+\s*,\s*\d+)\s*,\s*(\d*\.\d+|\d+(?=\s*%)|[01]\.?)\s*(%)?\s*\)")
#: Words that mean "no colour": uncovered pixels stay transparent.
TRANSPARENT = ("transparent", "none")


def parse_colour(text: str, alpha: bool = False) -> tuple[int, ...] | None:
    """An opaque colour as (r, g, b), or None for ``transparent`` / ``none``.

    Parameters
    ----------
    text : str
        A CSS colour name (``white``, ``skyblue`` ...), ``#rgb``, ``#rrggbb``,
        ``rgb(r, g, b)``, ``hsl(h, s%, l%)``, ``transparent`` or ``none``; with ``alpha``
        also ``#rrggbbaa`` and ``rgba(r, g, b, a)``. Case and surrounding blanks do not
        matter.
    alpha : bool
        Accept a colour with an alpha value (returned as (r, g, b, a) when a < 255).

    Returns
    -------
    tuple of int (r, g, b) (or (r, g, b, a)) in 0..255, or None for transparent.

    Raises
    ------
    ValueError
        For text that is not a colour, values outside 0..255, or a colour with alpha.

    Examples
    --------
    >>> parse_colour("skyblue"), parse_colour("#f80"), parse_colour("none")
    ((135, 206, 235), (255, 136, 0), None)
    """
    word = text.strip()
    if word.lower() in TRANSPARENT:
        return None
    css = _CSS_ALPHA.fullmatch(word.lower())
    if css:                                   # CSS's rgba(r, g, b, 0.5) or 50 %: Pillow wants 0..255
        fraction = float(css.group(2)) / (100.0 if css.group(3) else 1.0)
        if not 0.0 <= fraction <= 1.0:
            raise ValueError(f"{text!r} has an alpha outside 0..1")
        word = f"rgba({css.group(1)}, {round(fraction * 255)})"
    try:
        colour = ImageColor.getrgb(word)
    except ValueError:
        raise ValueError(f"{text!r} is not a colour (use #rrggbb, #rgb, a name such as white, rgb(r,g,b), "
                         "hsl(h,s%,l%), or transparent)") from None
    if not all(0 <= value <= 255 for value in colour):
        raise ValueError(f"{text!r} has a value outside 0..255")
    if len(colour) == 4:
        if not alpha:
            raise ValueError(f"{text!r} has an alpha value; use an opaque colour or transparent")
        if colour[3] < 255:
            return tuple(int(value) for value in colour)
    return tuple(int(value) for value in colour[:3])

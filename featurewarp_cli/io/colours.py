"""Colour text for the background of uncovered pixels (``--background``).

Pillow's :func:`PIL.ImageColor.getrgb` reads the CSS colour names and the ``#rgb``,
``#rrggbb``, ``rgb()`` and ``hsl()`` forms.
"""

from __future__ import annotations

from PIL import ImageColor

#: Words that mean "no colour": uncovered pixels stay transparent.
TRANSPARENT = ("transparent", "none")


def parse_colour(text: str) -> tuple[int, int, int] | None:
    """An opaque colour as (r, g, b), or None for ``transparent`` / ``none``.

    Parameters
    ----------
    text : str
        A CSS colour name (``white``, ``skyblue`` ...), ``#rgb``, ``#rrggbb``,
        ``rgb(r, g, b)``, ``hsl(h, s%, l%)``, ``transparent`` or ``none``; case and
        surrounding blanks do not matter.

    Returns
    -------
    tuple of int (r, g, b) in 0..255, or None for transparent.

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
    try:
        colour = ImageColor.getrgb(word)
    except ValueError:
        raise ValueError(f"{text!r} is not a colour (use #rrggbb, a name such as white, "
                         "or transparent)") from None
    if len(colour) == 4:
        raise ValueError(f"{text!r} has an alpha value; use an opaque colour or transparent")
    if not all(0 <= value <= 255 for value in colour):
        raise ValueError(f"{text!r} has a value outside 0..255")
    return tuple(int(value) for value in colour)

"""The feature mask of a run: a mask file, or INPUT's own alpha (``--mask alpha``).

A cut-out (a product shot on transparency) carries its mask: its opaque part is the
subject. ``--mask alpha`` (``batch --mask-pattern alpha``: every input's own) reads it
as a mask file is read, at 128: alpha >= 128 (half opaque) marks a feature. A file
that is called ``alpha`` is named ``./alpha``. Nothing here depends on click.
"""

from __future__ import annotations

import os

import numpy as np

from .. import stages
from ..io import decode

#: The ``--mask`` value that means INPUT's alpha channel, not a file.
ALPHA = "alpha"


def uses_alpha(settings, mask: str | None) -> bool:
    """Whether the mask is INPUT's alpha: ``mask`` is :data:`ALPHA`, or none is given and
    ``settings.alpha_mask`` (a batch's ``--mask-pattern alpha``) says so."""
    return mask == ALPHA or (mask is None and getattr(settings, "alpha_mask", False))


def masked(settings, mask: str | None) -> bool:
    """Whether the run has a feature mask (a file or the alpha) and uses it (not plain mode)."""
    return (mask is not None or uses_alpha(settings, mask)) and settings.mode != "plain"


def mask_file(settings, mask: str | None) -> str | None:
    """The mask file the run reads: ``mask``, or None when there is none or it is the alpha."""
    return None if uses_alpha(settings, mask) else mask


def load_mask(settings, mask: str | None, size: tuple[int, int], header=None, image=None):
    """The feature mask, checked against the image's (width, height) (``header``: its header),
    and warnings; from ``image``'s alpha (decoded INPUT) when :func:`uses_alpha`."""
    from .pipeline import WarpError, check_file_size, read_input

    if uses_alpha(settings, mask):
        return alpha_mask(image, mask == ALPHA)
    width, height = size
    if mask != "-" and os.path.isfile(mask):
        check_file_size(mask, "--mask", settings.max_memory, settings.max_pixels)
    pixels = read_input(mask, "--mask", settings.max_pixels, max_bytes=settings.max_memory)
    feature_mask = decode.mask_from_image(pixels)
    if feature_mask.shape != (height, width):
        turned = (feature_mask.shape == (width, height) and getattr(header, "orientation", 1) >= 5) * \
            " (upright, as its EXIF orientation turns it: draw the mask on the image as viewers show it)"
        raise WarpError(f"mask is {feature_mask.shape[1]}x{feature_mask.shape[0]} but the "
                        f"image is {width}x{height}{turned}", "--mask", usage=True)
    if feature_mask.any():
        return feature_mask, []
    brightest, colour = decode.brightest_gray(pixels)
    return feature_mask, [f"the mask marks no feature (a feature is gray 128 or more, or a 1 of a 0/1 mask; its "
                          f"brightest pixel is {brightest}{', as colour is read as its gray: pure red is 76' * colour})"
                          f": plain warp"]


def alpha_mask(image: np.ndarray, named: bool = True) -> tuple[np.ndarray, list[str]]:
    """The feature mask of INPUT's alpha: alpha >= 128 (on the 0..255 scale), and warnings
    (an alpha that marks nothing or everything). ``named``: ``--mask alpha`` was given (a
    notice where a file called alpha is beside it), else a batch's ``--mask-pattern alpha``. An
    image without alpha is a usage error naming the option given and what to give instead (``./alpha``
    where a file called alpha is here)."""
    from .pipeline import WarpError

    if image.ndim != 3 or image.shape[2] != 4:
        if not named:                       # a batch's --mask-pattern alpha: it has no --mask
            todo, param = "give --mask-pattern a file pattern, such as '{stem}_mask.png'", "--mask-pattern"
        elif os.path.isfile(ALPHA):         # --mask alpha read this file before it meant the alpha
            todo, param = "for the file 'alpha' here, give --mask ./alpha", "--mask"
        else:
            todo, param = "give a mask file", "--mask"
        raise WarpError("the input has no alpha channel to take the mask from (alpha: a cut-out's own "
                        f"transparency, in a PNG, WebP or TIFF with alpha); {todo}", param, usage=True)
    if named and os.path.isfile(ALPHA):
        stages.notice("--mask alpha is the input's alpha channel, not the file 'alpha' here (for that "
                      "file: --mask ./alpha)")
    feature_mask = image[:, :, 3] >= 128 * np.iinfo(image.dtype).max / 255
    if not feature_mask.any():
        return feature_mask, ["the input's alpha marks no feature (no pixel is half opaque or more, as "
                              "--mask alpha needs): plain warp"]
    if feature_mask.all():
        return feature_mask, ["the input's alpha is opaque everywhere: --mask alpha makes the whole image "
                              "one feature (a cut-out has a transparent background)"]
    return feature_mask, []

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
        for hint in inverted(feature_mask):      # a question, not a compromise: --strict passes it
            stages.notice(f"notice: {mask}: {hint}")
        return feature_mask, dropped_colour(pixels, feature_mask)
    brightest, colour = decode.brightest_gray(pixels)
    top, most = np.iinfo(pixels.dtype).max, int(pixels.max(initial=0))
    if top > 255 and most <= 255:                       # 0..255 values in a 16-bit file: not 0
        brightest = f"{most} of {top}, as a 16-bit mask is read on its own scale (a feature: 32896 or more)"
    elif pixels.ndim == 3 and pixels.shape[2] == 4 and bool((pixels[:, :, 3] >= 128 * top / 255).any()):
        brightest = f"{brightest}: its opaque pixels are dark, and its transparent ones count as black"
    return feature_mask, [f"the mask marks no feature (a feature is gray 128 or more, or a 1 of a 0/1 mask; its "
                          f"brightest pixel is {brightest}{', as colour is read as its gray: pure red is 76' * colour})"
                          f": plain warp"]


def dropped_colour(pixels: np.ndarray, feature_mask: np.ndarray) -> list[str]:
    """A warning where strokes of a strong colour are read as no feature (their gray, over black,
    is under 128: a red or blue brush) while other pixels are features: they drop out in silence.
    Strong: the brightest channel (over black, by alpha) 128 or more, the channels 64 or more apart."""
    if pixels.ndim != 3 or pixels.shape[2] < 3:
        return []
    top = np.iinfo(pixels.dtype).max
    colour = pixels[:, :, :3]
    brightest = np.maximum(np.maximum(colour[:, :, 0], colour[:, :, 1]), colour[:, :, 2])   # 4x a max(axis=2)
    if brightest.max(initial=0) <= 1:                   # a 0/1 mask in colour: its own rule
        return []
    at = np.flatnonzero((brightest >= 128 * top / 255) & ~feature_mask)     # in integers: few are left
    samples = colour.reshape(-1, 3)[at].astype(np.float32)
    if pixels.shape[2] == 4:
        samples *= pixels[:, :, 3].reshape(-1)[at, None] / np.float32(top)
    strong = (samples.max(axis=1) >= 128 * top / 255) & (np.ptp(samples, axis=1) >= 64 * top / 255)
    dropped = int(np.count_nonzero(strong))
    if dropped < max(16, feature_mask.sum() // 100):
        return []
    return [f"{dropped} pixels of the mask are painted in a colour whose gray is under 128 (pure red is 76, "
            "pure blue 29) and mark no feature; paint features white"]


def inverted(feature_mask: np.ndarray) -> list[str]:
    """A hint where the mask looks inverted: it marks most of the image and (nearly) all of the
    frame's border, as a mask of the background does (:func:`load_mask` says it as a notice)."""
    border = np.concatenate([feature_mask[0], feature_mask[-1], feature_mask[1:-1, 0], feature_mask[1:-1, -1]])
    share = feature_mask.mean()
    if share <= 0.5 or border.mean() < 0.9 or feature_mask.all():     # all: "covers" says it
        return []
    return [f"the mask marks {share:.0%} of the image and {border.mean():.0%} of its border: is it inverted? "
            "(features are white, gray 128 or more; a mask of the background holds it still and lets the "
            "subject bend)"]


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

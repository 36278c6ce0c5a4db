"""Sample depths: the one rule that brings 16-bit samples to 8 bits.

A 16-bit sample v stands for v / 257 on the 8-bit scale (65535 / 255 = 257): the
encoders of 8-bit formats, the compare panel, animations and ``diff`` all use it.
"""

from __future__ import annotations

import numpy as np

#: 16-bit steps per 8-bit step.
SIXTEEN_PER_EIGHT = 257


def on_eight_bit_scale(image: np.ndarray) -> np.ndarray:
    """The samples of a uint8 or uint16 image as float64 on the 0..255 scale (same shape)."""
    scale = SIXTEEN_PER_EIGHT if image.dtype == np.uint16 else 1
    return image.astype(np.float64) / scale


def to_eight_bit(image: np.ndarray) -> np.ndarray:
    """A uint8 image: uint8 as it is, uint16 rounded to the nearest 8-bit value (round(v / 257)).

    Raises
    ------
    ValueError
        For a sample type other than uint8 and uint16.
    """
    if image.dtype == np.uint8:
        return image
    if image.dtype != np.uint16:
        raise ValueError(f"cannot bring {image.dtype} samples to 8 bits (uint8 or uint16 expected)")
    # v / 257 is never halfway between two integers, so this is exact rounding.
    return ((image.astype(np.uint32) + SIXTEEN_PER_EIGHT // 2) // SIXTEEN_PER_EIGHT).astype(np.uint8)

"""Tolerant image comparison for golden-image tests (``featurewarp diff``).

All metrics are on the 0..255 scale: 8-bit samples as they are, 16-bit samples
divided by 257. Every channel counts, alpha included.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..io.depth import on_eight_bit_scale


@dataclass(frozen=True)
class Comparison:
    """Differences between two images of the same size and channel count.

    Attributes
    ----------
    rmse : float
        Root mean square difference over all samples.
    psnr : float
        20 log10(255 / rmse) in dB; inf for identical images.
    max_abs : float
        Largest absolute difference of one sample.
    pixels_off : int
        Pixels where some channel differs by more than ``tolerance``.
    pixels : int
        Width * height.
    tolerance : float
    off : (h, w) bool ndarray
        Which pixels are off.
    """

    rmse: float
    psnr: float
    max_abs: float
    pixels_off: int
    pixels: int
    tolerance: float
    off: np.ndarray

    def lines(self) -> list[str]:
        """The metrics as ``name value`` lines (what ``featurewarp diff`` prints)."""
        return [f"rmse {self.rmse:.6g}", f"psnr {self.psnr:.6g}", f"max_abs_diff {self.max_abs:.6g}",
                f"pixels_off {self.pixels_off} of {self.pixels} (tolerance {self.tolerance:g})"]


def channels(image: np.ndarray) -> int:
    """Channel count of an (h, w) or (h, w, C) image."""
    return 1 if image.ndim == 2 else image.shape[2]


def normalised(image: np.ndarray) -> np.ndarray:
    """(h, w, C) float64 samples on the 0..255 scale."""
    data = on_eight_bit_scale(image)
    return data[:, :, None] if data.ndim == 2 else data


def mismatch(a: np.ndarray, b: np.ndarray) -> str | None:
    """Why ``a`` and ``b`` cannot be compared (size or channel count), or None."""
    if a.shape[:2] != b.shape[:2]:
        return f"sizes differ: {a.shape[1]}x{a.shape[0]} vs {b.shape[1]}x{b.shape[0]}"
    if channels(a) != channels(b):
        return f"channel counts differ: {channels(a)} vs {channels(b)}"
    return None


def compare(a: np.ndarray, b: np.ndarray, tolerance: float = 0.0) -> Comparison:
    """Compare two images sample by sample.

    Parameters
    ----------
    a, b : (h, w) or (h, w, C) ndarray, uint8 or uint16
        Same size and channel count (depths may differ).
    tolerance : float
        A pixel is off when some channel differs by more than this (0..255 scale).

    Returns
    -------
    Comparison

    Raises
    ------
    ValueError
        If the sizes or channel counts differ.

    Examples
    --------
    >>> a = np.zeros((2, 2), np.uint8); b = a.copy(); b[0, 0] = 10
    >>> c = compare(a, b)
    >>> c.rmse, c.max_abs, c.pixels_off
    (5.0, 10.0, 1)
    """
    reason = mismatch(a, b)
    if reason:
        raise ValueError(reason)
    diff = np.abs(normalised(a) - normalised(b))
    rmse = float(np.sqrt(np.mean(diff**2)))
    off = diff.max(axis=2) > tolerance
    return Comparison(rmse=rmse, psnr=20 * math.log10(255 / rmse) if rmse > 0 else math.inf,
                      max_abs=float(diff.max()), pixels_off=int(off.sum()), pixels=off.size,
                      tolerance=float(tolerance), off=off)


def failures(c: Comparison, max_rmse=None, min_psnr=None, max_pixels_off=None) -> list[str]:
    """The tolerances ``c`` breaks, one text each; empty when within tolerance.

    With no limit given the images must match within ``c.tolerance`` everywhere.
    """
    exact = max_rmse is None and min_psnr is None and max_pixels_off is None
    broken = []
    if max_rmse is not None and c.rmse > max_rmse:
        broken.append(f"rmse {c.rmse:.6g} > {max_rmse:g} (--max-rmse)")
    if min_psnr is not None and c.psnr < min_psnr:
        broken.append(f"psnr {c.psnr:.6g} dB < {min_psnr:g} (--min-psnr)")
    if exact and c.pixels_off:
        broken.append(f"{c.pixels_off} pixels differ by more than {c.tolerance:g} (with no limit given, none may: "
                      f"--max-rmse, --min-psnr or --max-pixels-off set one)")
    elif max_pixels_off is not None and c.pixels_off > max_pixels_off:
        broken.append(f"{c.pixels_off} pixels differ by more than {c.tolerance:g}, at most "
                      f"{max_pixels_off} allowed (--max-pixels-off)")
    return broken


def highlight(a: np.ndarray, off: np.ndarray) -> np.ndarray:
    """A picture of where two images differ: ``a`` in faded gray, off pixels in red.

    Parameters
    ----------
    a : (h, w) or (h, w, C) ndarray
    off : (h, w) bool ndarray

    Returns
    -------
    (h, w, 3) uint8 ndarray, BGR.
    """
    samples = normalised(a)[:, :, :3]
    gray = samples.mean(axis=2) if samples.shape[2] < 3 else samples @ [0.114, 0.587, 0.299]
    faded = np.round(128 + gray / 2).astype(np.uint8)
    out = np.repeat(faded[:, :, None], 3, axis=2)
    out[off] = (0, 0, 255)
    return out

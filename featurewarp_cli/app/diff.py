"""Tolerant image comparison for golden-image tests (``featurewarp diff``).

All metrics are on the 0..255 scale: 8-bit samples as they are, 16-bit samples
divided by 257. Every channel counts, alpha included, but an alpha that is opaque
everywhere in both images (or frames) is left out, so an opaque RGBA file reads as
its RGB twin; colour is compared premultiplied by alpha (what it adds over any
background), so the colour under a fully transparent pixel, which no one sees, counts
as 0. Images whose channel layouts
differ are compared as what their pixels mean: gray as R = G = B, no alpha as opaque.
Animations and multi-page files are compared frame by frame (:func:`compare_frames`).
"""

from __future__ import annotations

import math
from collections.abc import Iterable
from dataclasses import dataclass

import numpy as np

from ..io.depth import on_eight_bit_scale


@dataclass(frozen=True)
class Comparison:
    """Differences between two images (or two animations) of the same size.

    Attributes
    ----------
    rmse : float
        Root mean square difference over all samples of all frames.
    psnr : float
        20 log10(255 / rmse) in dB; inf for identical images.
    max_abs : float
        Largest absolute difference of one sample.
    pixels_off : int
        Pixels where some channel differs by more than ``tolerance``, summed over the frames.
    pixels : int
        Width * height * frames.
    tolerance : float
    off : (h, w) bool ndarray
        Which pixels are off (in some frame).
    frames : int
        Frames compared (1 for still images).
    frames_off : tuple of int
        The frames (numbered from 1) with a pixel off.
    notes : tuple of str
        What was widened to compare the channel layouts (gray as R = G = B, no alpha as opaque).
    """

    rmse: float
    psnr: float
    max_abs: float
    pixels_off: int
    pixels: int
    tolerance: float
    off: np.ndarray
    frames: int = 1
    frames_off: tuple = ()
    notes: tuple = ()

    def lines(self) -> list[str]:
        """The metrics as ``name value`` lines (what ``featurewarp diff`` prints); a ``frames``
        line for animations and multi-page files."""
        lines = [f"rmse {self.rmse:.6g}", f"psnr {self.psnr:.6g}", f"max_abs_diff {self.max_abs:.6g}",
                 f"pixels_off {self.pixels_off} of {self.pixels} (tolerance {self.tolerance:g})"]
        if self.frames > 1:
            differ = ", ".join(map(str, self.frames_off)) or "none"
            lines.append(f"frames {self.frames} (off: {differ})")
        return lines


def channels(image: np.ndarray) -> int:
    """Channel count of an (h, w) or (h, w, C) image."""
    return 1 if image.ndim == 2 else image.shape[2]


def normalised(image: np.ndarray) -> np.ndarray:
    """(h, w, C) float64 samples on the 0..255 scale, colour premultiplied by alpha: what a pixel
    adds over any background, so colour under alpha 0 is 0 (encoders differ there, libwebp fills
    it with nearby colour) and colour under alpha 1 counts 1/255 (a 16-bit twin's rounding there
    failed ``--max-rmse 0.5``)."""
    data = on_eight_bit_scale(image)
    data = data[:, :, None] if data.ndim == 2 else data
    if data.shape[2] == 4:
        data[:, :, :3] *= data[:, :, 3:] / 255.0
    return data


#: Channel counts whose pixels can be widened to each other (gray, BGR, BGRA).
LAYOUTS = {1: "gray", 3: "colour without alpha", 4: "colour with alpha"}


def mismatch(a: np.ndarray, b: np.ndarray) -> str | None:
    """Why ``a`` and ``b`` cannot be compared (size or channel count), or None."""
    if a.shape[:2] != b.shape[:2]:
        return f"sizes differ: {a.shape[1]}x{a.shape[0]} vs {b.shape[1]}x{b.shape[0]}"
    if channels(a) != channels(b) and not {channels(a), channels(b)} <= LAYOUTS.keys():
        return f"channel counts differ: {channels(a)} vs {channels(b)}"
    return None


def aligned(a: np.ndarray, b: np.ndarray) -> tuple[np.ndarray, np.ndarray, list[str]]:
    """``a`` and ``b`` in the same channel layout, the narrower widened: gray as B = G = R, no
    alpha as opaque (what their pixels mean; a PNG optimiser or ``convert`` may change the
    layout of a golden file and no pixel). Returns the two and notes saying what was widened.

    Examples
    --------
    >>> a, b, notes = aligned(np.zeros((1, 1), np.uint8), np.zeros((1, 1, 4), np.uint8))
    >>> a.shape, notes
    ((1, 1, 4), ['A is gray without alpha: compared as R = G = B, opaque'])
    """
    want = max(channels(a), channels(b))
    notes = []

    def widen(image, name):
        have = channels(image)
        if have == want:
            return image
        out = image if image.ndim == 3 else image[:, :, None]
        if have == 1:
            out = np.repeat(out, 3, axis=2)
        if want == 4:
            top = np.iinfo(image.dtype).max
            out = np.dstack([out, np.full(image.shape[:2], top, image.dtype)])
        how = {(1, 3): "R = G = B", (1, 4): "R = G = B, opaque", (3, 4): "opaque"}[have, want]
        notes.append(f"{name} is {LAYOUTS[have]}" + (" without alpha" if have == 1 and want == 4 else "")
                     + f": compared as {how}")
        return out

    return widen(a, "A"), widen(b, "B"), notes


def compare(a: np.ndarray, b: np.ndarray, tolerance: float = 0.0) -> Comparison:
    """Compare two images sample by sample.

    Parameters
    ----------
    a, b : (h, w) or (h, w, C) ndarray, uint8 or uint16
        Same size; depths may differ, and channel layouts (:func:`aligned`).
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
    return compare_frames([(a, b)], tolerance)


def compare_frames(pairs: Iterable[tuple[np.ndarray, np.ndarray]], tolerance: float = 0.0) -> Comparison:
    """Compare two animations (or multi-page files) frame by frame: the metrics of all their
    samples together, ``off`` where some frame is off; see :func:`compare`.

    Parameters
    ----------
    pairs : iterable of (a, b)
        The frames of the two, one pair at a time (decoded as they are needed).
    tolerance : float

    Raises
    ------
    ValueError
        If a pair cannot be compared (its frame named when there are several), or there is none.
    """
    squares, samples, max_abs, pixels_off, pixels = 0.0, 0, 0.0, 0, 0
    off, frames_off, notes, count = None, [], [], 0
    for count, (a, b) in enumerate(pairs, 1):
        reason = mismatch(a, b)
        if reason:
            raise ValueError(reason if count == 1 else f"frame {count}: {reason}")
        a, b, widened = aligned(a, b)
        notes += [note for note in widened if note not in notes]
        a, b = normalised(a), normalised(b)
        if a.shape[2] == 4 and (a[:, :, 3] == 255).all() and (b[:, :, 3] == 255).all():
            a, b = a[:, :, :3], b[:, :, :3]      # opaque in both: as without alpha, whatever the container
        diff = np.abs(a - b)
        squares += float(np.sum(diff**2))
        samples += diff.size
        max_abs = max(max_abs, float(diff.max()))
        frame_off = diff.max(axis=2) > tolerance
        pixels_off += int(frame_off.sum())
        pixels += frame_off.size
        off = frame_off if off is None else off | frame_off
        if frame_off.any():
            frames_off.append(count)
    if not count:
        raise ValueError("no frame to compare")
    rmse = math.sqrt(squares / samples)
    return Comparison(rmse=rmse, psnr=20 * math.log10(255 / rmse) if rmse > 0 else math.inf, max_abs=max_abs,
                      pixels_off=pixels_off, pixels=pixels, tolerance=float(tolerance), off=off, frames=count,
                      frames_off=tuple(frames_off), notes=tuple(notes))


def failures(c: Comparison, max_rmse=None, min_psnr=None, max_pixels_off=None,
             tolerance_given: bool = False) -> list[str]:
    """The tolerances ``c`` breaks, one text each; empty when within tolerance.

    With no limit given the images must match within ``c.tolerance`` everywhere; so they must
    with ``tolerance_given`` (--tolerance said on the command line) and no ``max_pixels_off``,
    whatever other limits are given: the tolerance would else be ignored.
    """
    limits = max_rmse is not None or min_psnr is not None
    exact = max_pixels_off is None and (tolerance_given or not limits)
    broken = []
    if max_rmse is not None and c.rmse > max_rmse:
        broken.append(f"rmse {c.rmse:.6g} > {max_rmse:g} (--max-rmse)")
    if min_psnr is not None and c.psnr < min_psnr:
        broken.append(f"psnr {c.psnr:.6g} dB < {min_psnr:g} (--min-psnr)")
    if exact and c.pixels_off:
        why = ("--tolerance without --max-pixels-off: none may" if limits else "with no limit given, none may: "
               "--max-rmse, --min-psnr or --max-pixels-off set one")
        broken.append(f"{c.pixels_off} pixels differ by more than {c.tolerance:g} ({why})")
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

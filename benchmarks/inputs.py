"""Benchmark inputs: upscaled sample photos and masks (synthetic masks: :mod:`samples.scenes`)."""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np

#: Photo sizes (width, height) by label.
SIZES = {"1MP": (1024, 1024), "12MP": (4000, 3000)}


def make_photos(samples: Path, folder: Path) -> dict[str, tuple[Path, Path]]:
    """Upscale samples/astronaut.png and its mask to each of :data:`SIZES` in ``folder``.

    Returns
    -------
    dict
        label -> (photo path, mask path), PNG files.
    """
    photo = cv2.imread(str(samples / "astronaut.png"), cv2.IMREAD_UNCHANGED)
    if photo is None:
        raise FileNotFoundError(f"samples/astronaut.png is missing in {samples}")
    out = {}
    for label, (w, h) in SIZES.items():
        p, m = folder / f"photo-{label}.png", folder / f"mask-{label}.png"
        cv2.imwrite(str(p), cv2.resize(photo, (w, h), interpolation=cv2.INTER_CUBIC))
        upscale_mask(samples / "astronaut_mask.png", (w, h), m)
        out[label] = (p, m)
    return out


def upscale_mask(source: Path, size: tuple[int, int], path: Path) -> Path:
    """Write the mask ``source`` resized to ``size`` (width, height), thresholded at 128, to ``path``."""
    mask = cv2.imread(str(source), cv2.IMREAD_GRAYSCALE)
    if mask is None:
        raise FileNotFoundError(f"{source} is missing")
    big = cv2.resize(mask, size, interpolation=cv2.INTER_LINEAR)
    cv2.imwrite(str(path), np.where(big >= 128, 255, 0).astype(np.uint8))
    return path

"""How far the shapes of a synthetic scene (:mod:`samples.scenes`) came out from a disc or a square."""

from __future__ import annotations

import cv2
import numpy as np
from samples.scenes import SHAPES

def shape_region(image, colour, tolerance=80):
    """Largest connected blob of pixels close to ``colour``: its contour."""
    bgr = image[:, :, :3].astype(np.int32)
    close = (np.abs(bgr - np.array(colour)).max(axis=2) < tolerance).astype(np.uint8)
    if image.shape[2] == 4:
        close &= (image[:, :, 3] > 128).astype(np.uint8)
    contours, _ = cv2.findContours(close, cv2.RETR_EXTERNAL, cv2.CHAIN_APPROX_NONE)
    return max(contours, key=cv2.contourArea)


def soft_region(image, colour):
    """Per-pixel fraction of ``colour`` (against the local background) around the shape.

    Returns
    -------
    fraction : (h, w) float ndarray
        1 inside, 0 outside, partial on anti-aliased edges (alpha included).
    origin : (x0, y0)
        Position of the patch in the image.
    contour : ndarray
        The thresholded blob's contour (image coordinates).
    """
    contour = shape_region(image, colour)
    x, y, w, h = cv2.boundingRect(contour)
    x0, y0 = max(x - 3, 0), max(y - 3, 0)
    patch = image[y0 : y + h + 3, x0 : x + w + 3].astype(np.float64)
    inside = np.zeros(patch.shape[:2], np.uint8)
    cv2.drawContours(inside, [contour - [x0, y0]], -1, 1, -1)
    ring = cv2.dilate(inside, np.ones((7, 7), np.uint8)) - cv2.dilate(inside, np.ones((3, 3), np.uint8))
    background = patch[:, :, :3][ring > 0].mean(axis=0)
    direction = np.asarray(colour, np.float64) - background
    fraction = np.clip(((patch[:, :, :3] - background) @ direction) / (direction @ direction), 0.0, 1.0)
    if patch.shape[2] == 4:
        fraction *= patch[:, :, 3] / 255.0
    fraction[cv2.dilate(inside, np.ones((5, 5), np.uint8)) == 0] = 0.0
    return fraction, (x0, y0), contour


def distortion(image, kind, colour):
    """How far a shape is from a disc or a square (0: perfect).

    Disc: fitted-ellipse axis ratio - 1. Square: min-area-rect defect, measured
    sub-pixel: in the frame of the minimal rectangle, side lengths come from the
    soft second moments (a rectangle a x b has variance a^2/12, b^2/12); the
    defect is the largest of a/b - 1, |1 - area / (a b)| and the anisotropy of
    the second moments (sqrt of their eigenvalue ratio - 1, zero for a square at
    any rotation and first-order in any shear or stretch).
    """
    if kind == "disc":
        (_, _), (a, b), _ = cv2.fitEllipse(shape_region(image, colour))
        return float(max(a, b) / min(a, b) - 1.0)
    fraction, _, contour = soft_region(image, colour)
    (_, _), _, angle = cv2.minAreaRect(contour)
    ys, xs = np.nonzero(fraction)
    wts = fraction[ys, xs]
    total = wts.sum()
    xs, ys = xs - (wts * xs).sum() / total, ys - (wts * ys).sum() / total
    t = np.radians(angle)
    u, v = xs * np.cos(t) + ys * np.sin(t), -xs * np.sin(t) + ys * np.cos(t)
    a = np.sqrt(12.0 * (wts * u * u).sum() / total)
    b = np.sqrt(12.0 * (wts * v * v).sum() / total)
    cov = np.cov(np.stack([xs, ys]), aweights=wts)
    low, high = np.linalg.eigvalsh(cov)
    anisotropy = np.sqrt(high / low) - 1.0
    return float(max(max(a, b) / min(a, b) - 1.0, abs(1.0 - total / (a * b)), anisotropy))


def area(image, colour):
    """Sub-pixel area in pixels of the shape of ``colour``."""
    return float(soft_region(image, colour)[0].sum())


def distortions(image, shapes=SHAPES):
    """Distortion of every shape, in the order of ``shapes``."""
    return [distortion(image, kind, colour) for kind, _, _, _, colour in shapes]

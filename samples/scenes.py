"""Synthetic scenes: solid discs and squares on a gray texture, and their feature mask.

The one generator of synthetic inputs, shared by the tests (``from samples.scenes
import scene``), the samples (``make_masks.py`` writes ``shapes.png`` and
``shapes_mask.png`` from :func:`sample_scene`) and the benchmarks
(:func:`disc_mask`). A shape is ``(kind, centre x, centre y, size, BGR colour)``
with kind ``"disc"`` (size: radius) or ``"square"`` (size: half its side; the
square covers ``centre +- size`` pixels, both ends included). Needs only numpy and
OpenCV; the same call always gives the same pixels.

Examples
--------
>>> image, mask = scene((("disc", 20, 15, 6, (0, 0, 255)),), (40, 30))
>>> image.shape, mask.shape, bool(mask[15, 20]), bool(mask[0, 0])
((30, 40, 3), (30, 40), True, False)
"""

from __future__ import annotations

import cv2
import numpy as np

#: The tests' scene: three discs and three squares, two rows, 500 x 360.
SHAPES = (
    ("disc", 110, 100, 30, (0, 0, 255)),
    ("square", 250, 100, 27, (0, 200, 0)),
    ("disc", 390, 100, 30, (255, 0, 0)),
    ("square", 110, 260, 27, (0, 255, 255)),
    ("disc", 250, 260, 30, (255, 0, 255)),
    ("square", 390, 260, 27, (255, 255, 0)),
)
SIZE = (500, 360)

#: samples/shapes.png: the same layout, larger, 640 x 480, on a noisy checker.
SAMPLE_SHAPES = (
    ("disc", 130, 140, 40, (0, 0, 255)),        # red
    ("square", 320, 140, 36, (0, 200, 0)),      # green, side 73
    ("disc", 510, 140, 46, (255, 0, 0)),        # blue
    ("square", 130, 340, 44, (0, 230, 255)),    # yellow, side 89
    ("disc", 320, 340, 50, (255, 0, 255)),      # magenta
    ("square", 510, 340, 40, (255, 255, 0)),    # cyan, side 81
)
SAMPLE_SIZE = (640, 480)


def ripples(width: int, height: int) -> np.ndarray:
    """A smooth gray texture around 128 (no flat area, no noise): (height, width) float ndarray."""
    y, x = np.mgrid[0:height, 0:width]
    return 128 + 30 * np.sin(x / 3.0) * np.cos(y / 4.0) + 10 * np.sin((x + 2 * y) / 7.0)


def noisy_checker(width: int, height: int, seed: int = 0) -> np.ndarray:
    """A 16 px sine checker with Gaussian noise (sigma 6), clipped to 90..166: (height, width) uint8."""
    y, x = np.mgrid[0:height, 0:width].astype(np.float32)
    noise = np.random.default_rng(seed).normal(0, 6, (height, width))
    gray = 128 + 22 * np.sin(2 * np.pi * x / 16) * np.sin(2 * np.pi * y / 16) + noise
    return np.clip(gray, 90, 166).astype(np.uint8)


def scene(shapes=SHAPES, size=SIZE, dilate: int = 6, background=None, antialias: bool = True):
    """Solid ``shapes`` on a gray ``background``, and the feature mask: the shapes dilated.

    Parameters
    ----------
    shapes : sequence of (kind, cx, cy, size, colour)
        See the module docstring.
    size : (int, int)
        (width, height) of the scene.
    dilate : int
        The mask reaches this many pixels beyond each shape (an elliptic kernel).
    background : (height, width) ndarray, optional
        Gray levels under the shapes; default :func:`ripples`.
    antialias : bool
        Draw the discs' edges antialiased in the image (the mask never is).

    Returns
    -------
    image : (height, width, 3) uint8 ndarray
    mask : (height, width) bool ndarray
    """
    width, height = size
    gray = ripples(width, height) if background is None else background
    image = np.repeat(np.asarray(gray)[:, :, None], 3, axis=2).astype(np.uint8)
    shapes_mask = np.zeros((height, width), np.uint8)
    line = cv2.LINE_AA if antialias else cv2.LINE_8
    for kind, cx, cy, s, colour in shapes:
        if kind == "disc":
            cv2.circle(image, (cx, cy), s, colour, -1, line)
            cv2.circle(shapes_mask, (cx, cy), s, 255, -1)
        elif kind == "square":
            cv2.rectangle(image, (cx - s, cy - s), (cx + s, cy + s), colour, -1)
            cv2.rectangle(shapes_mask, (cx - s, cy - s), (cx + s, cy + s), 255, -1)
        else:
            raise ValueError(f"unknown shape {kind!r} (disc or square)")
    kernel = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (2 * dilate + 1, 2 * dilate + 1))
    return image, cv2.dilate(shapes_mask, kernel) > 0


def sample_scene(seed: int = 0):
    """samples/shapes.png and its mask: :data:`SAMPLE_SHAPES` on :func:`noisy_checker`, hard edges."""
    width, height = SAMPLE_SIZE
    return scene(SAMPLE_SHAPES, SAMPLE_SIZE, background=noisy_checker(width, height, seed), antialias=False)


def disc_mask(width: int, height: int, fraction: float = 0.2, seed: int = 1) -> np.ndarray:
    """Random discs (radius 9 % of the short side) until they cover ``fraction`` of the image.

    Returns
    -------
    (height, width) bool ndarray
    """
    rng = np.random.default_rng(seed)
    mask = np.zeros((height, width), np.uint8)
    radius = max(1, int(0.09 * min(width, height)))
    for _ in range(10_000):
        if mask.mean() >= fraction:
            break
        cx = rng.uniform(radius, max(radius + 1, width - radius))
        cy = rng.uniform(radius, max(radius + 1, height - radius))
        cv2.circle(mask, (int(cx), int(cy)), radius, 1, -1)
    return mask.astype(bool)

"""Before/after panel of the renderer's antialiasing (benchmarks/results/aa_before_after.png).

Rows: a zone plate shrunk to 0.35, a one-pixel checkerboard shrunk to 0.45 in x,
the astronaut pinched (bulge -0.8), and the silhouette of an arc of 120 degrees
on a transparent canvas (enlarged 4x, shown over gray). Left: plain sampling
(``antialias=False``, the old renderer's output); right: antialiased.

Usage::

    .venv/bin/python benchmarks/aa_panel.py [OUTPUT.png]
"""

from __future__ import annotations

import sys
from pathlib import Path

import cv2
import numpy as np

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

from featurewarp_cli.render import raster as render  # noqa: E402
from featurewarp_cli.engine.warper import load_warp  # noqa: E402
from featurewarp_cli.engine.grid import Grid  # noqa: E402


def warped(image, preset, **params):
    h, w = image.shape[:2]
    grid = Grid.for_image(w, h, 4)
    warp = load_warp(preset)(w, h, **params)
    mesh = (grid.nodes(), warp(grid.nodes()), grid.triangles(), tuple(warp.canvas))
    return (render.render(image, *mesh, "cubic", None, antialias=False),
            render.render(image, *mesh, "cubic", None, antialias=True))


def on_gray(image):
    if image.ndim == 3 and image.shape[2] == 4:
        alpha = image[:, :, 3:4].astype(np.float32) / 255.0
        return (image[:, :, :3] * alpha + 128 * (1 - alpha)).astype(np.uint8)
    return image


def fit(image, height):
    image = on_gray(image)
    scale = height / image.shape[0]
    return cv2.resize(image, (max(1, round(image.shape[1] * scale)), height), interpolation=cv2.INTER_NEAREST)


def main(argv=None):
    argv = sys.argv[1:] if argv is None else argv
    out = Path(argv[0]) if argv else ROOT / "benchmarks" / "results" / "aa_before_after.png"
    y, x = np.mgrid[0:400, 0:400]
    zone = (127.5 + 127.5 * np.cos(((x - 200) ** 2 + (y - 200) ** 2) * np.pi / 400.0)).astype(np.uint8)
    board = ((np.add.outer(np.arange(200), np.arange(400)) % 2) * 255).astype(np.uint8)
    astronaut = cv2.imread(str(ROOT / "samples" / "astronaut.png"))
    rows = [warped(cv2.merge([zone] * 3), "stretch", sx=0.35, sy=0.35),
            warped(cv2.merge([board] * 3), "stretch", sx=0.45, sy=1.0),
            warped(astronaut, "bulge", strength=-0.8)]
    before, after = warped(astronaut, "arc", angle=120)
    crop = (slice(300, 420), slice(0, 200))
    rows.append(tuple(cv2.resize(on_gray(im[crop]), None, fx=4, fy=4, interpolation=cv2.INTER_NEAREST)
                      for im in (before, after)))
    panel_rows = []
    for left, right in rows:
        h = 360
        gap = np.full((h, 12, 3), 255, np.uint8)
        panel_rows.append(np.hstack([fit(left, h), gap, fit(right, h)]))
    width = max(r.shape[1] for r in panel_rows)
    panel = np.vstack([np.pad(r, ((0, 12), (0, width - r.shape[1]), (0, 0)), constant_values=255)
                       for r in panel_rows])
    cv2.putText(panel, "plain sampling", (10, 30), cv2.FONT_HERSHEY_SIMPLEX, 0.9, (0, 0, 255), 2)
    cv2.putText(panel, "antialiased", (panel_rows[0].shape[1] // 2 + 16, 30), cv2.FONT_HERSHEY_SIMPLEX, 0.9,
                (0, 0, 255), 2)
    out.parent.mkdir(parents=True, exist_ok=True)
    cv2.imwrite(str(out), panel)
    print(out)


if __name__ == "__main__":
    main()

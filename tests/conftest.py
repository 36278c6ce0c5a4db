"""Shared fixtures: small synthetic images and masks, built in memory (no files)."""

from __future__ import annotations

import os
import sys

from featurewarp_cli import blas

blas.one_thread()                       # as the command runs, before numpy loads OpenBLAS

import cv2  # noqa: E402
import numpy as np  # noqa: E402
import pytest  # noqa: E402

sys.path.insert(0, os.path.dirname(__file__))
sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))   # samples.scenes

from samples.scenes import scene  # noqa: E402

#: Two shapes well inside a 200 x 150 image (at least 2 cells from the border).
SMALL_SHAPES = (
    ("disc", 60, 60, 20, (0, 0, 255)),
    ("square", 140, 90, 15, (0, 255, 0)),
)
SMALL_SIZE = (200, 150)


@pytest.fixture
def rng():
    """A seeded random generator: every test run draws the same numbers."""
    return np.random.default_rng(20240607)


@pytest.fixture(scope="session")
def small_scene():
    """(image, mask): 200 x 150 BGR uint8 textured scene with a disc and a square."""
    image, mask = scene(SMALL_SHAPES, SMALL_SIZE)
    image.flags.writeable = False
    mask.flags.writeable = False
    return image, mask


@pytest.fixture(scope="session")
def textured_bgr():
    """A 160 x 120 BGR uint8 image with texture in all three channels (no flat areas)."""
    y, x = np.mgrid[0:120, 0:160]
    b = 128 + 60 * np.sin(x / 5.0) * np.cos(y / 7.0)
    g = 128 + 50 * np.cos((x + y) / 9.0)
    r = 40 + x * 1.2
    image = np.clip(np.dstack([b, g, r]), 0, 255).astype(np.uint8)
    image.flags.writeable = False
    return image


@pytest.fixture(scope="session")
def blob_mask():
    """A 160 x 120 mask with two random-looking blobs away from the border."""
    mask = np.zeros((120, 160), np.uint8)
    cv2.circle(mask, (55, 50), 18, 1, -1)
    cv2.ellipse(mask, (112, 78), (24, 11), 30, 0, 360, 1, -1)
    pts = np.array([[30, 85], [48, 78], [52, 100], [38, 104]], np.int32)
    cv2.fillPoly(mask, [pts], 1)
    return mask > 0


@pytest.fixture(scope="session")
def random_mask():
    """A 160 x 120 mask of random blobs (seeded): smoothed noise above a threshold, border cleared."""
    noise = np.random.default_rng(7).normal(size=(120, 160)).astype(np.float32)
    smooth = cv2.GaussianBlur(noise, (0, 0), 6)
    mask = smooth > np.quantile(smooth, 0.85)
    mask[:8], mask[-8:], mask[:, :8], mask[:, -8:] = False, False, False, False
    return mask


@pytest.fixture(scope="session")
def border_mask():
    """A 160 x 120 mask whose two features touch the image border (top-left, bottom-right)."""
    mask = np.zeros((120, 160), bool)
    mask[0:40, 0:30] = True
    mask[90:, 125:] = True
    mask[50:70, 70:90] = True          # and one inside
    return mask


@pytest.fixture(autouse=True)
def every_report_validates(monkeypatch, request):
    """Every report a test makes is checked against the shipped JSON Schema: in this process as
    it is built, and those other processes wrote into the test's ``tmp_path`` when it ends."""
    import json

    from featurewarp_cli import schema
    from featurewarp_cli.app import report

    validator = schema.validator("report")
    build = report.build_report

    def checked(*args, **kwargs):
        made = build(*args, **kwargs)
        validator.validate(json.loads(json.dumps(made)))
        return made

    monkeypatch.setattr(report, "build_report", checked)
    folder = request.getfixturevalue("tmp_path") if "tmp_path" in request.fixturenames else None
    yield
    if folder is not None and folder.is_dir():
        for path in folder.rglob("*.json"):
            try:
                made = json.loads(path.read_text())
            except (ValueError, UnicodeDecodeError, OSError):
                continue
            if isinstance(made, dict) and str(made.get("schema", "")).startswith("featurewarp-report/"):
                validator.validate(made)

"""Masks as people make them: a coloured brush, a 16-bit file, a layer on transparency, an
inverted mask. What the tool says must match what the mask marks."""

from __future__ import annotations

import json

import cv2
import numpy as np

from test_cli import SIZE, runner, save, textured  # noqa: F401  (runner: a fixture)


def _warp(runner, tmp_path, mask: np.ndarray, preset=("stretch", "--sx", "1.5")):
    image = save(tmp_path / "in.png", textured())
    path = str(tmp_path / "m.png")
    assert cv2.imwrite(path, mask)
    run = runner("warp", preset[0], image, tmp_path / "out.png", "-m", path, *preset[1:],
                 "--report", tmp_path / "r.json")
    assert run.code == 0, run.stderr
    return run, json.loads((tmp_path / "r.json").read_text())


def test_a_red_brush_beside_a_white_one_is_said_not_dropped_in_silence(runner, tmp_path):
    """Strokes of a red brush (gray 76) marked nothing while the white ones marked features: the
    red feature was warped as background and the report read every feature kept, in silence."""
    w, h = SIZE
    mask = np.zeros((h, w, 3), np.uint8)
    mask[10:24, 4:18] = 255                     # white: a feature
    mask[10:24, 28:42] = (0, 0, 255)            # pure red (BGR): gray 76, no feature
    run, report = _warp(runner, tmp_path, mask)
    said = [line for line in report["warnings"] if "painted in a colour" in line]
    assert len(said) == 1 and said[0].startswith("196 pixels") and "painted in a colour" in run.stderr


def test_an_empty_mask_says_what_it_holds_at_16_bits_and_on_transparency(runner, tmp_path):
    """A 16-bit mask holding 0 and 255 was told 'its brightest pixel is 0'; black strokes on a
    transparent layer were told the same, with no word of the alpha that holds the strokes."""
    w, h = SIZE
    sixteen = np.zeros((h, w), np.uint16)
    sixteen[10:24, 10:30] = 255
    run, report = _warp(runner, tmp_path, sixteen)
    assert "brightest pixel is 255 of 65535" in run.stderr and report["mode"] == "plain"
    layer = np.zeros((h, w, 4), np.uint8)
    layer[10:24, 10:30, 3] = 255                # black, opaque strokes; the rest transparent
    run, _ = _warp(runner, tmp_path, layer)
    assert "its opaque pixels are dark, and its transparent ones count as black" in run.stderr


def test_an_inverted_mask_is_named_as_possibly_inverted(runner, tmp_path):
    """A mask of the background (white all round, the subject black) was told only that a feature
    'cut by a border' gave way; nothing hinted that the mask is the wrong way round. A notice asks
    (a question, not a compromise of the result: not in the report's warnings, --strict passes)."""
    w, h = SIZE
    mask = np.full((h, w), 255, np.uint8)
    mask[10:26, 14:34] = 0
    run, report = _warp(runner, tmp_path, mask)
    asked = [line for line in run.lines if "is it inverted?" in line]
    assert len(asked) == 1 and asked[0].startswith(f"featurewarp: notice: {tmp_path / 'm.png'}: the mask marks")
    assert not any("inverted" in line for line in report["warnings"])
    upright = 255 - mask
    run, report = _warp(runner, tmp_path, upright)
    assert "inverted" not in run.stderr

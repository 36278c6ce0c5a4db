"""``featurewarp diff``: metrics, tolerances, exit codes and the highlighted difference picture."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest

from featurewarp_cli.app import diff
from featurewarp_cli.io import decode
from test_cli import runner, save, textured  # noqa: F401  (fixture)


@pytest.fixture
def pair(tmp_path):
    """Two 48x36 images that differ by 10 in the blue channel of 12 pixels."""
    a = textured()
    b = a.copy()
    patch = a[:3, :4, 0].astype(int)
    b[:3, :4, 0] = np.where(patch < 128, patch + 10, patch - 10)
    return save(tmp_path / "a.png", a), save(tmp_path / "b.png", b)


def metrics(run) -> dict:
    return {line.split()[0]: line.split()[1] for line in run.stdout.decode().splitlines()}


def test_identical_images(runner, pair):
    run = runner("diff", pair[0], pair[0])
    assert run.code == 0 and run.stderr == ""
    assert metrics(run) == {"rmse": "0", "psnr": "inf", "max_abs_diff": "0", "pixels_off": "0"}


def test_different_images_fail_by_default(runner, pair):
    run = runner("diff", *pair)
    assert run.code == 1 and len(run.lines) == 1 and "differ beyond tolerance" in run.stderr
    assert "with no limit given, none may" in run.stderr and "allowed (--max-pixels-off)" not in run.stderr
    m = metrics(run)
    assert m["max_abs_diff"] == "10" and m["pixels_off"] == "12"
    assert float(m["rmse"]) == pytest.approx(math.sqrt(12 * 100 / (48 * 36 * 3)), rel=1e-5)


@pytest.mark.parametrize("options, code", [
    (["--max-rmse", "1"], 0), (["--max-rmse", "0.1"], 1),
    (["--min-psnr", "40"], 0), (["--min-psnr", "60"], 1),
    (["--max-pixels-off", "12"], 0), (["--max-pixels-off", "11"], 1),
    (["--tolerance", "10"], 0), (["--tolerance", "9.5"], 1),
    (["--max-pixels-off", "0", "--tolerance", "10"], 0),
    (["--max-rmse", "1", "--min-psnr", "60"], 1),
])
def test_tolerances(runner, pair, options, code):
    run = runner("diff", *pair, *options)
    assert run.code == code, run.stderr
    assert len(run.stdout.splitlines()) == 4


def test_alpha_counts(runner, tmp_path):
    a = np.dstack([textured(), np.full((36, 48), 255, np.uint8)])
    b = a.copy()
    b[5, 5, 3] = 0
    run = runner("diff", save(tmp_path / "a.png", a), save(tmp_path / "b.png", b))
    assert run.code == 1 and metrics(run)["pixels_off"] == "1" and metrics(run)["max_abs_diff"] == "255"


def test_sixteen_bit_is_normalised(runner, tmp_path):
    eight = textured()
    sixteen = eight.astype(np.uint16) * 257
    run = runner("diff", save(tmp_path / "a.png", eight), save(tmp_path / "b.png", sixteen))
    assert run.code == 0 and metrics(run)["rmse"] == "0"


@pytest.mark.parametrize("other, reason", [
    (np.zeros((36, 47, 3), np.uint8), "sizes differ: 48x36 vs 47x36"),
    (np.zeros((36, 48), np.uint8), "channel counts differ: 3 vs 1"),
    (np.zeros((36, 48, 4), np.uint8), "channel counts differ: 3 vs 4"),
])
def test_incomparable_images(runner, tmp_path, other, reason):
    run = runner("diff", save(tmp_path / "a.png", textured()), save(tmp_path / "b.png", other),
                 "--max-rmse", "1000", "--diff-image", tmp_path / "d.png")
    assert run.code == 1 and len(run.lines) == 1 and reason in run.stderr and run.stdout == b""
    assert not (tmp_path / "d.png").exists() and "d.png not written" in run.stderr
    run = runner("diff", tmp_path / "a.png", tmp_path / "b.png", "--json")     # CI parses the failure too
    figures = json.loads(run.stdout)
    assert run.code == 1 and figures["within"] is False and figures["rmse"] is None
    assert figures["failures"] == [f"cannot be compared: {reason}"]


def test_diff_image(runner, pair, tmp_path):
    run = runner("diff", *pair, "--diff-image", tmp_path / "d.png", "--quiet")
    assert run.code == 1 and run.stdout == b""
    picture = decode.read_image(str(tmp_path / "d.png"))
    red = (picture == (0, 0, 255)).all(axis=2)
    assert picture.shape == (36, 48, 3) and red.sum() == 12 and red[:3, :4].all()
    gray = picture[~red]
    assert (gray[:, 0] == gray[:, 1]).all() and (gray[:, 1] == gray[:, 2]).all() and gray.min() >= 128


def test_stdin_and_errors(runner, pair, tmp_path):
    run = runner("diff", "-", pair[0], input=Path(pair[0]).read_bytes())
    assert run.code == 0
    assert runner("diff", "-", "-").code == 2
    missing = runner("diff", pair[0], tmp_path / "nope.png")
    assert missing.code == 2 and "nope.png does not exist" in missing.stderr
    (tmp_path / "junk.png").write_bytes(b"junk")
    junk = runner("diff", pair[0], tmp_path / "junk.png")
    assert junk.code == 1 and "cannot be decoded" in junk.stderr and len(junk.lines) == 1
    assert runner("diff", *pair, "--diff-image", tmp_path / "d.xyz").code == 2
    assert runner("diff", *pair, "--max-rmse", "nan").code == 2


def test_compare_unit():
    a = np.zeros((2, 2), np.uint8)
    b = a.copy()
    b[0, 0] = 10
    c = diff.compare(a, b)
    assert (c.rmse, c.max_abs, c.pixels_off, c.pixels) == (5.0, 10.0, 1, 4)
    assert c.psnr == pytest.approx(20 * math.log10(255 / 5))
    assert diff.failures(c) and not diff.failures(c, max_rmse=5)
    with pytest.raises(ValueError, match="sizes differ"):
        diff.compare(a, np.zeros((3, 2), np.uint8))

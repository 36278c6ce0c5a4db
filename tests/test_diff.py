"""``featurewarp diff``: metrics, tolerances, exit codes and the highlighted difference picture."""

from __future__ import annotations

import json
import math
import subprocess
import sys
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


def test_a_tolerance_above_255_is_refused_every_sample_would_pass(runner, pair):
    """--tolerance is on the 0..255 scale (16-bit samples scaled to it): above 255 nothing could
    differ, so a CI job's typo (3000 for 30) is a usage error, not a silent pass."""
    run = runner("diff", *pair, "--tolerance", "300")
    assert run.code == 2 and len(run.lines) == 1 and "0 <= T <= 255" in run.stderr
    assert runner("diff", *pair, "--tolerance", "255").code == 0


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
    (np.zeros((36, 47), np.uint8), "sizes differ: 48x36 vs 47x36"),
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


def test_quiet_prints_nothing_but_trouble(runner, tmp_path):
    """``-q`` printed a note (A without alpha against B with it) and the "differ" line; as
    ``cmp -s``, it says nothing but trouble (exit 2), and the exit status is the same."""
    image = textured()
    opaque = save(tmp_path / "a.png", image)
    cut = np.dstack([image, np.full(image.shape[:2], 255, np.uint8)])
    cut[:10, :, 3] = 0
    pairs = {1: (opaque, save(tmp_path / "b.png", cut)), 0: (opaque, opaque)}
    pairs[-1] = (opaque, save(tmp_path / "c.png", image[:20]))       # sizes differ: cannot be compared
    for code, pair in pairs.items():
        loud = runner("diff", *pair)
        for flags in (["-q"], ["--quiet", "--json"]):
            run = runner("diff", *pair, *flags)
            assert run.code == loud.code == abs(code) and run.stderr == "" and run.stdout == b"", run.stderr
    assert "note: A is colour without alpha" in runner("diff", *pairs[1]).stderr
    missing = runner("diff", opaque, tmp_path / "none.png", "-q")
    assert missing.code == 2 and "does not exist" in missing.stderr


def test_stdin_and_errors(runner, pair, tmp_path):
    run = runner("diff", "-", pair[0], input=Path(pair[0]).read_bytes())
    assert run.code == 0
    assert runner("diff", "-", "-").code == 2
    missing = runner("diff", pair[0], tmp_path / "nope.png")
    assert missing.code == 2 and "nope.png does not exist" in missing.stderr
    (tmp_path / "junk.png").write_bytes(b"junk")
    junk = runner("diff", pair[0], tmp_path / "junk.png")
    assert junk.code == 2 and "cannot be decoded" in junk.stderr and len(junk.lines) == 1    # trouble, not "differ"
    full = runner("diff", *pair[:1], pair[0], "--diff-image", "png:/dev/full")
    assert full.code == 2 and full.lines[-1] == "featurewarp: error: cannot write /dev/full: No space left on device"
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


def frames_file(path, frames, durations=None, **options):
    """Save BGR frames as an animation or multi-page file by Pillow (format from the extension)."""
    from PIL import Image

    images = [Image.fromarray(np.ascontiguousarray(f[:, :, ::-1])) for f in frames]
    if durations:
        options["duration"] = durations
    images[0].save(path, save_all=True, append_images=images[1:], **options)
    return str(path)


@pytest.mark.parametrize("ext, options", [(".png", {}), (".webp", {"lossless": True}), (".tif", {}),
                                          (".gif", {})])
def test_every_frame_is_compared(runner, tmp_path, ext, options):
    """Finding 1: frames after the first count, and so does the frame count."""
    one, two, three = textured(), np.ascontiguousarray(textured()[::-1]), np.ascontiguousarray(textured()[:, ::-1])
    changed = three.copy()
    changed[:6, :6] = 255 - changed[:6, :6]
    a = frames_file(tmp_path / f"a{ext}", [one, two, three], **options)
    b = frames_file(tmp_path / f"b{ext}", [one, two, changed], **options)
    same = runner("diff", a, frames_file(tmp_path / f"c{ext}", [one, two, three], **options))
    assert same.code == 0 and "frames 3 (off: none)" in same.stdout.decode()
    run = runner("diff", a, b, "--max-rmse", "0.5", "--json")
    figures = json.loads(run.stdout)
    assert run.code == 1 and figures["frames"] == 3 and figures["frames_off"] == [3]
    assert figures["pixels"] == 3 * 48 * 36
    assert figures["pixels_off"] == 36 or ext == ".gif" and figures["pixels_off"] >= 36    # GIF: a new palette
    shorter = runner("diff", a, frames_file(tmp_path / f"d{ext}", [one, two], **options))
    assert shorter.code == 1 and "frame counts differ: 3 vs 2" in shorter.stderr
    still = runner("diff", a, save(tmp_path / "still.png", one))
    assert still.code == 1 and "frame counts differ: 3 vs 1" in still.stderr


@pytest.mark.parametrize("ext", [".png", ".webp"])
def test_frame_durations_count(runner, tmp_path, ext):
    """WebP's durations are set only once a frame is loaded: they were never compared (review)."""
    frames = [textured(), np.ascontiguousarray(textured()[::-1])]
    a = frames_file(tmp_path / f"a{ext}", frames, [100, 100], lossless=True)
    b = frames_file(tmp_path / f"b{ext}", frames, [100, 250], lossless=True)
    run = runner("diff", a, b, "--max-rmse", "1")
    assert run.code == 1 and "frame 2 is shown for 100 ms vs 250 ms" in run.stderr
    same = runner("diff", a, frames_file(tmp_path / f"c{ext}", frames, [100, 100], lossless=True))
    assert same.code == 0


def test_an_animation_s_rmse_does_not_depend_on_its_container(runner, tmp_path):
    """Opaque APNG frames were read as BGRA, TIFF pages as BGR: the same change read RMSE 1.70
    against 1.97 (review)."""
    frames = [textured(), np.ascontiguousarray(textured()[::-1])]
    changed = [frames[0], frames[1].copy()]
    changed[1][:3, :3] = 255 - changed[1][:3, :3]
    rmse = [metrics(runner("diff", frames_file(tmp_path / f"a{ext}", frames, [100, 100]),
                           frames_file(tmp_path / f"b{ext}", changed, [100, 100]), "--max-rmse", "100"))["rmse"]
            for ext in (".png", ".tif")]
    assert rmse[0] == rmse[1]


@pytest.mark.parametrize("layout", ["gray as rgb", "opaque alpha", "gray as rgba"])
def test_channel_layouts_compared_by_meaning(runner, tmp_path, layout):
    """Finding 3: a golden re-saved with another channel layout and the same pixels passes."""
    gray = textured(channels=1)
    colour = {"gray as rgb": np.dstack([gray] * 3), "opaque alpha": None,
              "gray as rgba": np.dstack([gray] * 3 + [np.full_like(gray, 255)])}[layout]
    if layout == "opaque alpha":
        gray = textured()
        colour = np.dstack([gray, np.full(gray.shape[:2], 255, np.uint8)])
    a, b = save(tmp_path / "a.png", gray), save(tmp_path / "b.png", colour)
    run = runner("diff", a, b)
    assert run.code == 0 and metrics(run)["rmse"] == "0"
    assert "featurewarp: note: A is " in run.stderr and "compared as" in run.stderr
    off = colour.copy()
    off[0, 0, 1] ^= 1             # a colour in the RGB file that the gray one cannot have
    if layout == "opaque alpha":
        off[1, 1, 3] = 254         # or an alpha that is not opaque
    run = runner("diff", a, save(tmp_path / "c.png", off))
    assert run.code == 1 and int(metrics(run)["pixels_off"]) >= 1


def test_colour_under_transparent_pixels_not_compared(runner, tmp_path):
    """Finding 2: encoders differ in the colour they keep where alpha is 0; no one sees it."""
    a = np.dstack([textured(), np.full((36, 48), 255, np.uint8)])
    a[:10, :, 3] = 0
    b = a.copy()
    a[:10, :, :3] = 0
    assert runner("diff", save(tmp_path / "a.png", a), save(tmp_path / "b.png", b)).code == 0
    b[10, 0, 3] = 0               # a pixel made transparent does count
    assert runner("diff", tmp_path / "a.png", save(tmp_path / "b.png", b)).code == 1


def test_colour_under_faint_alpha_counts_as_it_shows(runner, tmp_path):
    """Colour is compared premultiplied: under alpha 2 of 255 a colour 255 apart shows 2 apart
    over any background. Compared straight it counted 255, and a 16-bit output's 8-bit twin
    (whose colour under faint alpha is its rounding) failed --max-rmse 0.5 on four edge pixels."""
    a = np.dstack([textured(), np.full((36, 48), 255, np.uint8)])
    a[:, :3, 3] = 2
    b = a.copy()
    b[:, :3, :3] = 255 - a[:, :3, :3]
    run = runner("diff", save(tmp_path / "a.png", a), save(tmp_path / "b.png", b), "--max-rmse", "0.5")
    assert run.code == 0 and 1.0 < float(metrics(run)["max_abs_diff"]) <= 2.0, run.stdout
    b[:, :3, 3] = 200                       # the alpha itself counts in full, and the colour shows
    run = runner("diff", tmp_path / "a.png", save(tmp_path / "b.png", b), "--max-rmse", "0.5")
    assert run.code == 1 and float(metrics(run)["max_abs_diff"]) >= 198


def test_tolerance_with_a_limit_is_kept(runner, pair):
    """Finding 4: --tolerance with --max-rmse means no sample off by more than it."""
    run = runner("diff", *pair, "--max-rmse", "5", "--tolerance", "1")
    assert run.code == 1 and "--tolerance without --max-pixels-off: none may" in run.stderr
    assert runner("diff", *pair, "--max-rmse", "5", "--tolerance", "10").code == 0
    assert runner("diff", *pair, "--max-rmse", "5").code == 0
    assert runner("diff", *pair, "--max-rmse", "5", "--tolerance", "1", "--max-pixels-off", "12").code == 0


def test_diff_image_cannot_be_stdout(runner, pair, tmp_path):
    """Finding 7: the picture would land in the metrics."""
    unknown = runner("diff", *pair, "--diff-image", tmp_path / "d.txt")      # diff has no --format to suggest
    assert unknown.code == 2 and unknown.stderr.rstrip().endswith(f"or a prefix: png:{tmp_path / 'd.txt'}")
    for alias in ("png:/dev/stdout", "png:/dev/fd/1", "png:-"):       # png:- put the PNG after the metrics
        run = runner("diff", *pair, "--diff-image", alias)
        assert run.code == 2 and "is stdout, which holds the metrics" in run.stderr and b"PNG" not in run.stdout
    out = tmp_path / "out.txt"
    with open(out, "wb") as stdout:         # the real command, its stdout a file named again
        code = subprocess.run([sys.executable, "-m", "featurewarp_cli", "diff", *pair, "--diff-image",
                               f"png:{out}"], stdout=stdout, stderr=subprocess.PIPE, timeout=60).returncode
    assert code == 2 and b"PNG" not in out.read_bytes()
    quiet = subprocess.run([sys.executable, "-m", "featurewarp_cli", "diff", *pair, "-q", "--diff-image",
                            "png:/dev/stdout"], capture_output=True, timeout=60)
    assert quiet.returncode == 1 and quiet.stdout.startswith(b"\x89PNG")     # -q: stdout holds only it
    assert runner("diff", *pair, "--diff-image", "/dev/null").code == 1     # no extension needed there


def test_multi_page_tiff_with_soft_alpha_is_read_straight(runner, tmp_path):
    """libtiff's RGBA reading premultiplied the pages' 8-bit alpha: an APNG and the same frames
    as a multi-page TIFF differed in every soft edge pixel ([127, 127, 127, a=6] read [3, 3, 3];
    smoke trial 1). Still TIFFs were already read straight."""
    from PIL import Image

    frames = []
    for k in range(2):
        rgba = np.dstack([textured()[:, :, ::-1], np.full(textured().shape[:2], 255, np.uint8)])
        rgba[:, : 8 + 4 * k, 3] = 6                      # soft alpha, the colour kept under it
        frames.append(Image.fromarray(np.ascontiguousarray(rgba)))
    apng, tif = str(tmp_path / "a.png"), str(tmp_path / "a.tif")
    frames[0].save(apng, save_all=True, append_images=frames[1:], duration=[100, 100])
    frames[0].save(tif, save_all=True, append_images=frames[1:])
    run = runner("diff", apng, tif)
    assert run.code == 0 and metrics(run)["rmse"] == "0"


def test_an_opaque_alpha_channel_is_left_out_of_the_metrics(runner, tmp_path):
    """The same change read RMSE 2.95 between opaque RGBA stills and 3.40 between their RGB twins
    (and 1.70 against 1.97 between RGBA and RGB TIFF pages): an alpha opaque in both says
    nothing and no longer dilutes the mean (second review, finding 6)."""
    rgb = textured()
    changed = rgb.copy()
    changed[:4, :4] = 255 - changed[:4, :4]
    opaque = np.full(rgb.shape[:2], 255, np.uint8)
    plain = metrics(runner("diff", save(tmp_path / "a.png", rgb), save(tmp_path / "b.png", changed), "--max-rmse", "99"))
    alpha = metrics(runner("diff", save(tmp_path / "c.png", np.dstack([rgb, opaque])),
                           save(tmp_path / "d.png", np.dstack([changed, opaque])), "--max-rmse", "99"))
    assert plain["rmse"] == alpha["rmse"] and float(plain["rmse"]) > 0


def test_a_closed_pipe_is_left_to_the_command_line_and_a_full_stdout_is_trouble(monkeypatch):
    """diff's figures not written are trouble (2); a reader gone away is not (main says nothing)."""
    import click

    from featurewarp_cli.cli import diff as command

    for error, expected in ((BrokenPipeError(32, "Broken pipe"), BrokenPipeError),
                            (OSError(28, "No space left on device"), click.ClickException)):
        def failing(text, error=error):
            raise error
        monkeypatch.setattr(command.click, "echo", failing)
        with pytest.raises(expected) as caught:
            command._echo("rmse 0")
        if expected is click.ClickException:
            assert caught.value.exit_code == 2 and "No space left" in caught.value.message


"""Issue 15: the one-line rule everywhere, and a seeded mutation fuzz of the decode path and of
the presets' parameters within their declared ranges."""

from __future__ import annotations

import subprocess
import sys
import time

import cv2
import numpy as np
import pytest
from click.testing import CliRunner

from featurewarp_cli import FeatureWarper, load_warp, plugins
from featurewarp_cli.cli.main import cli
from featurewarp_cli.io import ImageError, decode

CLI = [sys.executable, "-m", "featurewarp_cli"]


def picture(width: int = 48, height: int = 36) -> np.ndarray:
    y, x = np.mgrid[0:height, 0:width]
    return np.dstack([x * 5 % 256, y * 7 % 256, (x + y) * 3 % 256]).astype(np.uint8)


def encoded(fmt: str) -> bytes:
    ok, data = cv2.imencode("." + fmt, picture())
    assert ok
    return data.tobytes()


def mutations(data: bytes, rng: np.random.Generator, count: int):
    """``count`` mutants of ``data``: flipped bytes, a truncation, junk inserted, a chunk repeated."""
    for _ in range(count):
        mutant = bytearray(data)
        kind = rng.integers(4)
        if kind == 0:
            for at in rng.integers(0, len(mutant), rng.integers(1, 8)):
                mutant[at] = int(rng.integers(256))
        elif kind == 1:
            mutant = mutant[: rng.integers(1, len(mutant))]
        elif kind == 2:
            at = int(rng.integers(0, len(mutant)))
            mutant[at:at] = rng.integers(0, 256, rng.integers(1, 64)).astype(np.uint8).tobytes()
        else:
            a, b = sorted(rng.integers(0, len(mutant), 2))
            mutant[b:b] = mutant[a:b][:4096]
        yield bytes(mutant)


@pytest.mark.parametrize("fmt", ["png", "jpg", "webp", "tiff", "bmp", "ppm"])
def test_decoder_fuzz(fmt):
    """Mutated files decode to an image or raise ImageError, never anything else, each quickly."""
    rng = np.random.default_rng(sum(map(ord, fmt)))
    for mutant in mutations(encoded(fmt), rng, 60):
        t0 = time.perf_counter()
        try:
            image = decode.decode_image(mutant, "fuzz", max_pixels=10_000)
        except ImageError:
            pass
        else:
            assert image.dtype in (np.uint8, np.uint16) and image.size
        assert time.perf_counter() - t0 < 2.0


def test_cli_fuzz_one_line_and_nothing_left(tmp_path):
    """Mutated inputs and masks through the CLI: exit 0, 1 or 2, at most one error line, no
    traceback, and the output folder holds the output or nothing."""
    rng = np.random.default_rng(15)
    mask = tmp_path / "mask.png"
    cv2.imwrite(str(mask), (picture()[..., 0] > 128).astype(np.uint8) * 255)
    out_dir = tmp_path / "out"
    out_dir.mkdir()
    runner = CliRunner()
    for k, mutant in enumerate(mutations(encoded("png"), rng, 12)):
        source = tmp_path / f"m{k}.png"
        source.write_bytes(mutant)
        for args in (["warp", "swirl", source, out_dir / "o.png", "-m", mask],
                     ["warp", "stretch", mask, out_dir / "o.png", "-m", source, "--sx", "1.5"]):
            run = runner.invoke(cli, [str(a) for a in args])
            errors = [line for line in run.output.splitlines() if "error" in line]
            assert run.exit_code in (0, 1, 2) and len(errors) <= 1 and "Traceback" not in run.output, run.output
            assert sorted(p.name for p in out_dir.iterdir()) in ([], ["o.png"])
            assert (run.exit_code == 0) == (out_dir / "o.png").exists()
            (out_dir / "o.png").unlink(missing_ok=True)


def _random_value(param, rng):
    low = param.min if param.min is not None else -1000.0
    high = param.max if param.max is not None else 1000.0
    if param.type is int:
        high = min(high, 4 * 48)
        return int(rng.integers(max(1, int(low)), int(high) + 1))
    value = float(rng.uniform(low, high)) if rng.random() < 0.7 else float(rng.choice([low, high]))
    if param.min_open and value == low:
        value = low + 1e-3 * (high - low)
    return value


@pytest.mark.parametrize("name", ["stretch", "arc", "swirl", "bulge"])
def test_preset_parameter_fuzz(name):
    """Random values within each built-in preset's declared ranges (extremes included): a
    fold-free mesh in bounded time, with features and without."""
    rng = np.random.default_rng(len(name))
    preset = load_warp(name)
    mask = np.zeros((36, 48), bool)
    mask[10:20, 12:26] = True
    for _ in range(6):
        values = {p.name: _random_value(p, rng) for p in preset.params
                  if p.name not in ("width", "height") and p.type not in (tuple, str)}
        try:
            warp = preset(48, 36, **values)
        except ValueError as err:      # a combination the grid cannot follow (swirl: a tight radius), named
            assert str(err).startswith("--") and "\n" not in str(err), err
            continue
        t0 = time.perf_counter()
        mesh = FeatureWarper(48, 36, mask).solve(warp)
        assert mesh.flips() == 0, (name, values, mesh.info["fold_guard"])
        assert time.perf_counter() - t0 < 20.0, (name, values)


def test_closed_stdin_and_newline_names_are_one_line(tmp_path):
    run = subprocess.run([*CLI, "warp", "swirl", "-", str(tmp_path / "o.png")], stdin=subprocess.DEVNULL,
                         capture_output=True, text=True, timeout=60)
    assert run.returncode == 1 and len(run.stderr.splitlines()) == 1
    closed = subprocess.run(" ".join([*CLI, "warp", "swirl", "-", str(tmp_path / "o.png")]) + " <&-", shell=True,
                            capture_output=True, text=True, timeout=60)
    assert closed.returncode == 1 and closed.stderr.splitlines() == [
        "featurewarp: error: stdin is closed; pipe an image into it (or give a file name)"]
    odd = CliRunner().invoke(cli, ["warp", "swirl", str(tmp_path / "no\nsuch.png"), str(tmp_path / "o.png")])
    assert odd.exit_code == 2


def test_newline_in_a_name_stays_on_one_line(tmp_path):
    run = subprocess.run([*CLI, "warp", "swirl", str(tmp_path / "no\nsuch.png"), str(tmp_path / "o.png")],
                         capture_output=True, text=True, timeout=60)
    assert run.returncode == 2 and len(run.stderr.splitlines()) == 1 and "no\\nsuch.png" in run.stderr


@pytest.mark.parametrize("fps", ["1e-9", "0", "1e9", "nan"])
def test_animate_fps_out_of_range_is_a_usage_error(tmp_path, fps):
    source = tmp_path / "in.png"
    cv2.imwrite(str(source), picture())
    run = CliRunner().invoke(cli, ["animate", "swirl", str(source), str(tmp_path / "o.gif"), "--vary",
                                   "angle=0:90", "--frames", "2", "--fps", fps])
    assert run.exit_code == 2 and "--fps" in run.output and not (tmp_path / "o.gif").exists()


def test_a_noisy_mask_that_covers_the_picture_is_said(tmp_path):
    """A JPEG mask whose grey background crosses the threshold with its noise: the warning
    says so, and --strict fails with nothing written."""
    rng = np.random.default_rng(0)
    source, mask, out = tmp_path / "in.png", tmp_path / "mask.jpg", tmp_path / "o.png"
    cv2.imwrite(str(source), picture(160, 120))
    cv2.imwrite(str(mask), np.clip(126 + rng.normal(0, 3, (120, 160)), 0, 255).astype(np.uint8))
    run = CliRunner().invoke(cli, ["warp", "swirl", str(source), str(out), "-m", str(mask)])
    assert run.exit_code == 0 and "of the grid" in run.output
    strict = CliRunner().invoke(cli, ["warp", "swirl", str(source), str(out), "-m", str(mask), "--strict"])
    assert strict.exit_code == 1


def test_every_builtin_preset_declares_bounded_ranges():
    """Every float parameter of the built-in presets has both bounds (a promise needs them)."""
    for name in ("stretch", "arc", "swirl", "bulge"):
        for param in plugins.load(name).params:
            if param.type not in (tuple, str):              # a point, a size or a word is checked in _setup
                assert param.min is not None and param.max is not None, (name, param.name)


def test_png_exif_orientation_after_the_pixels_is_applied():
    """A PNG whose eXIf chunk (orientation 6: turn clockwise) follows its pixel data is turned
    upright, as a JPEG's EXIF is, without decoding twice."""
    import struct
    import zlib

    from PIL import Image

    stored = np.zeros((20, 40, 3), np.uint8)
    stored[:, :10] = 255                                    # white on the left as stored
    png = cv2.imencode(".png", stored)[1].tobytes()
    exif = Image.Exif()
    exif[0x0112] = 6
    payload = exif.tobytes()
    chunk = struct.pack(">I", len(payload)) + b"eXIf" + payload + struct.pack(">I", zlib.crc32(b"eXIf" + payload))
    end = png.rindex(b"IEND") - 4
    upright = decode.decode_image(png[:end] + chunk + png[end:], "exif.png")
    assert upright.shape == (40, 20, 3)
    assert (upright[:10] == 255).all() and (upright[10:] == 0).all()   # the left edge is now the top


def test_animated_input_says_the_first_frame_is_used(tmp_path):
    from PIL import Image

    frames = [Image.fromarray(np.full((12, 16, 3), v, np.uint8)) for v in (0, 255)]
    source = tmp_path / "anim.gif"
    frames[0].save(source, "GIF", save_all=True, append_images=frames[1:])
    run = CliRunner().invoke(cli, ["warp", "swirl", str(source), str(tmp_path / "o.png")])
    assert run.exit_code == 0 and "the first is used" in run.output


def test_debug_is_accepted_after_the_command(tmp_path):
    """--debug after the subcommand is the global flag (it was 'no such option')."""
    source = tmp_path / "in.png"
    cv2.imwrite(str(source), picture())
    run = subprocess.run([*CLI, "warp", "swirl", str(source), str(tmp_path / "o.png"), "--debug"],
                         capture_output=True, text=True, timeout=60)
    assert run.returncode == 0 and run.stderr == ""


class _EntryPoint:
    """A stand-in for an installed plugin's entry point."""

    def __init__(self, name, value, error=None):
        self.name, self.value, self.error = name, value, error

    def load(self):
        raise self.error


def test_a_broken_plugin_shows_its_load_error_when_used(monkeypatch, tmp_path):
    """`featurewarp warp broken IN OUT`: the plugin's import error, not 'unexpected extra arguments'."""
    broken = _EntryPoint("ripple", "theirpkg.ripple:Ripple", ImportError("No module named 'theirpkg'"))
    monkeypatch.setattr(plugins, "entry_points", lambda: [broken])
    plugins.names.cache_clear()
    plugins.load.cache_clear()
    try:
        run = CliRunner().invoke(cli, ["warp", "ripple", str(tmp_path / "in.png"), str(tmp_path / "o.png"),
                                       "--amount", "3"])
        assert run.exit_code == 1 and "failed to load" in run.output and "theirpkg" in run.output, run.output
    finally:
        plugins.names.cache_clear()
        plugins.load.cache_clear()


def test_a_plugin_that_shadows_a_builtin_is_warned_about(monkeypatch):
    shadow = _EntryPoint("swirl", "theirpkg.swirl:Swirl")
    monkeypatch.setattr(plugins, "entry_points", lambda: [shadow])
    plugins.names.cache_clear()
    try:
        run = CliRunner().invoke(cli, ["warps"])
        assert run.exit_code == 0 and "built-in name 'swirl'" in run.output
    finally:
        plugins.names.cache_clear()


def test_a_factorization_inside_the_guard_gives_the_line_back_to_the_guard():
    """The release's factorization announced "factor", and the line said so for the rest of the
    guard: 7 of a swirl 540's 8.7 s, against 0.48 s of factoring in the report."""
    from featurewarp_cli import stages

    heard = []
    stages.listen(heard.append)
    try:
        stages.enter("guard")
        with stages.within("factor", {"grid": "solve"}):
            pass
        stages.enter("grid")                    # the grid's own: the solve follows it
        with stages.within("factor", {"grid": "solve"}):
            pass
    finally:
        stages.forget(heard.append)
    assert heard == ["guard", "factor", "guard", "grid", "factor", "solve"]


def test_progress_line_names_the_stages_and_is_erased(monkeypatch):
    """In a terminal a long run shows its stage and time on one redrawn line, erased at the end;
    nothing is drawn off a terminal or with -q."""
    import io

    from featurewarp_cli import stages
    from featurewarp_cli.cli import progress

    monkeypatch.setattr(progress, "DELAY", 0.0)
    stream = io.StringIO()
    line = progress.ProgressLine(stream)
    stages.listen(line.enter)
    line.thread.start()
    stages.enter("guard")
    deadline = time.monotonic() + 5.0              # drawn at once (DELAY 0), then every INTERVAL
    while "\rfeaturewarp: guard" not in stream.getvalue() and time.monotonic() < deadline:
        time.sleep(0.01)
    stages.forget(line.enter)
    line.close()
    text = stream.getvalue()
    assert "\rfeaturewarp: guard" in text and text.endswith("\r\033[K")
    with progress.progress_line(quiet=True) as shown:
        assert shown is None
    monkeypatch.setattr(sys.stderr, "isatty", lambda: False, raising=False)
    with progress.progress_line(quiet=False) as shown:
        assert shown is None


def test_quiet_silences_notices(monkeypatch, tmp_path):
    """-q: no warning, no notice (the SciPy fallback's one included)."""
    from featurewarp_cli import stages

    monkeypatch.setattr(stages, "quiet", False)
    source = tmp_path / "in.png"
    cv2.imwrite(str(source), picture(160, 120))
    mask = tmp_path / "mask.png"
    blobs = np.zeros((120, 160), np.uint8)
    blobs[:, :150] = 255                       # most of the picture: warns, and factors a system
    cv2.imwrite(str(mask), blobs)
    code = ("import sys; sys.modules['sksparse'] = None\n"
            "from featurewarp_cli.cli.main import main\n"
            f"main(['warp', 'swirl', {str(source)!r}, {str(tmp_path / 'o.png')!r}, '-m', {str(mask)!r}, '-q'])\n")
    run = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=60)
    assert run.returncode == 0 and run.stderr == "", run.stderr
    loud = subprocess.run([sys.executable, "-c", code.replace(", '-q'", "")], capture_output=True, text=True,
                          timeout=60)
    assert "scikit-sparse" in loud.stderr and "warning" in loud.stderr


@pytest.mark.parametrize("value", ["abc", "-1", "0", "inf", "-inf", "nan", "1e300", " "])
def test_a_stage_delay_it_cannot_use_is_ignored(monkeypatch, tmp_path, value):
    """Hostile review D13: FEATUREWARP_TEST_STAGE_DELAY=abc, -1 or inf turned every run into an
    internal error (ValueError, OverflowError from time.sleep); the test hook now ignores them."""
    from featurewarp_cli.io import write

    monkeypatch.setenv(write.STAGE_DELAY_VARIABLE, value)
    cv2.imwrite(str(tmp_path / "in.png"), picture())
    started = time.monotonic()
    run = CliRunner().invoke(cli, ["warp", "swirl", str(tmp_path / "in.png"), str(tmp_path / "out.png"), "-q"])
    assert run.exit_code == 0, run.output
    assert (tmp_path / "out.png").exists() and time.monotonic() - started < 30
    assert write.stage_delay() == 0.0


def test_a_usable_stage_delay_still_waits(monkeypatch):
    from featurewarp_cli.io import write

    monkeypatch.setenv(write.STAGE_DELAY_VARIABLE, "0.25")
    assert write.stage_delay() == 0.25


def test_a_name_longer_than_the_file_system_takes_is_a_usage_error(tmp_path):
    """It was 'OSError: [Errno 36] File name too long' (exit 1), with the whole path echoed."""
    from click.testing import CliRunner

    from featurewarp_cli.cli.main import cli

    cv2.imwrite(str(tmp_path / "in.png"), np.zeros((20, 30, 3), np.uint8))
    long = tmp_path / ("a" * 252 + ".png")
    run = CliRunner().invoke(cli, ["warp", "swirl", str(tmp_path / "in.png"), str(long)])
    assert run.exit_code == 2 and "file name too long (256 bytes; at most 255)" in run.output
    assert len(run.output) < 400


def test_a_read_only_output_is_not_replaced(tmp_path, monkeypatch):
    """The atomic rename needs only the folder's permission: a 0444 file was replaced."""
    import os

    from featurewarp_cli.io import write

    target = tmp_path / "ro.png"
    target.write_bytes(b"kept")
    real = os.access
    monkeypatch.setattr(os, "access", lambda path, mode, **kw: False if str(path) == str(target) else real(path, mode))
    with pytest.raises(ValueError, match="ro.png is not writable by you \\(read-only"):
        write.check_writable(str(target))


def test_a_file_nobody_may_write_is_not_replaced_even_by_root(tmp_path):
    """os.access lets root write anything: as root (CI) a chmod 444 output was replaced, rc 0.
    A regular file with no write bit is refused before the work, and again when staged."""
    import os
    import stat

    from featurewarp_cli.io import write

    cv2.imwrite(str(tmp_path / "in.png"), np.zeros((20, 30, 3), np.uint8))
    target = tmp_path / "o.png"
    target.write_bytes(b"golden")
    target.chmod(0o444)
    inode = target.stat().st_ino
    run = CliRunner().invoke(cli, ["warp", "swirl", str(tmp_path / "in.png"), str(target)])
    assert run.exit_code == 2 and "Traceback" not in run.output, run.output
    assert "o.png is read-only (mode 444): not replaced; chmod u+w it or give another name" in run.output
    with pytest.raises(PermissionError, match="read-only file"):        # made read-only after the check
        write.write_outputs([(str(target), b"new")])
    assert target.read_bytes() == b"golden" and target.stat().st_ino == inode
    target.chmod(0o644)
    write.write_atomic(str(target), b"new")
    assert target.read_bytes() == b"new" and stat.S_IMODE(os.stat(target).st_mode) == 0o644


def test_the_same_bytes_leave_an_output_in_place(tmp_path):
    """Each rerun replaced an unchanged output (new inode, hard links broken); now only a change
    is written. Its time is set to now all the same: left alone, make found the target older than
    the input that changed and ran the rule on every call."""
    import os

    from featurewarp_cli.io import write

    target, linked = tmp_path / "o.png", tmp_path / "hard.png"
    write.write_atomic(str(target), b"result")
    os.link(target, linked)
    os.utime(target, ns=(10**18, 10**18))                         # 2001
    before = os.stat(target)
    write.write_outputs([(str(target), b"result"), (str(tmp_path / "r.json"), b"{}")])
    after = os.stat(target)
    assert (after.st_ino, after.st_nlink) == (before.st_ino, 2) and after.st_mtime_ns > 10**18 + 10**17
    assert not [p for p in os.listdir(tmp_path) if p.startswith(write.TEMP_PREFIX)]
    for changed in (b"resulT", b"result and more"):                 # same size, and another size
        write.write_atomic(str(target), changed)
        assert target.read_bytes() == changed and linked.read_bytes() == b"result"
        assert os.stat(target).st_ino != before.st_ino


def test_a_failed_rename_names_the_output_not_its_staging_file(tmp_path, monkeypatch):
    """The error named the hidden .featurewarp-....tmp file."""
    import os

    from featurewarp_cli.io import write

    def refuse(source, target):
        raise PermissionError(13, "Permission denied", source)
    monkeypatch.setattr(os, "replace", refuse)
    with pytest.raises(OSError) as caught:
        write.write_outputs([(str(tmp_path / "out.png"), b"data")])
    assert caught.value.filename == str(tmp_path / "out.png")

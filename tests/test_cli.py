"""The command line: pipes, formats, determinism, atomic writes, verbosity, completion, entry points.

Most tests call :func:`featurewarp_cli.cli.main` in-process through click's
``CliRunner`` isolation (the ``runner`` fixture), so that exit codes and the
one-line error messages are exactly those of the console script; a few run
the real command in a subprocess. The helpers here are shared by the other CLI
test files (``from test_cli import ...``).
"""

from __future__ import annotations

import inspect
import io
import json
import os
import subprocess
import sys
from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np
import pytest
from click.testing import CliRunner

from featurewarp_cli.io import ImageError, decode, encode, formats
from featurewarp_cli import plugins
from featurewarp_cli.cli.main import main

SIZE = (48, 36)                      # width, height of the test images: small, so a warp takes ms
FORMATS = ("png", "jpg", "webp", "tiff", "bmp")


@dataclass
class Run:
    """The outcome of one command: exit code, stdout bytes, stderr text."""

    code: int
    stdout: bytes
    stderr: str

    @property
    def lines(self) -> list[str]:
        return self.stderr.splitlines()


class Runner:
    """Calls ``main(args)`` as the console script would, capturing stdin, stdout and stderr."""

    def __init__(self):
        # click < 8.2 mixes stderr into stdout unless told not to (8.2 dropped the argument).
        separate = {"mix_stderr": False} if "mix_stderr" in inspect.signature(CliRunner).parameters else {}
        self.cli = CliRunner(**separate)

    def __call__(self, *args, input: bytes | None = None, env: dict | None = None) -> Run:
        with self.cli.isolation(input=input, env=env) as (out, err, *_):
            try:
                main([str(a) for a in args])
                code = 0
            except SystemExit as exit_:
                code = exit_.code
            sys.stdout.flush()
            sys.stderr.flush()
            return Run(code, out.getvalue(), err.getvalue().decode())


@pytest.fixture
def runner() -> Runner:
    return Runner()


def command(*args, input: bytes | None = None) -> subprocess.CompletedProcess:
    """Run ``python -m featurewarp_cli ARGS`` in a fresh process."""
    return subprocess.run([sys.executable, "-m", "featurewarp_cli", *map(str, args)], input=input,
                          capture_output=True, timeout=120)


def textured(size=SIZE, channels=3, dtype=np.uint8) -> np.ndarray:
    """A smooth, colourful test image of ``size`` (width, height)."""
    w, h = size
    y, x = np.mgrid[0:h, 0:w]
    planes = [128 + 90 * np.sin(x / 4.0 + k) * np.cos(y / 5.0 - k) for k in range(channels)]
    image = np.clip(np.dstack(planes), 0, 255)
    if dtype == np.uint16:
        return (image * 257).astype(np.uint16)
    image = image.astype(np.uint8)
    return image[:, :, 0] if channels == 1 else image


def square_mask(size=SIZE) -> np.ndarray:
    """A uint8 mask (0 / 255) with one square feature in the middle."""
    w, h = size
    mask = np.zeros((h, w), np.uint8)
    mask[h // 3 : 2 * h // 3, w // 3 : 2 * w // 3] = 255
    return mask


def save(path, image: np.ndarray):
    """Write ``image`` with OpenCV (format from the extension); returns the path as str."""
    ok, buf = cv2.imencode(os.path.splitext(str(path))[1], image)
    assert ok
    buf.tofile(str(path))
    return str(path)


def scene(tmp_path, name="in.png"):
    """Write a test image and its mask into ``tmp_path``; returns (image path, mask path)."""
    return (save(tmp_path / name, textured()),
            save(tmp_path / (os.path.splitext(name)[0] + "_mask.png"), square_mask()))


def decoded(data: bytes) -> np.ndarray:
    return decode.decode_image(data, "test")


def listing(directory) -> dict:
    """{name: bytes} of every file in a directory (to prove nothing was created or changed)."""
    return {p.name: p.read_bytes() for p in sorted(directory.iterdir()) if p.is_file()}


# --- basics ---------------------------------------------------------------------------------

def test_warp_writes_the_declared_canvas(runner, tmp_path):
    image, mask = scene(tmp_path)
    run = runner("warp", "stretch", image, tmp_path / "out.png", "--mask", mask, "--sx", "1.5")
    assert (run.code, run.stdout, run.stderr) == (0, b"", "")
    out = decode.read_image(str(tmp_path / "out.png"))
    assert out.shape[:2] == (SIZE[1], round(SIZE[0] * 1.5))


def test_output_may_be_the_input(runner, tmp_path):
    image, mask = scene(tmp_path)
    before = Path(image).read_bytes()
    run = runner("warp", "swirl", image, image, "--mask", mask, "--angle", "60")
    assert run.code == 0, run.stderr
    after = Path(image).read_bytes()
    assert after != before and decoded(after).shape == decoded(before).shape
    assert sorted(os.listdir(tmp_path)) == ["in.png", "in_mask.png"]


def test_report_is_written(runner, tmp_path):
    image, mask = scene(tmp_path)
    run = runner("warp", "bulge", image, tmp_path / "out.png", "-m", mask, "--report", tmp_path / "r.json")
    assert run.code == 0, run.stderr
    report = json.loads((tmp_path / "r.json").read_text())
    assert report["preset"] == "bulge" and report["output"]["width"] == SIZE[0]
    assert set(report["fold_guard"]) >= {"flipped_before", "flipped_after", "untangle_iterations",
                                         "window_quads", "window", "feature_blend"}
    from featurewarp_cli.engine import guard                # the window's settings, as the guard runs them
    from featurewarp_cli.engine.window import PATH_TOLERANCE
    assert report["fold_guard"]["window"] == {"margin": guard.WINDOW_MARGIN, "min_margin": guard.WINDOW_MIN_MARGIN,
                                              "max_steps": guard.WINDOW_STEPS,
                                              "continued_below": list(guard.CONTINUED_BELOW),
                                              "tolerance": PATH_TOLERANCE}


# --- pipes ----------------------------------------------------------------------------------

def test_stdin_to_stdout_equals_files(runner, tmp_path):
    image, mask = scene(tmp_path)
    files = runner("warp", "swirl", image, tmp_path / "out.png", "-m", mask)
    piped = runner("warp", "swirl", "-", "png:-", "-m", mask, "--verbose", input=Path(image).read_bytes())
    assert files.code == piped.code == 0
    assert piped.stdout == (tmp_path / "out.png").read_bytes()
    assert "48x36" in piped.stderr                       # the summary goes to stderr, not stdout


@pytest.mark.parametrize("source", ["jpg", "webp", "tiff", "bmp"])
def test_stdin_format_is_sniffed(runner, tmp_path, source):
    data = encode.encode_image(textured(), source)
    run = runner("warp", "stretch", "-", "-", "--format", "png", "--sx", "2", input=data)
    assert run.code == 0, run.stderr
    assert decoded(run.stdout).shape == (SIZE[1], 2 * SIZE[0], 3)


def test_prefix_names_the_format_of_a_file(runner, tmp_path):
    image, _ = scene(tmp_path)
    run = runner("warp", "swirl", image, f"jpg:{tmp_path / 'out.bin'}")
    assert run.code == 0, run.stderr
    assert (tmp_path / "out.bin").read_bytes()[:2] == b"\xff\xd8"


def test_mask_from_stdin(runner, tmp_path):
    image, mask = scene(tmp_path)
    run = runner("warp", "swirl", image, "-", "--format", "png", "-m", "-", input=Path(mask).read_bytes())
    reference = runner("warp", "swirl", image, "png:-", "-m", mask)
    assert run.code == 0 and run.stdout == reference.stdout


def test_output_target_parsing():
    assert formats.output_target("png:-") == ("-", "png")
    assert formats.output_target("-", "JPEG") == ("-", "jpg")
    assert formats.output_target("a/b.TIF") == ("a/b.TIF", "tiff")
    assert formats.output_target("x:y.png") == ("x:y.png", "png")       # not a format prefix
    with pytest.raises(ValueError, match="--format"):
        formats.output_target("-")
    with pytest.raises(ValueError, match="asks for png"):
        formats.output_target("png:-", "jpg")


# --- determinism ----------------------------------------------------------------------------

@pytest.mark.parametrize("fmt", FORMATS)
def test_same_command_gives_the_same_bytes(runner, tmp_path, fmt):
    """Twice in this process and once in a fresh one: byte-identical files."""
    image, mask = scene(tmp_path)
    args = ["warp", "bulge", image, None, "-m", mask, "--strength", "0.7", "--background", "#336699"]
    outputs = []
    for k in range(2):
        args[3] = tmp_path / f"out{k}.{fmt}"
        assert runner(*args).code == 0
        outputs.append(args[3].read_bytes())
    args[3] = tmp_path / f"out2.{fmt}"
    assert command(*args).returncode == 0
    outputs.append(args[3].read_bytes())
    assert outputs[0] == outputs[1] == outputs[2]
    assert decoded(outputs[0]).shape[:2] == (SIZE[1], SIZE[0])


# --- formats and depths ---------------------------------------------------------------------

def test_sixteen_bit_png_stays_sixteen_bit(runner, tmp_path):
    src = save(tmp_path / "deep.png", textured(dtype=np.uint16))
    assert runner("warp", "swirl", src, tmp_path / "out.png", "--angle", "0").code == 0
    out = decode.read_image(str(tmp_path / "out.png"))
    assert out.dtype == np.uint16
    assert np.abs(out.astype(int) - decode.read_image(src).astype(int)).max() <= 257


@pytest.mark.parametrize("fmt", ["jpg", "webp", "bmp"])
def test_sixteen_bit_is_scaled_for_eight_bit_formats(runner, tmp_path, fmt):
    src = save(tmp_path / "deep.png", textured(dtype=np.uint16))
    assert runner("warp", "swirl", src, tmp_path / f"out.{fmt}", "--angle", "0").code == 0
    out = decode.read_image(str(tmp_path / f"out.{fmt}"))
    assert out.dtype == np.uint8
    assert np.abs(out.astype(int) - textured().astype(int)).mean() < 3


def test_alpha_is_flattened_on_the_background_for_jpeg(runner, tmp_path):
    rgba = np.dstack([textured(), np.zeros(SIZE[::-1], np.uint8)])     # fully transparent
    src = save(tmp_path / "clear.png", rgba)
    run = runner("warp", "swirl", src, tmp_path / "out.bmp", "--angle", "0", "--background", "red")
    assert run.code == 0, run.stderr
    out = decode.read_image(str(tmp_path / "out.bmp"))
    assert out.shape == (SIZE[1], SIZE[0], 3) and (out == (0, 0, 255)).all()


# --- atomic writes --------------------------------------------------------------------------

@pytest.mark.parametrize("where", ["encode", "write", "rename", "solve"])
def test_a_failure_leaves_the_existing_output_untouched(runner, tmp_path, monkeypatch, where):
    image, mask = scene(tmp_path)
    out = tmp_path / "out.png"
    out.write_bytes(b"precious")

    def boom(*args, **kwargs):
        raise OSError(28, "No space left on device")

    target = {"encode": (encode, "encode_image"), "write": (os, "write"), "rename": (os, "replace"),
              "solve": (__import__("featurewarp_cli.engine.warper").engine.warper.FeatureWarper, "solve")}[where]
    monkeypatch.setattr(*target, boom)
    before = listing(tmp_path)
    run = runner("warp", "swirl", image, out, "-m", mask)
    assert run.code == 1 and len(run.lines) == 1 and "Traceback" not in run.stderr
    assert "No space left on device" in run.stderr
    assert listing(tmp_path) == before


# --- verbosity, debug -----------------------------------------------------------------------

def test_verbose_summary_line(runner, tmp_path):
    image, mask = scene(tmp_path)
    run = runner("warp", "stretch", image, tmp_path / "o.png", "-m", mask, "--sx", "2", "-v")
    assert run.code == 0 and len(run.lines) == 1
    line = run.lines[0]
    assert "48x36" in line and "96x36" in line and "solver" in line and line.endswith(" s")


def test_quiet_silences_warnings(runner, tmp_path):
    image, _ = scene(tmp_path)
    black = save(tmp_path / "black.png", np.zeros(SIZE[::-1], np.uint8))
    loud = runner("warp", "swirl", image, tmp_path / "o.png", "-m", black)
    quiet = runner("warp", "swirl", image, tmp_path / "o.png", "-m", black, "--quiet")
    assert loud.code == quiet.code == 0
    assert "warning" in loud.stderr and "plain warp" in loud.stderr and quiet.stderr == ""


def test_quiet_and_verbose_exclude_each_other(runner, tmp_path):
    image, _ = scene(tmp_path)
    run = runner("warp", "swirl", image, tmp_path / "o.png", "-q", "-v")
    assert run.code == 2 and "exclude" in run.stderr


def test_debug_shows_a_traceback_for_processing_errors(runner, tmp_path):
    bad = tmp_path / "bad.png"
    bad.write_text("not an image")
    plain = runner("warp", "swirl", bad, tmp_path / "o.png")
    debug = runner("--debug", "warp", "swirl", bad, tmp_path / "o.png")
    assert plain.code == debug.code == 1
    assert "Traceback" not in plain.stderr and "Traceback" in debug.stderr
    assert debug.lines[-1] == plain.lines[0]


def test_unexpected_errors_are_one_line(runner, tmp_path, monkeypatch):
    image, _ = scene(tmp_path)
    monkeypatch.setattr(decode, "mask_from_image", lambda image: 1 / 0)
    run = runner("warp", "swirl", image, tmp_path / "o.png", "-m", image)
    assert run.code == 1 and run.lines == [
        "featurewarp: error: ZeroDivisionError: division by zero (--debug shows a traceback)"]


def test_an_opencv_assertion_is_one_clean_line(runner, tmp_path, monkeypatch):
    """cv2.error read 'error: error: OpenCV(4.14.0) ...' with OpenCV's newline as a literal \\n."""
    import cv2

    image, _ = scene(tmp_path)

    def fail(image):
        raise cv2.error("OpenCV(4.14.0) resize.cpp:4020: error: (-215:Assertion failed) !dsize.empty()\n")
    monkeypatch.setattr(decode, "mask_from_image", fail)
    run = runner("warp", "swirl", image, tmp_path / "o.png", "-m", image)
    assert run.code == 1 and len(run.lines) == 1 and run.lines[0].startswith("featurewarp: error: OpenCV: OpenCV(")
    assert "\\n" not in run.lines[0] and "error: error:" not in run.lines[0]


# --- conventions ----------------------------------------------------------------------------

def test_warps_json(runner):
    run = runner("warps", "--json")
    assert run.code == 0
    entries = json.loads(run.stdout)
    assert [e["name"] for e in entries] == list(plugins.names())
    for entry in entries:
        for p in entry["params"]:
            assert {"name", "type", "default", "min", "max", "help"} <= set(p)


def test_warps_lists_the_presets_it_is_given(runner):
    """'featurewarp warps swirl' said "Got unexpected extra argument"."""
    run = runner("warps", "swirl", "arc", "--json")
    assert run.code == 0 and [e["name"] for e in json.loads(run.stdout)] == ["swirl", "arc"]
    text = runner("warps", "swirl").stdout.decode()
    assert text.startswith("swirl  ") and "--angle" in text and "\narc  " not in text
    wrong = runner("warps", "swrl")
    assert wrong.code == 2 and "did you mean 'swirl'?" in wrong.stderr and len(wrong.lines) == 1


@pytest.mark.skipif(not os.path.exists("/dev/full"), reason="needs /dev/full")
def test_a_stdout_that_cannot_be_written_is_named(tmp_path):
    """'featurewarp warps > /dev/full' said "OSError: [Errno 28] No space left on device" and named no file."""
    for encoding in ("utf-8", "ascii"):          # with ASCII, click writes through its own wrapper of stdout
        with open("/dev/full", "w") as full:
            run = subprocess.run([sys.executable, "-m", "featurewarp_cli", "schema", "report"], stdout=full,
                                 stderr=subprocess.PIPE, text=True, timeout=60,
                                 env={**os.environ, "PYTHONIOENCODING": encoding})
        assert run.returncode == 1 and run.stderr == "featurewarp: error: cannot write stdout: No space left on device\n"
    image, _ = scene(tmp_path)              # the report on stdout failed named as the image beside it
    with open("/dev/full", "w") as full:
        run = subprocess.run([sys.executable, "-m", "featurewarp_cli", "warp", "swirl", image, str(tmp_path / "o.png"),
                              "--report", "-"], stdout=full, stderr=subprocess.PIPE, text=True, timeout=60)
    assert run.returncode == 1 and run.stderr == "featurewarp: error: cannot write stdout: No space left on device\n"
    assert not (tmp_path / "o.png").exists()


def test_only_a_stream_on_stdout_is_stdout(tmp_path):
    """No stdout at all (None, as under pythonw) is not a stream that failed to be written."""
    from featurewarp_cli.cli.main import _is_stdout

    with open(tmp_path / "f", "w") as other:
        assert not _is_stdout(None) and not _is_stdout(other) and not _is_stdout(io.StringIO())
    assert _is_stdout(os.fdopen(1, "w", closefd=False))


def test_help_is_fast():
    code = "import sys, featurewarp_cli.cli.main; print('cv2' in sys.modules, 'PIL' in sys.modules)"
    imported = subprocess.run([sys.executable, "-c", code], capture_output=True, timeout=60)
    assert imported.stdout.strip() == b"False False"  # --help loads neither OpenCV nor Pillow


def test_help_documents_completion(runner):
    run = runner("--help")
    assert run.code == 0 and b"_FEATUREWARP_COMPLETE=bash_source featurewarp" in run.stdout


def test_completion_works(runner):
    script = runner(env={"_FEATUREWARP_COMPLETE": "bash_source"})
    assert script.code == 0 and b"_featurewarp_completion" in script.stdout
    words = runner(env={"_FEATUREWARP_COMPLETE": "bash_complete", "COMP_WORDS": "featurewarp warp s",
                        "COMP_CWORD": "2"})
    assert words.code == 0 and b"stretch" in words.stdout and b"swirl" in words.stdout


def test_python_dash_m_and_console_script(tmp_path):
    version = command("--version")
    assert version.returncode == 0 and b"featurewarp" in version.stdout
    missing = command("warp", "swirl", tmp_path / "nope.png", tmp_path / "o.png")
    assert missing.returncode == 2 and missing.stdout == b""
    assert missing.stderr.decode().splitlines() == [
        f"featurewarp: error: Invalid value for 'INPUT': {tmp_path / 'nope.png'} does not exist"]


def test_real_pipe_end_to_end(tmp_path):
    image, mask = scene(tmp_path)
    run = command("warp", "arc", "-", "png:-", "-m", mask, "--angle", "90", input=Path(image).read_bytes())
    assert run.returncode == 0 and run.stderr == b""
    assert run.stdout[:8] == b"\x89PNG\r\n\x1a\n"


def test_python_warnings_are_one_line(runner, tmp_path, monkeypatch):
    import warnings

    from featurewarp_cli.app import pipeline as batch

    def warn_then_transparent(text, fmt):
        warnings.warn("overflow encountered in divide", RuntimeWarning)
        return None

    monkeypatch.setattr(batch, "background_colour", warn_then_transparent)
    image, _ = scene(tmp_path)
    run = runner("warp", "swirl", image, tmp_path / "o.png")
    assert run.code == 0
    assert run.lines == ["featurewarp: warning: overflow encountered in divide (test_cli.py:"
                         f"{warn_then_transparent.__code__.co_firstlineno + 1})"]


def test_stdin_terminal_is_refused(monkeypatch):
    class Terminal:
        def isatty(self):
            return True

    monkeypatch.setattr(sys, "stdin", Terminal())
    with pytest.raises(ImageError, match="stdin is a terminal"):
        decode.read_bytes("-")


def test_broken_pipe_is_one_line(tmp_path):
    image, _ = scene(tmp_path)
    run = subprocess.run(f"{sys.executable} -m featurewarp_cli warp stretch {image} bmp:- --sx 40 --sy 20 | true",
                         shell=True, capture_output=True, timeout=120)
    lines = run.stderr.decode().splitlines()
    assert lines == ["featurewarp: error: cannot write stdout: Broken pipe"]


def test_the_command_runs_openblas_with_one_thread_unless_told_otherwise():
    """A fresh ``featurewarp`` process: OPENBLAS_NUM_THREADS is 1 by the time numpy loads,
    unless the environment sets it (featurewarp_cli.blas)."""
    probe = ("import os, sys; from featurewarp_cli.cli import main; "
             "main.cli.add_command(main.click.Command('probe', callback=lambda: print("
             "os.environ.get('OPENBLAS_NUM_THREADS'), 'numpy' in sys.modules))); main.main(['probe'])")
    env = {key: value for key, value in os.environ.items() if key != "OPENBLAS_NUM_THREADS"}
    fresh = subprocess.run([sys.executable, "-c", probe], env=env, capture_output=True, text=True, timeout=60)
    assert fresh.stdout.split() == ["1", "False"], fresh.stderr
    told = subprocess.run([sys.executable, "-c", probe], env={**env, "OPENBLAS_NUM_THREADS": "3"},
                          capture_output=True, text=True, timeout=60)
    assert told.stdout.split() == ["3", "False"], told.stderr


@pytest.mark.parametrize("args, said", [
    (["presets"], "'featurewarp warps' lists the presets"),
    (["swirl", "a.png", "b.png"], "a preset is run as 'featurewarp warp swirl INPUT OUTPUT'"),
    (["warp", "swirl", "a.png", "b.png", "--sx", "2"], "--sx is stretch's; swirl has --angle, --radius, --center"),
])
def test_a_misplaced_word_says_where_it_belongs(runner, args, said):
    """'presets' and a preset in a command's place got 'No such command', and --sx given to swirl
    'Did you mean --mask?'."""
    run = runner(*args)
    assert run.code == 2 and said in run.stderr and len(run.stderr.strip().splitlines()) == 1, run.stderr


def test_animate_refuses_an_option_both_given_and_varied(runner, tmp_path):
    """--vary angle=0:90 with --angle 30 ran 0 to 90 and dropped the 30 in silence."""
    image = save(tmp_path / "in.png", textured(SIZE))
    run = runner("animate", "swirl", image, tmp_path / "a.gif", "--vary", "angle=0:90", "--angle", "30")
    assert run.code == 2 and "--angle is given and varied" in run.stderr
    assert not (tmp_path / "a.gif").exists()


def test_an_option_the_mode_leaves_unused_is_noted(runner, tmp_path):
    """--scale-prior under rigid, --feature-weight under plain were taken in silence."""
    image = save(tmp_path / "in.png", textured(SIZE))
    run = runner("warp", "stretch", image, tmp_path / "o.png", "--sx", "1.2", "--mode", "plain", "--feature-weight", "3")
    assert run.code == 0 and "--feature-weight does nothing with --mode plain" in run.stderr
    run = runner("warp", "stretch", image, tmp_path / "o.png", "--sx", "1.2", "--mode", "rigid", "--scale-prior", "0.5")
    assert "--scale-prior does nothing with --mode rigid" in run.stderr
    quiet = runner("warp", "stretch", image, tmp_path / "o.png", "--sx", "1.2", "--mode", "plain", "--decay", "2", "-q")
    assert quiet.code == 0 and quiet.stderr == ""
    assert "does nothing" not in runner("warp", "stretch", image, tmp_path / "o.png", "--sx", "1.2").stderr
    run = runner("warp", "stretch", image, tmp_path / "o.png", "--sx", "1.2", "--decay", "2")     # no mask
    assert "--decay does nothing without --mask" in run.stderr


def test_quality_for_a_format_it_does_not_set_is_noted(runner, tmp_path):
    """--quality 50 with a TIFF output was taken in silence (a retoucher expected compression)."""
    image = save(tmp_path / "in.png", textured(SIZE))
    for name, kind in (("o.tif", "TIFF is lossless"), ("o.png", "PNG is lossless"), ("o.gif", "GIF is a 256-colour")):
        run = runner("warp", "stretch", image, tmp_path / name, "--sx", "1.2", "--quality", "50")
        assert run.code == 0 and f"--quality does nothing for a {name[2:].upper().replace('TIF', 'TIFF')} output" \
            in run.stderr and kind in run.stderr, run.stderr
    for name in ("o.jpg", "o.webp"):
        assert "--quality" not in runner("warp", "stretch", image, tmp_path / name, "--sx", "1.2", "--quality",
                                         "50").stderr
    second = save(tmp_path / "in2.png", textured(SIZE))
    for each in ("in", "in2"):
        save(tmp_path / f"{each}_mask.png", np.zeros(SIZE[::-1], np.uint8))
    run = runner("batch", "stretch", image, second, "--out-dir", tmp_path / "out", "--sx", "1.2", "--quality", "50")
    assert run.code == 0 and run.stderr.count("--quality does nothing") == 1, run.stderr     # once, not a file


def test_an_option_another_overrides_is_noted(runner, tmp_path):
    """--sx 2 --width 100 wrote 100 px wide and said nothing of the 2."""
    image = save(tmp_path / "in.png", textured(SIZE))
    run = runner("warp", "stretch", image, tmp_path / "o.png", "--sx", "2", "--width", "100")
    assert run.code == 0 and run.stderr.count("does nothing") == 1
    assert "--sx does nothing with --width, which overrides it" in run.stderr
    assert decode.read_image(str(tmp_path / "o.png")).shape[1] == 100
    run = runner("warp", "stretch", image, tmp_path / "o.png", "--size", "50x40", "--sx", "3", "--height", "50")
    assert "--sx does nothing with --size" in run.stderr and "--height does nothing with --size" in run.stderr
    run = runner("warp", "stretch", image, tmp_path / "o.png", "--sx", "2", "--width", "100", "--size", "50x40")
    assert run.stderr.count("does nothing") == 2 and "--sx does nothing with --size, which overrides it" in run.stderr
    assert "--width does nothing with --size" in run.stderr       # --sx is not named against --width, which loses too
    for alone in (("--width", "100"), ("--sx", "2", "--height", "50")):
        assert "does nothing" not in runner("warp", "stretch", image, tmp_path / "o.png", *alone).stderr


@pytest.mark.parametrize("command", ["warp", "compare"])
def test_a_strict_refusal_names_the_input(runner, tmp_path, command):
    """'featurewarp -q warp ... --strict' refused with a line naming no file: under make -j it could
    not be told from its neighbours' (warnings, decode errors and batch name the file)."""
    image, mask = tmp_path / "in.png", tmp_path / "empty.png"
    save(image, textured())
    save(mask, np.zeros(SIZE[::-1], np.uint8))                       # marks nothing: a warning
    run = runner("-q", command, "swirl", image, tmp_path / "o.png", "-m", mask, "--strict")
    assert run.code == 1 and not (tmp_path / "o.png").exists()
    assert run.stderr.startswith(f"featurewarp: error: {image}: --strict: ") and run.stderr.count("\n") == 1, run.stderr

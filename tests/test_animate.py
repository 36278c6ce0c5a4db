"""featurewarp animate: frames, formats, one factorization, errors."""

import cv2
import numpy as np
import pytest

from samples import scenes
from test_cli import Runner


def run(*args):
    """``featurewarp animate ARGS`` in-process (CliRunner): exit code and stderr as the console script's."""
    return Runner()("animate", *args)


@pytest.fixture(scope="module")
def files(tmp_path_factory):
    folder = tmp_path_factory.mktemp("anim")
    image, mask = scenes.scene()
    image, mask = image[::2, ::2], mask[::2, ::2]
    cv2.imwrite(str(folder / "in.png"), image)
    cv2.imwrite(str(folder / "mask.png"), mask.astype(np.uint8) * 255)
    return folder


@pytest.mark.parametrize("name", ["out.gif", "out.webp", "out.png"])
def test_animated_image_has_every_frame(files, name):
    """An animated GIF/WebP/PNG holds --frames frames of the warp's canvas; one factorization."""
    out = run("swirl", str(files / "in.png"), str(files / name), "-m", str(files / "mask.png"),
              "--vary", "angle=0:90", "--frames", "5", "-v")
    assert out.code == 0, out.stderr
    assert "5 frames 250x180, 1 factorization(s)" in out.stderr
    ok, animation = cv2.imreadanimation(str(files / name))
    assert ok and len(animation.frames) == 5
    assert animation.frames[0].shape[:2] == (180, 250)
    assert np.abs(animation.frames[0].astype(int) - animation.frames[-1].astype(int)).max() > 50


def test_an_animated_webp_is_lossless_unless_a_quality_is_given(files):
    """OpenCV wrote animated WebP lossy whatever --quality said (three files byte-identical, up
    to 150 levels off the APNG of the same run; smoke trial 2): lossless as a still WebP, every
    frame equal to the APNG's; --quality makes it lossy, smaller."""
    args = [str(files / "in.png"), "-m", str(files / "mask.png"), "--vary", "angle=0:90", "--frames", "3"]
    for name, extra in (("l.webp", []), ("l.png", []), ("q.webp", ["--quality", "30"])):
        assert run("swirl", args[0], str(files / name), *args[1:], *extra).code == 0
    ok, lossless = cv2.imreadanimation(str(files / "l.webp"))
    ok_png, apng = cv2.imreadanimation(str(files / "l.png"))
    assert ok and ok_png and len(lossless.frames) == len(apng.frames) == 3
    for webp_frame, png_frame in zip(lossless.frames, apng.frames):
        assert np.array_equal(webp_frame, png_frame)
    assert (files / "q.webp").stat().st_size < (files / "l.webp").stat().st_size


def test_numbered_sequence_and_varying_canvas(files):
    """A %d pattern writes numbered PNGs; frames of a growing stretch are centred on the largest canvas."""
    out = run("stretch", str(files / "in.png"), str(files / "seq-%02d.png"), "-m", str(files / "mask.png"),
              "--vary", "sx=1:1.5", "--frames", "3")
    assert out.code == 0, out.stderr
    frames = [cv2.imread(str(files / f"seq-{i:02d}.png"), cv2.IMREAD_UNCHANGED) for i in range(3)]
    assert all(f.shape[:2] == (180, 375) for f in frames)
    assert frames[0][:, 0, 3].max() == 0 and frames[-1][:, 0, 3].min() == 255   # padding is transparent


def test_frames_left_after_a_sequence_by_a_longer_run_are_said(files, tmp_path):
    """A shorter run over an earlier sequence left its later frames, exit 0 and no word: a
    reader of the pattern (ffmpeg -i f-%04d.png) played a mixed clip."""
    args = [str(files / "in.png"), str(tmp_path / "f-%04d.png"), "--vary", "angle=0:90"]
    assert run("swirl", *args, "--frames", "5").code == 0
    out = run("swirl", *args, "--frames", "2")
    assert out.code == 0 and "f-0002.png to " in out.stderr and "f-0004.png (3 files) follow this" in out.stderr
    out = run("swirl", *args, "--frames", "4", "--strict")
    assert out.code == 1 and "f-0004.png (1 file) follows this sequence's last frame" in out.stderr
    assert run("swirl", *args, "--frames", "5", "--strict").code == 0


@pytest.mark.parametrize("output", ["gif:-", "/dev/stdout", "gif:{dir}/o.gif"])
def test_stdout_and_format_prefixes_are_named_as_what_animate_does_not_write(files, output):
    """``gif:-`` was "cannot tell the animation format" (the format was given), and ``gif:o.gif``
    wrote a file named ``gif:o.gif``."""
    out = run("swirl", str(files / "in.png"), output.format(dir=files), "--vary", "angle=0:90", "--frames", "2")
    assert out.code == 2 and "an animation is written to a file, its format from its extension" in out.stderr
    assert not list(files.glob("gif:*"))


def test_video(files):
    """An .mp4 is written through OpenCV's video writer."""
    out = run("bulge", str(files / "in.png"), str(files / "out.mp4"), "-m", str(files / "mask.png"),
              "--vary", "strength=0:1", "--frames", "4")
    assert out.code == 0, out.stderr
    video = cv2.VideoCapture(str(files / "out.mp4"))
    assert int(video.get(cv2.CAP_PROP_FRAME_COUNT)) == 4


def test_each_frames_compromises_are_said_with_its_number_and_the_rest_counted(files, monkeypatch):
    """What a frame could not do is a warning naming the frame (a coarse --cell strays from
    the warp in every moving frame; the first frame does not move); past FRAME_WARNINGS
    lines, one line counts the rest; ``--strict`` writes nothing."""
    from featurewarp_cli.app import animate

    args = ["swirl", str(files / "in.png"), str(files / "cell.gif"), "-m", str(files / "mask.png"),
            "--vary", "angle=0:90", "--frames", "4", "--cell", "60"]
    out = run(*args)
    assert out.code == 0, out.stderr
    strays = [line for line in out.stderr.splitlines() if "strays up to" in line]
    assert [line.split(": ")[3] for line in strays] == ["frame 1", "frame 2", "frame 3"], out.stderr
    monkeypatch.setattr(animate, "FRAME_WARNINGS", 1)
    counted = run(*args).stderr.splitlines()
    assert "frame 1: " in counted[0] and "more warning lines in frames 1 to 3 (one may count several features" in counted[-1]
    args[2] = str(files / "strict.gif")
    strict = run(*args, "--strict")                     # the first frame's compromise refuses the whole
    assert strict.code == 1 and "--strict: frame 1: " in strict.stderr and not (files / "strict.gif").exists()


def test_a_preset_with_nothing_to_vary_says_so(files):
    """perspective's corners are pairs: the errors listed what can vary as an empty list."""
    for vary in ("tl=0:1", "tx=0:1"):
        out = run("perspective", str(files / "in.png"), str(files / "bad.gif"), "--vary", vary)
        assert out.code == 2 and "perspective has no parameter that can vary" in out.stderr, out.stderr


@pytest.mark.parametrize("vary,message", [("angle", "NAME=START:END"), ("spin=0:1", "no parameter 'spin'"),
                                          ("angel=0:1", "did you mean 'angle'? it can vary: angle, radius"),
                                          ("center=0:1", "cannot vary (it can: angle, radius)"),
                                          ("angle=0:nan", "finite")])
def test_bad_vary_is_a_usage_error(files, vary, message):
    """A malformed --vary, an unknown parameter or a bad value: one line, exit 2, no file."""
    out = run("swirl", str(files / "in.png"), str(files / "bad.gif"), "--vary", vary)
    assert out.code == 2
    assert message in out.stderr and len(out.stderr.strip().splitlines()) == 1
    assert not (files / "bad.gif").exists()


def test_unknown_format_is_a_usage_error(files):
    """An output whose animation format cannot be told: exit 2."""
    out = run("swirl", str(files / "in.png"), str(files / "out.jpg"), "--vary", "angle=0:90")
    assert out.code == 2 and "animation format" in out.stderr


def test_a_parameter_varied_twice_and_a_sequence_name_python_cannot_fill_are_usage_errors(files):
    """The second --vary of a parameter silently won; ``%n`` beside ``%d`` was a raw TypeError."""
    out = run("swirl", str(files / "in.png"), str(files / "v.gif"), "--vary", "angle=0:90", "--vary", "angle=0:9")
    assert out.code == 2 and "angle is given twice" in out.stderr
    out = run("swirl", str(files / "in.png"), str(files / "f-%d%n.png"), "--vary", "angle=0:90", "--frames", "2")
    assert out.code == 2 and "one %d field" in out.stderr and len(out.stderr.strip().splitlines()) == 1
    assert not list(files.glob("f-*")) and not (files / "v.gif").exists()
    for name in ("s-%s.png", "s-%05i.png"):        # one APNG was written under that very name
        out = run("swirl", str(files / "in.png"), str(files / name), "--vary", "angle=0:90", "--frames", "2")
        assert out.code == 2 and "one %d field" in out.stderr and not list(files.glob("s-*"))
    out = run("swirl", str(files / "in.png"), str(files / "50%sale.gif"), "--vary", "angle=0:90", "--frames", "2")
    assert out.code == 0 and (files / "50%sale.gif").exists()          # a percent sign in a name stays one


def test_frames_that_would_not_fit_the_memory_limit_are_refused_before_any_is_made(files):
    """Every frame is held until the animation is encoded: --frames times the canvas beyond
    --max-memory is one line and exit 1, at once (10^8 frames used to build 10^8 parameter sets,
    then a MemoryError traceback)."""
    args = ["swirl", str(files / "in.png"), str(files / "big.gif"), "--vary", "angle=0:90", "--frames"]
    out = run(*args, "300", "--max-memory", "20M")
    assert out.code == 1 and "300 frames of 250x180 need about" in out.stderr, out.stderr
    assert "(--max-memory)" in out.stderr and len(out.stderr.strip().splitlines()) == 1
    out = run(*args, "100000000")
    assert out.code == 2 and "--frames" in out.stderr and len(out.stderr.strip().splitlines()) == 1
    assert not (files / "big.gif").exists()


def test_strict_refuses_an_empty_mask_before_any_frame(files, tmp_path):
    cv2.imwrite(str(tmp_path / "empty.png"), np.zeros((180, 250), np.uint8))
    out = run("swirl", str(files / "in.png"), str(tmp_path / "e.gif"), "-m", str(tmp_path / "empty.png"),
              "--vary", "angle=0:90", "--frames", "3", "--strict")
    assert out.code == 1 and "--strict: the mask marks no feature" in out.stderr
    assert not (tmp_path / "e.gif").exists()


def test_no_frame_replaces_the_mask_and_a_sequence_is_written_all_or_nothing(files, tmp_path):
    """An OUTPUT (or a sequence's frame) naming the mask replaced it with exit 0; a directory in
    the way of frame 2 failed with a raw ValueError after frames 0 and 1 were replaced; a
    200-million-digit frame number was a 200 MB error line after every frame was made."""
    mask = tmp_path / "f-0001.png"
    mask.write_bytes((files / "mask.png").read_bytes())
    before = mask.read_bytes()
    for output in (mask, tmp_path / "f-%04d.png"):
        out = run("swirl", str(files / "in.png"), str(output), "-m", str(mask), "--vary", "angle=0:90", "--frames", "3")
        assert out.code == 2 and "is also --mask" in out.stderr and mask.read_bytes() == before, out.stderr
    (tmp_path / "h-0002.png").mkdir()
    (tmp_path / "h-0000.png").write_bytes(b"old")
    out = run("swirl", str(files / "in.png"), str(tmp_path / "h-%04d.png"), "--vary", "angle=0:90", "--frames", "4")
    assert out.code == 2 and "h-0002.png is a directory" in out.stderr and "ValueError" not in out.stderr
    assert (tmp_path / "h-0000.png").read_bytes() == b"old"
    out = run("swirl", str(files / "in.png"), str(tmp_path / "o-%0200000000d.png"), "--vary", "angle=0:90")
    assert out.code == 2 and "longer than a file system allows" in out.stderr and len(out.stderr) < 300
    source = tmp_path / "g-0001.png"                       # a frame named like INPUT: refused too
    source.write_bytes((files / "in.png").read_bytes())
    out = run("swirl", str(source), str(tmp_path / "g-%04d.png"), "--vary", "angle=0:90", "--frames", "3")
    assert out.code == 2 and "is also INPUT" in out.stderr and source.read_bytes() == (files / "in.png").read_bytes()
    out = run("stretch", str(files / "in.png"), str(tmp_path / "wide.webp"), "--vary", "sx=70:80", "--frames", "2")
    assert out.code == 2 and "webp holds at most 16383" in out.stderr and not (tmp_path / "wide.webp").exists()


def test_a_sub_pixel_automatic_cell_is_the_animations_grid(files, monkeypatch):
    """The finest automatic cell over the frames went back in as a given --cell, refused below
    1 px: a swirl 540 on a 256 px image stopped with "cell must be ... at least 1, not
    0.9999999999999997", a cell the user never gave (the rule's own may be sub-pixel)."""
    from featurewarp_cli.engine import fidelity

    rule = fidelity.auto_cell
    monkeypatch.setattr(fidelity, "auto_cell", lambda w, h, warp=None: (min(rule(w, h, warp)[0], 0.75), 0.0))
    out = run("swirl", str(files / "in.png"), str(files / "sub.png"), "-m", str(files / "mask.png"),
              "--vary", "angle=0:30", "--frames", "2", "-v")
    assert out.code == 0, out.stderr


def test_the_automatic_cells_ladder_is_exact():
    """4 px / sqrt(2)^4 came out 1 - 3e-16: below the 1 px a given --cell must reach."""
    from featurewarp_cli import load_warp
    from featurewarp_cli.engine import fidelity

    cell = fidelity.auto_cell(256, 256, load_warp("swirl")(256, 256, angle=540))[0]
    rung = round(2 * np.log2(fidelity.base_cell(256, 256) / cell))
    assert cell == fidelity.base_cell(256, 256) * 2.0 ** -(rung // 2) / np.sqrt(2.0) ** (rung % 2)
    assert rung % 2 or cell == fidelity.base_cell(256, 256) / 2 ** (rung // 2)


def test_the_animations_automatic_grid_is_held_to_the_memory_budget(files):
    """Set as the warper's cell, the finest automatic cell skipped the budget a solve checks."""
    out = run("swirl", str(files / "in.png"), str(files / "big.gif"), "-m", str(files / "mask.png"),
              "--vary", "angle=400:450", "--frames", "2", "--max-memory", "20M")
    assert out.code == 1 and "that the memory limit allows" in out.stderr, out.stderr
    assert not (files / "big.gif").exists()


def test_an_animation_at_rest_is_said_once_not_as_a_frames(files):
    """'frame 4: no frame moves a pixel' read as though one frame were at rest; --strict refuses it."""
    args = ["stretch", str(files / "in.png"), str(files / "rest.gif"), "--vary", "sx=1:1", "--frames", "3"]
    out = run(*args)
    assert out.code == 0 and ": no frame moves a pixel: every frame is the input" in out.stderr
    assert "frame 2: no frame" not in out.stderr
    args[2] = str(files / "rest_strict.gif")
    strict = run(*args, "--strict")
    assert strict.code == 1 and "--strict: no frame moves a pixel" in strict.stderr
    assert not (files / "rest_strict.gif").exists()


def test_a_frame_written_with_folds_under_allow_folds_is_said(files):
    """warp --allow-folds says 'N triangles of the mesh fold over'; animate counted a frame's
    folds and said nothing (not even under -v): a folded animation passed as a clean one."""
    out = run("swirl", str(files / "in.png"), str(files / "folds.gif"), "-m", str(files / "mask.png"),
              "--vary", "angle=0:540", "--frames", "3", "--radius", "1", "--cell", "120", "--allow-folds")
    assert out.code == 0, out.stderr
    folded = [line for line in out.stderr.splitlines() if "triangles of the mesh fold over" in line]
    assert folded and all(": frame " in line for line in folded), out.stderr

"""featurewarp animate's files: the GIF's palette, alpha and timing, the APNG's delays, the
background of every format, the metadata kept, odd video sizes, and what a frame's error says."""

import struct

import cv2
import numpy as np
import pytest
from PIL import Image, ImageCms, ImageSequence

from samples import scenes
from test_cli import Runner


def run(*args):
    """``featurewarp ARGS`` in-process: exit code and stderr as the console script's."""
    return Runner()(*args)


#: An sRGB profile (made once: it holds the time it was made).
PROFILE = ImageCms.ImageCmsProfile(ImageCms.createProfile("sRGB")).tobytes()


@pytest.fixture(scope="module")
def files(tmp_path_factory):
    """The test scene at 250x180 (in.png, mask.png), with an sRGB profile (icc.png), in grey
    (grey.png), as flat colours (flat.png), with an alpha ramp (ramp.png) and at 251x181 (odd.png)."""
    folder = tmp_path_factory.mktemp("animf")
    image, mask = scenes.scene()
    image, mask = image[::2, ::2], mask[::2, ::2]
    cv2.imwrite(str(folder / "in.png"), image)
    cv2.imwrite(str(folder / "mask.png"), mask.astype(np.uint8) * 255)
    Image.fromarray(image[:, :, ::-1]).save(folder / "icc.png", icc_profile=PROFILE)
    cv2.imwrite(str(folder / "grey.png"), cv2.cvtColor(image, cv2.COLOR_BGR2GRAY))
    flat = np.full_like(image, 255)
    flat[mask] = (0, 200, 255)                       # BGR of #ffc800, a logo colour outside OpenCV's cube
    cv2.imwrite(str(folder / "flat.png"), flat)
    ramp = cv2.cvtColor(image, cv2.COLOR_BGR2BGRA)
    ramp[:, :, 3] = np.linspace(0, 255, image.shape[1]).round().astype(np.uint8)[None, :]
    cv2.imwrite(str(folder / "ramp.png"), ramp)
    cv2.imwrite(str(folder / "odd.png"), cv2.copyMakeBorder(image, 0, 1, 0, 1, cv2.BORDER_REPLICATE))
    cv2.imwrite(str(folder / "odd_mask.png"), cv2.copyMakeBorder(mask.astype(np.uint8) * 255, 0, 1, 0, 1,
                                                                 cv2.BORDER_REPLICATE))
    return folder


def animate(files, preset, source, output, *extra):
    out = run("animate", preset, str(files / source), str(files / output), "-m", str(files / "mask.png"), *extra)
    assert out.code == 0, out.stderr
    return out


def gif_frames(path, mode="RGB") -> list[np.ndarray]:
    with Image.open(path) as image:
        return [np.asarray(frame.convert(mode)) for frame in ImageSequence.Iterator(image)]


def test_a_gif_has_the_still_gifs_adaptive_palette(files):
    """OpenCV's fixed 8x8x4 cube with dithering put frame 0 of an identity swirl 19.7 levels
    RMS off the input, coloured a grey photo and checkered a flat logo colour: each frame now
    has the still GIF's palette (warp's), so frame 0 at angle 0 is the still GIF of the input,
    a grey input stays grey and exact, and flat colours stay flat."""
    animate(files, "swirl", "in.png", "a.gif", "--vary", "angle=0:90", "--frames", "3")
    assert run("warp", "swirl", str(files / "in.png"), str(files / "still.gif"), "-m", str(files / "mask.png"),
               "--angle", "0").code == 0
    frames, source = gif_frames(files / "a.gif"), cv2.imread(str(files / "in.png"))[:, :, ::-1]
    assert len(frames) == 3 and np.array_equal(frames[0], gif_frames(files / "still.gif")[0])
    assert np.sqrt(np.mean((frames[0].astype(float) - source) ** 2)) < 8
    animate(files, "bulge", "grey.png", "g.gif", "--vary", "strength=0:0.5", "--frames", "3")
    grey = gif_frames(files / "g.gif")
    assert all(np.array_equal(f[:, :, 0], f[:, :, 1]) and np.array_equal(f[:, :, 0], f[:, :, 2]) for f in grey)
    assert np.array_equal(grey[0][:, :, 0], cv2.imread(str(files / "grey.png"), cv2.IMREAD_GRAYSCALE))
    animate(files, "swirl", "flat.png", "f.gif", "--vary", "angle=0:90", "--frames", "2")
    assert np.array_equal(gif_frames(files / "f.gif")[0], cv2.imread(str(files / "flat.png"))[:, :, ::-1])


def test_a_gifs_background_is_white_and_transparent_cuts_alpha_at_half(files):
    """The GIF's background was transparent where the help and warp say white, and any alpha
    of 1 or more was opaque (a hard rim round soft edges): white by default, the input's alpha
    laid over it; with --background transparent a pixel is transparent where alpha < 128."""
    ramp = cv2.imread(str(files / "ramp.png"), cv2.IMREAD_UNCHANGED)
    animate(files, "arc", "ramp.png", "w.gif", "--vary", "angle=60:120", "--frames", "2")
    white = gif_frames(files / "w.gif", "RGBA")
    assert all(f[:, :, 3].min() == 255 for f in white) and tuple(white[-1][0, 0]) == (255, 255, 255, 255)
    animate(files, "swirl", "ramp.png", "w0.gif", "--vary", "angle=0:90", "--frames", "2")
    assert gif_frames(files / "w0.gif")[0][:, 0].min() >= 250     # alpha 0 over white, not the colour under it
    animate(files, "swirl", "ramp.png", "t.gif", "--vary", "angle=0:90", "--frames", "2", "--background",
            "transparent")
    first = gif_frames(files / "t.gif", "RGBA")[0]
    assert np.array_equal(first[:, :, 3] == 0, ramp[:, :, 3] < 128)
    # warp refused --background transparent for a GIF ("no alpha channel"): the still GIF of the
    # same swirl is the animation's first frame now, its transparency too
    still = run("warp", "swirl", str(files / "ramp.png"), str(files / "t0.gif"), "--angle", "0", "--background",
                "transparent")
    assert still.code == 0, still.stderr
    assert np.array_equal(gif_frames(files / "t0.gif", "RGBA")[0], first)


@pytest.mark.parametrize("fps", [7, 12, 30, 50])
def test_gif_delays_are_rounded_to_keep_time(fps, files):
    """Delays were cut down to 1/100 s (15 fps: 6 cs, 16.7 fps): each frame now ends at its
    time k/fps rounded to 1/100 s, so the animation runs at --fps on average."""
    animate(files, "swirl", "in.png", f"d{fps}.gif", "--vary", "angle=0:90", "--frames", "6", "--fps", str(fps))
    with Image.open(files / f"d{fps}.gif") as image:
        delays = [frame.info["duration"] for frame in ImageSequence.Iterator(image)]
    assert len(delays) == 6 and min(delays) >= 20
    assert sum(delays) == 10 * int(600 / fps + 0.5) and max(delays) - min(delays) <= 10


def test_a_gif_faster_than_50_fps_is_written_at_50_with_a_warning(files):
    """A 60 fps GIF got 1/100 s delays, which browsers play at 10 fps: 2/100 s and a warning."""
    out = animate(files, "swirl", "in.png", "d60.gif", "--vary", "angle=0:90", "--frames", "3", "--fps", "60")
    with Image.open(files / "d60.gif") as image:
        assert [frame.info["duration"] for frame in ImageSequence.Iterator(image)] == [20, 20, 20]
    assert "--fps 60: a GIF plays at most 50 frames a second" in out.stderr


def fctl_delays(path) -> list[tuple[int, int]]:
    data, found, at = path.read_bytes(), [], 0
    while (at := data.find(b"fcTL", at) + 1) > 0:
        found.append(struct.unpack(">HH", data[at + 23 : at + 27]))
    return found


@pytest.mark.parametrize("fps,delay", [(24, (1, 24)), (0.01, (100, 1)), (29.97, (100, 2997))])
def test_an_apngs_delay_is_the_fraction_of_its_fps(files, fps, delay):
    """round(1000/fps)/1000 s drifted (24 fps: 42/1000) and wrapped past 65.5 s (0.01 fps: 34.5 s)."""
    animate(files, "swirl", "in.png", f"p{fps}.png", "--vary", "angle=0:90", "--frames", "2", "--fps", str(fps))
    assert fctl_delays(files / f"p{fps}.png") == [delay, delay]


def test_video_has_no_transparent_background(files):
    """--background transparent with .mp4/.avi was a Python TypeError: one line, exit 2, no file."""
    for name in ("t.mp4", "t.avi"):
        out = run("animate", "arc", str(files / "in.png"), str(files / name), "-m", str(files / "mask.png"),
                  "--vary", "angle=30:120", "--frames", "2", "--background", "transparent")
        assert out.code == 2 and "video has no alpha channel; give a colour" in out.stderr, out.stderr
        assert len(out.stderr.strip().splitlines()) == 1 and not (files / name).exists()


@pytest.mark.parametrize("name,corner", [("h.png", (255, 0, 0, 128)), ("h.webp", (255, 0, 0, 128)),
                                         ("h-%d.png", (255, 0, 0, 128)), ("h.gif", (255, 128, 128, 255)),
                                         ("h.avi", (255, 128, 128, 255))])
def test_a_translucent_background_is_kept_or_laid_over_white(files, name, corner):
    """rgba(255,0,0,0.5) crashed every animate (a ValueError): kept where the format has alpha,
    laid over white where it has none, as warp and compare do."""
    animate(files, "arc", "in.png", name, "--vary", "angle=100:120", "--frames", "2",
            "--background", "rgba(255,0,0,0.5)")
    if name.endswith(".avi"):
        ok, frame = cv2.VideoCapture(str(files / name)).read()
        pixel = tuple(frame[2, 2, ::-1]) + (255,)
    else:
        with Image.open(files / name.replace("%d", "0")) as image:
            pixel = image.convert("RGBA").getpixel((0, 0))
    assert np.abs(np.subtract(pixel, corner)).max() <= (8 if name.endswith(".avi") else 1), pixel


@pytest.mark.parametrize("name", ["i.png", "i.webp", "i-%d.png"])
def test_an_animation_keeps_the_inputs_profile_unless_strip(files, name):
    """APNG, WebP and a sequence dropped the input's ICC profile though --strip's help says it is kept."""
    animate(files, "swirl", "icc.png", name, "--vary", "angle=0:90", "--frames", "2")
    first = files / name.replace("%d", "1")
    with Image.open(first) as image:
        assert image.info.get("icc_profile") == PROFILE
    animate(files, "swirl", "icc.png", "s" + name, "--vary", "angle=0:90", "--frames", "2", "--strip")
    with Image.open(files / ("s" + name).replace("%d", "1")) as image:
        assert not image.info.get("icc_profile")


def test_a_gif_or_video_says_it_drops_the_profile(files):
    for name, kind in (("i.gif", "GIF output"), ("i.mp4", "MP4 video")):
        out = animate(files, "swirl", "icc.png", name, "--vary", "angle=0:90", "--frames", "2")
        assert f"{kind} keeps none of the input's ICC profile" in out.stderr, out.stderr


def test_a_frames_error_names_the_frame_and_its_varied_values(files):
    """The error blamed --radius 0.1325, which the user never gave and --vary forbids giving."""
    out = run("animate", "swirl", str(files / "in.png"), str(files / "e.gif"), "-m", str(files / "mask.png"),
              "--vary", "radius=0.5:0.01", "--angle", "540", "--frames", "5")
    assert out.code == 2 and len(out.stderr.strip().splitlines()) == 1, out.stderr
    assert "frame 3 (radius 0.1325 of --vary radius=0.5:0.01): " in out.stderr and "--radius" not in out.stderr


@pytest.mark.parametrize("given", [["--size", "100x100"], ["--width", "200"]])
def test_an_option_that_overrides_the_varied_one_is_refused(files, given):
    """--vary sx=1:2 with --size or --width wrote identical frames without a word."""
    out = run("animate", "stretch", str(files / "in.png"), str(files / "o.gif"), "-m", str(files / "mask.png"),
              "--vary", "sx=1:2", "--frames", "3", *given)
    assert out.code == 2 and f"the varied sx changes no frame: {given[0]} overrides it" in out.stderr, out.stderr
    assert not (files / "o.gif").exists()
    animate(files, "stretch", "in.png", "ok.gif", "--vary", "sx=1:2", "--frames", "2", "--height", "200")


def test_only_the_options_that_override_the_varied_one_are_named(files):
    """With --sy beside --size the error said "--sy or --size overrides it; drop --sy or --size",
    though dropping --sy changes nothing (review finding 12)."""
    out = run("animate", "stretch", str(files / "in.png"), str(files / "o.gif"), "-m", str(files / "mask.png"),
              "--vary", "sx=1:2", "--size", "100x100", "--sy", "1.5", "--frames", "3")
    assert out.code == 2 and "the varied sx changes no frame: --size overrides it; drop --size to vary sx" \
        in out.stderr, out.stderr
    error = out.stderr.strip().splitlines()[-1]
    assert "--sy" not in error and "--sy does nothing with --size" in out.stderr      # the notice: it does not
    both = run("animate", "stretch", str(files / "in.png"), str(files / "o.gif"), "-m", str(files / "mask.png"),
               "--vary", "sx=1:2", "--width", "100", "--size", "100x100", "--frames", "3")
    assert both.code == 2 and "--width and --size override it; drop --width and --size to vary sx" in both.stderr
    assert "an option given" not in both.stderr       # neither alone frees sx: it named neither


@pytest.mark.parametrize("name", ["odd.mp4", "odd.avi"])
def test_an_odd_sized_video_is_padded_with_the_background_not_cropped(files, name):
    out = run("animate", "bulge", str(files / "odd.png"), str(files / name), "-m", str(files / "odd_mask.png"),
              "--vary", "strength=0:0.5", "--frames", "2")
    assert out.code == 0, out.stderr
    ok, frame = cv2.VideoCapture(str(files / name)).read()
    assert ok and frame.shape == (182, 252, 3)
    assert frame[-1].mean() > 230 and frame[:, -1].mean() > 230           # a white row and column


def test_the_same_run_writes_the_same_bytes(files):
    for name in ("r1.gif", "r2.gif", "r1.png", "r2.png", "r1.webp", "r2.webp"):
        animate(files, "swirl", "ramp.png", name, "--vary", "angle=0:90", "--frames", "3", "--background",
                "transparent")
    for ext in ("gif", "png", "webp"):
        assert (files / f"r1.{ext}").read_bytes() == (files / f"r2.{ext}").read_bytes()


def test_a_16_bit_input_says_its_frames_have_8_bits(tmp_path):
    """animate wrote a 16-bit input's frames at 8 bits without a word, where warp keeps 16 and
    README called APNG lossless (smoke trial 2)."""
    import subprocess
    import sys

    from pathlib import Path

    image = cv2.imread(str(Path(__file__).resolve().parent.parent / "samples" / "shapes.png")).astype(np.uint16) * 257
    cv2.imwrite(str(tmp_path / "in.png"), image)
    run = subprocess.run([sys.executable, "-m", "featurewarp_cli", "animate", "swirl", str(tmp_path / "in.png"),
                          str(tmp_path / "a.png"), "--vary", "angle=0:90", "--frames", "2"],
                         capture_output=True, text=True, timeout=120)
    assert run.returncode == 0 and "16 bits a sample; the animation's frames have 8" in run.stderr

"""Hostile input, round two (issue 24): reads that must be bounded, values that must not overflow.

Each case runs the real command (stdin streams and devices are what is tested) and must end
within seconds with one line on stderr, the right exit code, and no file written.
"""

from __future__ import annotations

import json
import re
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from test_cli import listing, save, square_mask, textured

TIMEOUT = 30


def run(*args, stdin=None, input=None):
    return subprocess.run([sys.executable, "-m", "featurewarp_cli", *map(str, args)], stdin=stdin, input=input,
                          capture_output=True, timeout=TIMEOUT)


def one_line(result, code, *words):
    err = result.stderr.decode()
    assert result.returncode == code, (result.returncode, err)
    assert len(err.strip().splitlines()) == 1 and "Traceback" not in err, err
    for word in words:
        assert word in err, err


@pytest.fixture
def scene(tmp_path):
    return save(tmp_path / "in.png", textured()), save(tmp_path / "m.png", square_mask())


@pytest.mark.parametrize("device", ["/dev/zero", "/dev/urandom"])
@pytest.mark.parametrize("role", ["input", "mask"])
def test_an_endless_stream_on_stdin_is_refused_at_once(tmp_path, scene, device, role):
    image, mask = scene
    before = listing(tmp_path)
    args = ["warp", "swirl", "-", tmp_path / "o.png"] if role == "input" else \
           ["warp", "swirl", image, tmp_path / "o.png", "-m", "-"]
    with open(device, "rb") as stream:
        result = run(*args, stdin=stream)
    one_line(result, 1, "stdin is not an image")
    assert listing(tmp_path) == before


def test_a_stream_longer_than_the_budget_is_refused_while_read(tmp_path, scene):
    image, _ = scene
    data = Path(image).read_bytes() + bytes(24 << 20)
    result = run("warp", "swirl", "-", tmp_path / "o.png", "--max-memory", "16M", input=data)
    one_line(result, 1, "stdin", "--max-memory")
    assert not (tmp_path / "o.png").exists()


def test_a_device_as_a_mask_is_named_for_what_it_is(tmp_path, scene):
    image, _ = scene
    one_line(run("warp", "swirl", image, tmp_path / "o.png", "-m", "/dev/zero"), 2, "--mask", "/dev/zero",
             "not a regular file")
    one_line(run("warp", "swirl", image, tmp_path / "o.png", "-m", tmp_path), 2, "--mask", "directory")


@pytest.mark.parametrize("option,value", [
    ("--max-pixels", "18446744073709551615"),      # SIGABRT inside OpenCV before
    ("--scale-prior", "1e308"),                    # OverflowError before
    ("--center", "1e308%,0"),                      # a transparent image with exit 0 before
    ("--center", "1e308,1e308"),                   # 7 s, 1.2 GB and folds before
    ("--center", "200000,0"),
])
def test_values_that_overflow_are_usage_errors(tmp_path, scene, option, value):
    image, mask = scene
    one_line(run("warp", "swirl", image, tmp_path / "o.png", "-m", mask, option, value), 2, option)
    assert not (tmp_path / "o.png").exists()


def test_a_stream_on_stdin_still_works(tmp_path, scene):
    image, mask = scene
    result = run("warp", "swirl", "-", tmp_path / "o.png", "-m", mask, input=Path(image).read_bytes())
    assert result.returncode == 0, result.stderr.decode()
    assert (tmp_path / "o.png").stat().st_size > 0


def test_a_failing_device_leaves_every_file_as_it_was(tmp_path, scene):
    """--report on /dev/full: nothing is linked into place before the device has been written."""
    image, mask = scene
    out = tmp_path / "o.png"
    out.write_bytes(b"old")
    one_line(run("warp", "swirl", image, out, "-m", mask, "--report", "/dev/full"), 1, "/dev/full")
    assert out.read_bytes() == b"old"


def test_a_fifo_without_a_reader_is_an_error_within_a_bounded_wait(tmp_path, scene, monkeypatch):
    import os
    import time

    from click.testing import CliRunner

    from featurewarp_cli.cli.main import cli
    from featurewarp_cli.io import write

    image, mask = scene
    fifo = tmp_path / "pipe"
    os.mkfifo(fifo)
    monkeypatch.setattr(write, "FIFO_WAIT", 0.3)
    started = time.monotonic()
    result = CliRunner().invoke(cli, ["warp", "swirl", image, f"png:{fifo}", "-m", mask,
                                      "--report", str(tmp_path / "r.json")])
    assert result.exit_code == 1 and "no process reads this FIFO" in result.output and str(fifo) in result.output
    assert time.monotonic() - started < 10
    assert not (tmp_path / "r.json").exists()


@pytest.mark.parametrize("writer", ["opencv", "opencv-large", "pillow-exif"])
def test_tiff_in_tiff_out_is_a_tiff_both_libraries_read(tmp_path, writer):
    """A TIFF's "EXIF" is its whole first directory; its layout tags must not reach the output
    (it was written declaring float samples, and neither library read it back)."""
    import cv2
    from click.testing import CliRunner
    from PIL import Image

    from featurewarp_cli.cli.main import cli

    pixels = textured((400, 300)) if writer == "opencv-large" else textured()   # tags beyond the first 64 KiB
    source = tmp_path / "in.tif"
    if writer.startswith("opencv"):
        cv2.imwrite(str(source), pixels)
    else:
        exif = Image.Exif()
        exif[271] = "Camera maker"
        Image.fromarray(pixels[:, :, ::-1]).save(source, exif=exif)
    out = tmp_path / "out.tif"
    result = CliRunner().invoke(cli, ["warp", "swirl", str(source), str(out)])
    assert result.exit_code == 0 and "warning" not in result.output, result.output
    back = cv2.imread(str(out), cv2.IMREAD_UNCHANGED)
    assert back is not None and back.dtype == np.uint8 and back.shape == pixels.shape
    with Image.open(out) as image:
        image.load()
        assert image.mode == "RGB"
        if writer == "pillow-exif":
            assert image.getexif().get(271) == "Camera maker"


def test_only_the_largest_components_get_free_scales():
    """The scale set-up costs two solves per free component: the largest MAX_FREE_SCALES keep
    free scales, the others (specks) the preset's lambda R, so time stays bounded by the image."""
    from featurewarp_cli import FeatureWarper, load_warp
    from featurewarp_cli.engine import components

    node_component = np.array([-1, 0, 0, 1, 2, 2, 2, 3, 3, 3])
    np.testing.assert_array_equal(components.largest(node_component, 4, 2), [False, False, True, True])
    mask = np.zeros((240, 320), bool)
    mask[5::10, 5::10] = True                          # 768 specks
    mask[100:160, 120:200] = True                      # and one real feature
    warper = FeatureWarper(320, 240, mask)
    mesh = warper.solve(load_warp("stretch")(320, 240, sx=1.5))
    assert mesh.flips() == 0
    records = mesh.record.components
    assert len(records) > components.MAX_FREE_SCALES
    big = max(records, key=lambda c: c.quads)
    assert big.kept


def test_a_scribbled_curve_costs_what_the_grid_can_follow(tmp_path, monkeypatch):
    """A curve of 100 000 random points (a scribble 5 M px long at 1 MP: 23.8 GB and killed
    before) is sampled at most CURVE_SAMPLES_PER_CELL times per cell of the rigid grid, and
    the schema sees its well-formed polylines cut to their ends (jsonschema: 5 000 points/s)."""
    from click.testing import CliRunner

    from featurewarp_cli import schema
    from featurewarp_cli.cli.main import cli
    from featurewarp_cli.engine.deform import rigid_grid
    from featurewarp_cli.engine.handles import CURVE_SAMPLES_PER_CELL, Handles

    width, height = 96, 72
    line = np.random.default_rng(24).uniform(0, height - 1, (100_000, 2)).round(2).tolist()
    data = {"version": 1, "points": [{"from": [1, 1], "to": [1, 1]}],
            "curves": [{"from": line, "to": line}, {"from": [[5, 5], [50, 60]], "to": [[6, 5], [50, 61]]}]}
    seen = []
    check = schema.check
    monkeypatch.setattr(schema, "check", lambda kind, value: (seen.append(value), check(kind, value))[1])
    handles = Handles.from_dict(data, width, height)
    assert [len(curve["from"]) for curve in seen[0]["curves"]] == [2]
    grid = rigid_grid(width, height)
    sources, targets, _ = handles.constraints(grid, 2.0)
    assert len(sources) <= 1 + CURVE_SAMPLES_PER_CELL * (grid.nx - 1) * (grid.ny - 1) + 2 * len(handles.curves)
    (tmp_path / "h.json").write_text(json.dumps(data))
    image = save(tmp_path / "in.png", textured((width, height)))
    result = CliRunner().invoke(cli, ["deform", image, str(tmp_path / "o.png"), "--handles", str(tmp_path / "h.json")])
    assert result.exit_code == 0, result.output


@pytest.mark.parametrize("key", ["points", "curves"])
def test_more_handles_than_a_file_may_hold_is_one_line(tmp_path, key):
    """10 001 point handles or curves: one line naming the file, exit 2 (490 000 pins in
    16 MiB took 2.2 GB before)."""
    from featurewarp_cli.engine.handles import MOST

    grid = np.stack(np.meshgrid(np.arange(101), np.arange(100)), -1).reshape(-1, 2)[: MOST[key] + 1].tolist()
    items = ([{"from": p, "to": p} for p in grid] if key == "points" else
             [{"from": [p, [p[0], p[1] + 0.5]], "to": [p, [p[0], p[1] + 0.5]]} for p in grid])
    (tmp_path / "h.json").write_text(json.dumps({"version": 1, key: items}))
    image = save(tmp_path / "in.png", textured((120, 110)))
    result = run("deform", image, tmp_path / "o.png", "--handles", tmp_path / "h.json")
    one_line(result, 2, "h.json", f"{key}: {MOST[key] + 1}", f"at most {MOST[key]}")
    assert not (tmp_path / "o.png").exists()


def test_the_schema_and_the_counts_agree_and_a_bad_point_far_down_is_named():
    from featurewarp_cli import schema
    from featurewarp_cli.engine.handles import MOST, Handles

    properties = json.loads(schema.text("handles"))["properties"]
    assert {key: properties[key]["maxItems"] for key in MOST} == MOST
    line = [[float(k % 90), float(k % 70)] for k in range(9000)]
    line[8765] = [3, True]
    with pytest.raises(ValueError, match=r"^curves\[0\]\.from\[8765\]\[1\]: expected a number, got true"):
        Handles.from_dict({"version": 1, "curves": [{"from": line, "to": line[:2]}]}, 96, 72)


def _odd_inputs(folder) -> dict:
    """Unusual but valid (or slightly broken) files: {name: path}."""
    import io
    import struct
    import zlib

    from PIL import Image, ImageCms

    y, x = np.mgrid[0:36, 0:48]
    rgb = np.dstack([x * 5 % 256, y * 7 % 256, (x + y) * 3 % 256]).astype(np.uint8)
    srgb = ImageCms.ImageCmsProfile(ImageCms.createProfile("sRGB")).tobytes()
    files = {}

    def keep(name, image, **options):
        files[name] = str(folder / name)
        image.save(files[name], **options)

    keep("16bit.png", Image.fromarray((x * 1300).astype(np.uint16)))
    keep("palette-trns.png", Image.fromarray(np.dstack([rgb, (x * 5).astype(np.uint8)])).quantize(16))
    keep("cmyk-profile.jpg", Image.fromarray(rgb).convert("CMYK"), icc_profile=srgb[:16] + b"CMYK" + srgb[20:])
    keep("grey-rgb-profile.png", Image.fromarray(rgb).convert("L"), icc_profile=srgb)
    camera = Image.Exif()
    camera[271] = "Camera maker"
    camera.get_ifd(0x8769)[0x829A] = 0.01                  # exposure time, in the Exif sub-directory
    camera.get_ifd(0x8825)[1] = "N"                        # GPS
    keep("camera.jpg", Image.fromarray(rgb), exif=camera)
    png = io.BytesIO()
    Image.fromarray(rgb).save(png, "PNG")
    data = png.getvalue()
    at = data.index(b"IDAT") - 4

    def chunk(kind, payload):
        return struct.pack(">I", len(payload)) + kind + payload + struct.pack(">I", zlib.crc32(kind + payload))

    for name, extra in (("bad-iccp.png", chunk(b"iCCP", b"p\x00\x00" + zlib.compress(b"junk" * 20))),
                        ("bad-exif.png", chunk(b"eXIf", b"MM\x00\x2a\x00\x00\x00\x08\x00\x05" + bytes(7)))):
        files[name] = str(folder / name)
        (folder / name).write_bytes(data[:at] + extra + data[at:])
    files["truncated.png"] = str(folder / "truncated.png")
    (folder / "truncated.png").write_bytes(data[: len(data) * 2 // 3])
    return files


def test_unusual_inputs_say_nothing_or_one_line_of_ours(tmp_path, capfd):
    """16-bit, palette with transparency, CMYK with its profile, broken chunks, a camera's
    EXIF, a truncated file: no Python warning, nothing of a C library on stderr, at most one
    line of ours. A camera JPEG written as TIFF failed (libtiff: 'Bad LONG8 or IFD8 value'
    and a RuntimeError); a CMYK JPEG's profile was kept on the RGB pixels it decodes to."""
    import warnings

    import cv2
    from click.testing import CliRunner
    from PIL import Image

    from featurewarp_cli.cli.main import cli

    capfd.readouterr()
    for name, path in _odd_inputs(tmp_path).items():
        for ext in ("png", "tif", "jpg"):
            out = tmp_path / f"out.{ext}"
            with warnings.catch_warnings(record=True) as caught:
                warnings.simplefilter("always")
                result = CliRunner().invoke(cli, ["warp", "swirl", path, str(out)])
            assert not caught, (name, ext, [str(w.message) for w in caught])
            assert capfd.readouterr().err == "", (name, ext)
            if name == "truncated.png":
                assert result.exit_code == 1 and len(result.output.strip().splitlines()) == 1, result.output
                continue
            assert result.exit_code == 0, (name, ext, result.output)
            if name == "cmyk-profile.jpg":    # its "CMYK" profile is sRGB's with the header changed: refused
                lines = result.output.strip().splitlines()
                assert len(lines) == 1 and "CMYK without a colour profile" in lines[0], (ext, result.output)
            elif name == "16bit.png" and ext == "jpg":
                assert result.output.endswith("the input has 16 bits a sample; JPEG holds 8 (PNG and TIFF keep 16)\n")
            else:
                assert result.output == "", (name, ext, result.output)
            assert cv2.imread(str(out), cv2.IMREAD_UNCHANGED) is not None
            with Image.open(out) as image:
                image.load()
                profile = image.info.get("icc_profile")
                assert not profile or profile[16:20] == (b"GRAY" if image.mode in ("L", "I;16") else b"RGB "), name
                if name == "camera.jpg":
                    assert image.getexif().get(271) == "Camera maker"


def _zlib_bomb(width: int, height: int) -> bytes:
    """A valid grey PNG of zeros: 7 KB for 4 000 x 4 000 (the issue's 14 100 x 14 100 was 580 KB)."""
    import struct
    import zlib

    def chunk(kind, data):
        return struct.pack(">I", len(data)) + kind + data + struct.pack(">I", zlib.crc32(kind + data))

    packer = zlib.compressobj(9)
    row = bytes(width + 1)
    data = b"".join(packer.compress(row) for _ in range(height)) + packer.flush()
    return (b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", struct.pack(">IIBBBBB", width, height, 8, 0, 0, 0, 0))
            + chunk(b"IDAT", data) + chunk(b"IEND", b""))


def test_within_limit_bombs_are_refused_before_decoding(tmp_path, monkeypatch):
    """The default --max-pixels (160 MP) refuses the issue's bombs from their headers; a bomb
    within it is refused by --max-memory before a pixel is decoded (a 4 KB AVIF of 14 000^2
    decoded to 3.3 GB before a 2 GB budget refused it), and so is the canvas a warp would
    need (the decoding thread starts once every check that needs no pixels has passed)."""
    import time

    from click.testing import CliRunner

    import bombs
    from featurewarp_cli.app import pipeline
    from featurewarp_cli.cli.main import cli
    from featurewarp_cli.io import limits

    assert limits.MAX_PIXELS == 160_000_000
    (tmp_path / "claims.png").write_bytes(bombs.png(14_100, 14_100))
    started = time.monotonic()
    one_line(run("warp", "swirl", tmp_path / "claims.png", tmp_path / "o.png"), 1, "above the limit", "--max-pixels")
    assert time.monotonic() - started < 10
    (tmp_path / "bomb.png").write_bytes(_zlib_bomb(4000, 4000))
    decoded = []
    monkeypatch.setattr(pipeline._Decoding, "start", lambda self: decoded.append(self))
    runner = CliRunner()
    for command, args, words in ((["warp"], ["--max-memory", "300M"], ("needs about 488 MiB", "--max-memory")),
                                 (["compare"], ["--max-memory", "300M"], ("needs about 488 MiB", "--max-memory")),
                                 (["warp"], ["--max-memory", "1G", "--size", "400%x100%"], ("canvas", "--max-memory"))):
        for source in (str(tmp_path / "bomb.png"), "-"):
            result = runner.invoke(cli, [*command, "stretch", source, str(tmp_path / "o.png"), *args],
                                   input=(tmp_path / "bomb.png").read_bytes())
            assert result.exit_code == 1 and all(word in result.output for word in words), (args, result.output)
            assert len(result.output.strip().splitlines()) == 1 and not decoded
    assert not (tmp_path / "o.png").exists()


@pytest.mark.parametrize("args,words", [
    (["swirl", "--angle", "720"], ["--angle", "out of range (-540 <= DEG <= 540)"]),
    (["swirl", "--angle", "-720"], ["--angle", "out of range (-540 <= DEG <= 540)"]),
    (["arc", "--where", "upper", "--angle", "160"], ["--angle", "out of range when --where is upper (at most 150)"]),
    (["perspective", "--tl", "45%,45%"], ["--tl", "the angle at --tl is 174 degrees (5 to 170)"]),
])
def test_ranges_that_took_too_long_are_usage_errors(tmp_path, scene, args, words):
    """Swirl +-720 took 18-44 s CPU at 0.08 to 1 MP (80-120 s wall), its features wound past
    recognition and relaxed to the plain warp; Arc Upper and Lower at 170 took 34-60 s CPU and
    2.3 GB at 1 MP, perspective with a corner of 174 degrees 34 s: the ranges are +-540, 150 and
    corners of 5 to 170 degrees (at most 17, 11 and 5 s: benchmarks/extremes.py --1mp)."""
    image, mask = scene
    preset, *options = args
    one_line(run("warp", preset, image, tmp_path / "o.png", "-m", mask, *options), 2, *words)
    assert not (tmp_path / "o.png").exists()


@pytest.mark.parametrize("size", [(320, 240), (1024, 1024), (4000, 3000)])
@pytest.mark.parametrize("angle", [540, -540, 90])
def test_a_swirl_too_tight_for_the_grid_is_refused_and_the_tightest_accepted_is_followed(size, angle):
    """540 degrees over a 102 px radius at 1 MP folded 632 triangles of the finest automatic grid
    (exit 1 after the solve); now the warp is refused at once, naming the radius it needs, and
    at that radius the automatic grid follows it within 0.5 px without a fold."""
    import math

    from featurewarp_cli import load_warp
    from featurewarp_cli.engine import fidelity
    from featurewarp_cli.engine.grid import Grid

    width, height = size
    swirl = load_warp("swirl")
    with pytest.raises(ValueError, match=r"^angle: .* needs a swirl radius of .* use radius ([0-9.]+) or more") as err:
        swirl(width, height, angle=angle, radius=0.001)
    radius = float(re.search(r"use radius ([0-9.]+)", str(err.value)).group(1))
    warp = swirl(width, height, angle=angle, radius=radius)
    cell, error = fidelity.auto_cell(width, height, warp)
    assert fidelity.follows(Grid.for_image(width, height, cell), warp) == (True, error) and error <= 0.5
    limit = int(re.search(r"within \+-(\d+)", str(err.value)).group(1))
    swirl(width, height, angle=math.copysign(limit, angle), radius=0.001)


def _corrupt_tiff(tmp_path, compression: str, at: int):
    """An 80 x 60 TIFF whose strip data has 30 bytes flipped (XOR 0xa5) after its first ``at``."""
    import io

    from PIL import Image

    buffer = io.BytesIO()
    Image.fromarray(textured()[:60, :80, :3]).save(buffer, "TIFF", compression=compression)
    image = Image.open(io.BytesIO(buffer.getvalue()))
    start = image.tag_v2[273][0] + at                   # StripOffsets
    data = bytearray(buffer.getvalue())
    data[start:start + 30] = bytes(b ^ 0xA5 for b in data[start:start + 30])
    return save_bytes(tmp_path / f"{compression}.tif", bytes(data))


def save_bytes(path, data: bytes):
    path.write_bytes(data)
    return path


@pytest.mark.parametrize("compression, at", [("tiff_lzw", 40), ("tiff_adobe_deflate", 40), ("packbits", 0)])
def test_a_tiff_whose_strips_fail_to_decode_is_refused_not_warped_as_garbage(tmp_path, compression, at):
    """libtiff's errors reach featurewarp only through OpenCV's log: the corrupt strips decoded
    to pixels 64-84 grey levels off and the command exited 0 (PackBits: where a run's header
    overruns; a flipped byte inside a run, or in raw samples, no decoder can tell)."""
    one_line(run("warp", "swirl", _corrupt_tiff(tmp_path, compression, at), tmp_path / "o.png"), 1, "is corrupt: ")
    assert not (tmp_path / "o.png").exists()


def test_a_jpeg_of_too_many_scans_is_refused_before_decoding(tmp_path):
    """Each scan of a progressive JPEG is a pass over the image: 10 000 of them in 376 KB took 13 s."""
    import cv2

    ok, data = cv2.imencode(".jpg", textured(), [cv2.IMWRITE_JPEG_PROGRESSIVE, 1])
    data = data.tobytes()
    last = data.rindex(b"\xff\xda")                    # the last scan, repeated before the end marker
    scan = data[data.rindex(b"\xff\xc4", 0, last) if b"\xff\xc4" in data[:last] else last:-2]
    bomb = save_bytes(tmp_path / "scans.jpg", data[:-2] + scan * 600 + data[-2:])
    one_line(run("warp", "swirl", bomb, tmp_path / "o.png"), 1, "JPEG scans, above 500")
    assert run("warp", "swirl", save_bytes(tmp_path / "fine.jpg", data), tmp_path / "p.png").returncode == 0


@pytest.mark.parametrize("header, samples, dtype, top", [
    (b"P6\n4 2\n3\n", bytes([0, 1, 2, 3] * 6), np.uint8, 255),
    (b"P5\n# a comment\n4 2\n15\n", bytes([0, 15, 7, 8, 1, 2, 3, 4]), np.uint8, 255),
    (b"P6\n2 2\n1023\n", np.array([0, 1023, 512] * 4, ">u2").tobytes(), np.uint16, 65535),
    (b"P2\n4 1\n3\n", b"0 1 2 3\n", np.uint8, 255),               # the plain forms OpenCV scales itself:
    (b"P3\n2 1\n3\n", b"0 1 2 3 3 3\n", np.uint8, 255),           # not a second time (all 255),
    (b"P2\n3 1\n1000\n", b"0 500 1000\n", np.uint16, 65535)])     # but only up to MAXVAL 255
def test_a_pnm_whose_maxval_is_not_the_types_is_scaled_to_its_full_range(header, samples, dtype, top):
    """OpenCV keeps PNM samples as stored: MAXVAL 3 came out nearly black."""
    from featurewarp_cli.io.decode import decode_image

    image = decode_image(header + samples, "x.pnm")
    assert image.dtype == dtype and image.min() == 0 and image.max() == top
    assert len(np.unique(image)) > 2                                  # the levels between stay apart


def test_a_pam_of_maxval_zero_is_refused(tmp_path):
    pam = b"P7\nWIDTH 2\nHEIGHT 2\nDEPTH 1\nMAXVAL 0\nTUPLTYPE GRAYSCALE\nENDHDR\n" + bytes(4)
    one_line(run("warp", "swirl", save_bytes(tmp_path / "z.pam", pam), tmp_path / "o.png"), 1, "MAXVAL 0")


def test_a_tiff_whose_next_page_cannot_be_read_is_its_first_page(tmp_path):
    """libtiff's error about a next directory past the end is not corruption of the image (its
    pixels decode exactly): the page is warped, with the several-frames note."""
    import io
    import struct

    import cv2
    from PIL import Image

    buffer = io.BytesIO()
    Image.fromarray(textured()[:60, :80, :3]).save(buffer, "TIFF")
    data = bytearray(buffer.getvalue())
    ifd = struct.unpack_from("<I", data, 4)[0]
    entries = struct.unpack_from("<H", data, ifd)[0]
    struct.pack_into("<I", data, ifd + 2 + 12 * entries, len(data) + 1000)      # the next page: nowhere
    source = save_bytes(tmp_path / "next.tif", bytes(data))
    result = run("warp", "stretch", source, tmp_path / "o.png", "--sx", "1")
    assert result.returncode == 0, result.stderr
    assert np.array_equal(cv2.imread(str(tmp_path / "o.png")), cv2.imread(str(source)))


@pytest.mark.parametrize("depth", [np.uint8, np.uint16])
def test_a_tiff_with_alpha_says_so_and_reads_back_unpremultiplied(tmp_path, depth):
    """OpenCV wrote RGBA TIFFs without ExtraSamples (the fourth sample "unspecified" to libtiff
    and ImageMagick), and read 8-bit ones that have it (Pillow, GIMP, Photoshop) premultiplied:
    every half-transparent colour came out at half its value."""
    import io

    from PIL import Image

    from featurewarp_cli.io.decode import decode_image
    from featurewarp_cli.io.encode import encode_image

    top = np.iinfo(depth).max
    pixels = (np.random.default_rng(8).integers(0, 256, (20, 30, 4)) * (top // 255)).astype(depth)
    pixels[..., 3] = top // 2 + 1
    written = encode_image(pixels, "tiff")
    with Image.open(io.BytesIO(written)) as image:
        assert image.tag_v2.get(338) == (2,)                  # unassociated alpha
    level = 257 if depth == np.uint16 else 1
    assert np.abs(decode_image(written, "ours.tif").astype(int) - pixels).max() <= level
    if depth == np.uint8:                                     # what other programs write, read exactly
        buffer = io.BytesIO()
        Image.fromarray(pixels[..., [2, 1, 0, 3]]).save(buffer, "TIFF")
        assert np.array_equal(decode_image(buffer.getvalue(), "theirs.tif"), pixels)
        faint = pixels.copy()
        faint[..., 3] = 3                                     # alpha 3: a division back would lose colours
        assert np.array_equal(decode_image(encode_image(faint, "tiff"), "faint.tif"), faint)


def test_a_16_bit_tiff_of_associated_alpha_is_read_with_straight_colours(tmp_path):
    """Associated alpha is stored premultiplied; OpenCV's 16-bit reading keeps it so."""
    import struct

    from featurewarp_cli.io import tiff
    from featurewarp_cli.io.decode import decode_image
    from featurewarp_cli.io.encode import encode_image

    straight = np.zeros((4, 5, 4), np.uint16)
    straight[...] = (51400, 38550, 25700, 32768)
    stored = straight.copy()
    stored[..., :3] = np.rint(straight[..., :3] * (32768 / 65535)).astype(np.uint16)
    data = bytearray(encode_image(stored, "tiff"))            # ExtraSamples 2: make it 1 (associated)
    order, first, entries, _ = tiff.first_directory(bytes(data))
    at = next(first + 2 + 12 * k for k, e in enumerate(entries) if struct.unpack_from(order + "H", e)[0] == 338)
    struct.pack_into(order + "H", data, at + 8, tiff.ASSOCIATED)
    assert np.abs(decode_image(bytes(data), "assoc.tif").astype(int) - straight).max() <= 2


def test_a_gray_tiff_with_alpha_keeps_its_alpha():
    """OpenCV reads gray + alpha TIFFs as gray alone: the transparency was lost."""
    import io

    from PIL import Image

    from featurewarp_cli.io.decode import decode_image

    pixels = np.dstack([np.full((6, 7), 100, np.uint8), np.full((6, 7), 128, np.uint8)])
    buffer = io.BytesIO()
    Image.fromarray(pixels, "LA").save(buffer, "TIFF")
    image = decode_image(buffer.getvalue(), "la.tif")
    assert image.shape == (6, 7, 4) and np.all(image[0, 0] == (100, 100, 100, 128))


def test_pillows_own_log_lines_on_a_hostile_header_stay_off_stderr(tmp_path):
    """A TIFF claiming 9 999 samples a pixel made Pillow log "More samples per pixel than can be
    decoded" five times on stderr before our one line."""
    import io
    import struct

    from PIL import Image

    buffer = io.BytesIO()
    Image.fromarray(np.zeros((4, 4, 3), np.uint8)).save(buffer, "TIFF")
    data = bytearray(buffer.getvalue())
    first = struct.unpack_from("<I", data, 4)[0]
    for k in range(struct.unpack_from("<H", data, first)[0]):
        if struct.unpack_from("<H", data, first + 2 + 12 * k)[0] == 277:          # SamplesPerPixel
            struct.pack_into("<H", data, first + 2 + 12 * k + 8, 9999)
    one_line(run("warp", "swirl", save_bytes(tmp_path / "spp.tif", bytes(data)), tmp_path / "o.png"), 1,
             "cannot be decoded")


def test_a_png_whose_metadata_pillow_refuses_is_still_measured_before_decoding(tmp_path):
    """A zTXt chunk over Pillow's text limit made the header unreadable, the size checks were
    skipped, and a 422 KB file was decoded to 432 MB under --max-memory 100M: the size comes
    from IHDR, which is at a fixed place."""
    import struct
    import zlib

    from featurewarp_cli.io import decode

    def chunk(kind, data):
        return struct.pack(">I", len(data)) + kind + data + struct.pack(">I", zlib.crc32(kind + data))

    width = height = 4000
    rows = zlib.compress(b"\0" * (1 + 3 * width) * height, 9)
    text = chunk(b"zTXt", b"Comment\0\0" + zlib.compress(b"A" * (2 << 20), 9))
    data = (b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", struct.pack(">IIBBBBB", width, height, 8, 2, 0, 0, 0)) + text
            + chunk(b"IDAT", rows) + chunk(b"IEND", b""))
    header = decode.read_header(data)
    assert (header.format, header.width, header.height) == ("PNG", width, height)
    (tmp_path / "sneaky.png").write_bytes(data)
    one_line(run("warp", "swirl", tmp_path / "sneaky.png", tmp_path / "o.png", "--max-memory", "20M"), 1,
             "4000x4000", "--max-memory")


def test_a_result_larger_than_the_output_format_holds_is_refused_before_the_work(tmp_path):
    """A stretch of a wide strip failed after the solve with "cannot encode the result as png":
    each format's largest side is checked once the canvas is known, before anything is decoded."""
    import cv2

    cv2.imwrite(str(tmp_path / "wide.png"), np.zeros((1, 40000), np.uint8))
    one_line(run("warp", "stretch", tmp_path / "wide.png", tmp_path / "o.webp", "--sx", "0.5"), 2,
             "20000x1", "webp holds at most 16383")
    assert not (tmp_path / "o.webp").exists()
    assert run("warp", "stretch", tmp_path / "wide.png", tmp_path / "o.png", "--sx", "0.3").returncode == 0
    one_line(run("compare", "stretch", tmp_path / "wide.png", tmp_path / "c.webp", "--sx", "0.3"), 2,
             "webp holds at most 16383")

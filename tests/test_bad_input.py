"""A catalogue of bad (and odd-but-valid) inputs.

Every refused input must give the right exit code (2: usage, 1: processing), a
single-line message on stderr naming the problem, no traceback, and must leave
the output folder exactly as it was (no new file, an existing OUTPUT untouched).
Odd inputs that are valid (1x1 images, 16-bit, palette, EXIF-rotated, odd masks,
Unicode paths) must simply work.
"""

from __future__ import annotations

import json
import os
import struct
import zlib
from pathlib import Path

import cv2
import numpy as np
import pytest

from featurewarp_cli.io import decode, encode, write
from test_cli import SIZE, listing, runner, save, square_mask, textured  # noqa: F401  (fixture)

# --- building odd files ---------------------------------------------------------------------


def png_bytes(pixels: np.ndarray, colour_type: int, chunks=(), size=None) -> bytes:
    """A PNG written by hand (for types OpenCV does not write: palette, gray + alpha).

    ``pixels`` is (h, w) or (h, w, c) uint8 or uint16 (stored big-endian); ``size``
    overrides the header's (width, height) to fake a huge image.
    """
    def chunk(kind: bytes, data: bytes) -> bytes:
        return struct.pack(">I", len(data)) + kind + data + struct.pack(">I", zlib.crc32(kind + data))

    h, w = pixels.shape[:2]
    depth = 16 if pixels.dtype == np.uint16 else 8
    raw = b"".join(b"\0" + row.astype(">u2" if depth == 16 else np.uint8).tobytes() for row in pixels)
    header = struct.pack(">IIBBBBB", *(size or (w, h)), depth, colour_type, 0, 0, 0)
    return (b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", header) + b"".join(chunk(k, d) for k, d in chunks)
            + chunk(b"IDAT", zlib.compress(raw)) + chunk(b"IEND", b""))


def jpeg_with_orientation(image: np.ndarray, orientation: int) -> bytes:
    """A JPEG of ``image`` carrying an EXIF orientation tag (big-endian EXIF block)."""
    jpg = encode.encode_image(image, "jpg")
    ifd = b"MM\x00\x2a\x00\x00\x00\x08" + struct.pack(">HHHIHH", 1, 0x0112, 3, 1, orientation, 0) + bytes(4)
    payload = b"Exif\x00\x00" + ifd
    return jpg[:2] + b"\xff\xe1" + struct.pack(">H", len(payload) + 2) + payload + jpg[2:]


def huge_jpeg() -> bytes:
    """A valid small JPEG whose frame header claims 30000 x 30000 pixels."""
    data = bytearray(encode.encode_image(textured(), "jpg"))
    sof = data.index(b"\xff\xc0")
    data[sof + 5 : sof + 9] = struct.pack(">HH", 30000, 30000)
    return bytes(data)


def corrupted(data: bytes, at: int, junk: bytes = b"x" * 40) -> bytes:
    """``data`` with the bytes from ``at`` on overwritten by ``junk``."""
    return data[:at] + junk + data[at + len(junk) :]


PNG = encode.encode_image(textured(), "png")
JPG = encode.encode_image(textured(), "jpg")


def lab_tiff() -> bytes:
    """A CIELab TIFF (photometric 8), which OpenCV decodes as if its L*, a*, b* were colours."""
    import io

    from PIL import Image

    out = io.BytesIO()
    Image.fromarray(cv2.cvtColor(textured(), cv2.COLOR_BGR2RGB)).convert("LAB").save(out, "TIFF")
    return out.getvalue()


def lab_tiff_16(kind=None) -> bytes:
    """A 16-bit CIELab TIFF, which Pillow cannot open (so its header says nothing) and OpenCV
    decodes to 8-bit RGB of the wrong colours; ``kind``: the photometric tag's field type (libtiff
    reads a LONG one too)."""
    from featurewarp_cli.io import tiff

    samples = textured().astype(np.uint16) * 257
    return tiff.with_tags(encode.encode_image(samples, "tiff"), {tiff.PHOTOMETRIC: (kind or tiff.SHORT, [8])})


#: Input files by name: their bytes.
FILES = {
    "ok.png": PNG,
    "mask.png": encode.encode_image(square_mask(), "png"),
    "small_mask.png": encode.encode_image(np.zeros((10, 10), np.uint8), "png"),
    "empty.png": b"",
    "empty.jpg": b"",
    "truncated.png": PNG[: len(PNG) // 2],
    "truncated.jpg": JPG[: len(JPG) // 2],
    "corrupt.png": corrupted(PNG, 100),
    # JPEG has no checksum: flipped bytes in the entropy-coded data decode silently to wrong
    # pixels. Detectable corruption: stray markers in the data, or a broken Huffman table.
    "corrupt.jpg": corrupted(JPG, len(JPG) // 2, b"\xff\xd0\xff\xd3"),
    "bad_header.jpg": corrupted(JPG, JPG.index(b"\xff\xc4") + 4, b"\xee" * 20),
    "text.png": b"This is a text file, not a PNG.\n",
    "noise.jpg": np.random.default_rng(1).integers(0, 256, 5000, dtype=np.uint8).tobytes(),
    "huge.png": png_bytes(np.zeros((2, 2), np.uint8), 0, size=(20000, 20000)),
    "huge.jpg": huge_jpeg(),
    "zero.png": png_bytes(np.zeros((2, 2), np.uint8), 0, size=(0, 5)),
    "lab.tif": lab_tiff(),
    "lab16.tif": lab_tiff_16(),
    "lab_long.tif": lab_tiff_16((4, "I")),
    "lab_byte.tif": lab_tiff_16((1, None)),
}

# (id, arguments, exit code, words the message must contain). {name} is a file of FILES,
# {out} the output (in its own folder), {dir} the input folder.
CASES = [
    # usage errors: exit 2
    ("missing input", "swirl {dir}/missing.png {out}", 2, ["missing.png", "does not exist"]),
    ("input is a folder", "swirl {dir} {out}", 2, ["is a directory"]),
    ("missing mask", "swirl {ok.png} {out} -m {dir}/nomask.png", 2, ["--mask", "does not exist"]),
    ("mask of another size", "swirl {ok.png} {out} -m {small_mask.png}", 2, ["--mask", "10x10", "48x36"]),
    # stdin is read once: the mask's error, not "stdin is empty" from reading it again
    ("stdin with a mask of another size", "swirl - {out} -m {small_mask.png}", 2, ["--mask", "10x10", "48x36"]),
    ("nan option", "swirl {ok.png} {out} --angle nan", 2, ["--angle", "not a finite number"]),
    ("inf option", "swirl {ok.png} {out} --feature-weight inf", 2, ["--feature-weight", "finite"]),
    ("-inf option", "swirl {ok.png} {out} --decay -inf", 2, ["--decay", "finite"]),
    ("out of preset range", "bulge {ok.png} {out} --strength 5", 2, ["--strength", "out of range"]),
    ("zero scale", "stretch {ok.png} {out} --sx 0", 2, ["--sx", "out of range"]),
    ("cell too small", "swirl {ok.png} {out} --cell 0.5", 2, ["--cell", "out of range (1 <= PX)"]),
    ("not a number", "swirl {ok.png} {out} --angle ninety", 2, ["--angle", "not a number"]),
    ("python's digit grouping", "swirl {ok.png} {out} --angle 1_0", 2, ["--angle", "'1_0' is not a number"]),
    ("digit grouping in a pair", "swirl {ok.png} {out} --center 5_0,10", 2, ["--center", "'5_0,10' is not X,Y"]),
    ("not a whole number", "stretch {ok.png} {out} --width 10.5", 2, ["--width", "whole number"]),
    ("max pixels zero", "swirl {ok.png} {out} --max-pixels 0", 2, ["--max-pixels", "out of range (1 <= N <= 1099511627776)"]),
    ("output folder missing", "swirl {ok.png} {dir}/nowhere/o.png", 2, ["nowhere", "does not exist"]),
    ("output is a folder", "swirl {ok.png} {dir}", 2, ["is a directory"]),
    ("unknown extension", "swirl {ok.png} {dir}/out/o.xyz", 2, ["OUTPUT", "unknown output format", ".xyz"]),
    ("no extension", "swirl {ok.png} {dir}/out/o", 2, ["OUTPUT", "no extension"]),
    ("prefix against --format", "swirl {ok.png} png:- --format jpg", 2, ["png", "jpg"]),
    ("mask and input both stdin", "swirl - {out} -m -", 2, ["--mask", "stdin"]),
    ("unknown preset", "twirl {ok.png} {out}", 2, ["unknown preset", "twirl", "swirl"]),
    ("bad colour", "swirl {ok.png} {out} --background notacolour", 2, ["--background", "not a colour"]),
    ("transparent jpeg", "swirl {ok.png} {dir}/out/o.jpg --background transparent", 2,
     ["--background", "no alpha"]),
    ("report folder missing", "swirl {ok.png} {out} --report {dir}/nowhere/r.json", 2,
     ["--report", "does not exist"]),
    ("unknown option", "swirl {ok.png} {out} --bogus 3", 2, ["--bogus"]),
    ("missing output argument", "swirl {ok.png}", 2, ["OUTPUT"]),
    # processing errors: exit 1
    ("empty png", "swirl {empty.png} {out}", 1, ["empty.png", "is empty"]),
    ("empty jpeg", "swirl {empty.jpg} {out}", 1, ["empty.jpg", "is empty"]),
    ("truncated png", "swirl {truncated.png} {out}", 1, ["truncated.png", "cannot be decoded"]),
    ("truncated jpeg", "swirl {truncated.jpg} {out}", 1, ["truncated.jpg"]),
    ("corrupt png", "swirl {corrupt.png} {out}", 1, ["corrupt.png", "cannot be decoded"]),
    ("corrupt jpeg", "swirl {corrupt.jpg} {out}", 1, ["corrupt.jpg", "is corrupt", "premature end"]),
    ("corrupt jpeg header", "swirl {bad_header.jpg} {out}", 1, ["bad_header.jpg", "cannot be decoded"]),
    ("text named png", "swirl {text.png} {out}", 1, ["text.png", "cannot be decoded"]),
    ("noise named jpg", "swirl {noise.jpg} {out}", 1, ["noise.jpg"]),
    ("huge png header", "swirl {huge.png} {out}", 1, ["20000x20000", "--max-pixels"]),
    ("huge jpeg header", "swirl {huge.jpg} {out}", 1, ["30000x30000", "--max-pixels"]),
    ("above --max-pixels", "swirl {ok.png} {out} --max-pixels 1000", 1, ["48x36", "--max-pixels"]),
    ("zero width header", "swirl {zero.png} {out}", 1, ["zero.png", "cannot be decoded", "IHDR"]),
    ("canvas above --max-pixels", "stretch {ok.png} {out} --sx 100 --sy 100 --max-pixels 100000", 1,
     ["output canvas", "4800x3600", "--max-pixels"]),
    ("corrupt mask", "swirl {ok.png} {out} -m {corrupt.png}", 1, ["--mask", "corrupt.png"]),
    ("empty mask file", "swirl {ok.png} {out} -m {empty.png}", 1, ["--mask", "is empty"]),
    ("lab tiff", "swirl {lab.tif} {out}", 1, ["lab.tif", "CIELab", "convert it to RGB"]),   # was wrong colours, exit 0
    ("16-bit lab tiff", "swirl {lab16.tif} {out}", 1, ["lab16.tif", "CIELab", "convert it to RGB"]),
    ("lab tiff, its tag a long", "swirl {lab_long.tif} {out}", 1, ["lab_long.tif", "CIELab"]),
    ("lab tiff, its tag a byte", "swirl {lab_byte.tif} {out}", 1, ["lab_byte.tif", "CIELab"]),
    # a mask's grey levels from L*a*b* are off too: greys 123-127 crossed 128, a 0/1 mask marked nothing
    ("lab tiff mask", "swirl {ok.png} {out} -m {lab.tif}", 1, ["--mask", "lab.tif", "CIELab"]),
]


@pytest.fixture
def inputs(tmp_path):
    """The FILES written into tmp_path/in, and an empty output folder tmp_path/in/out."""
    folder = tmp_path / "in"
    (folder / "out").mkdir(parents=True)
    paths = {"dir": str(folder), "out": str(folder / "out" / "o.png")}
    for name, data in FILES.items():
        (folder / name).write_bytes(data)
        paths[name] = str(folder / name)
    return paths


def fill(arg: str, paths: dict) -> str:
    """Replace ``{name}`` placeholders of a case's argument by paths."""
    for name, path in paths.items():
        arg = arg.replace("{" + name + "}", path)
    return arg


def check_refused(run, code, words):
    assert run.code == code, run.stderr
    assert len(run.lines) == 1, run.stderr
    line = run.lines[0]
    assert line.startswith("featurewarp: error: ") and "Traceback" not in run.stderr
    for word in words:
        assert word in line, line
    assert run.stdout == b""


@pytest.mark.parametrize("existing", [False, True], ids=["new", "existing"])
@pytest.mark.parametrize("args, code, words", [c[1:] for c in CASES], ids=[c[0] for c in CASES])
def test_refused(runner, inputs, args, code, words, existing):
    out_dir = os.path.join(inputs["dir"], "out")
    if existing:
        for name in ("o.png", "o.jpg"):
            with open(os.path.join(out_dir, name), "wb") as fh:
                fh.write(b"precious")
    before, folder = listing(Path(out_dir)), listing(Path(inputs["dir"]))
    stdin = FILES["ok.png"] if " - " in f" {args} " else None
    run = runner("warp", *[fill(a, inputs) for a in args.split()], input=stdin)
    check_refused(run, code, words)
    assert listing(Path(out_dir)) == before and listing(Path(inputs["dir"])) == folder


def test_catalogue_is_large_enough():
    assert len(CASES) >= 30


def test_stdin_errors(runner, tmp_path):
    check_refused(runner("warp", "swirl", "-", tmp_path / "o.png", input=b""), 1, ["stdin is empty"])
    check_refused(runner("warp", "swirl", "-", tmp_path / "o.png", input=b"garbage"), 1,
                  ["stdin", "cannot be decoded"])
    assert list(tmp_path.iterdir()) == []
    # stdin to stdout: what is wrong with stdin, not that its format is not one featurewarp writes
    check_refused(runner("warp", "swirl", "-", "-", input=b""), 1, ["stdin is empty"])
    check_refused(runner("warp", "swirl", "-", "-", input=b"hello\n"), 1, ["stdin", "cannot be decoded"])
    # the hint's command reads stdin as the failed one did, not a file named "stdin"
    check_refused(runner("warp", "swirl", "-", tmp_path / "o.png", input=FILES["lab.tif"]), 1,
                  ["stdin holds CIELab", "convert - -colorspace sRGB"])


def test_huge_image_is_refused_before_decoding(runner, inputs, monkeypatch):
    def no_decoding(*args):
        raise AssertionError("pixels were decoded")

    monkeypatch.setattr(decode.cv2, "imdecode", no_decoding)
    for name in ("huge.png", "huge.jpg"):
        check_refused(runner("warp", "swirl", inputs[name], inputs["out"]), 1, ["--max-pixels"])
    check_refused(runner("warp", "swirl", inputs["ok.png"], inputs["out"], "--max-pixels", "100"), 1,
                  ["--max-pixels"])


@pytest.mark.parametrize("fmt", ["png", "jpg", "webp", "tiff", "bmp"])
@pytest.mark.parametrize("size", [(1, 1), (37, 5), (300, 2)])
def test_header_sizes(fmt, size):
    image = np.zeros((size[1], size[0], 3), np.uint8)
    header = decode.read_header(encode.encode_image(image, fmt))
    assert (header.width, header.height, header.orientation) == (*size, 1)


# --- read-only output folder ----------------------------------------------------------------

@pytest.mark.skipif(os.geteuid() == 0, reason="root may write into any folder, so a read-only "
                    "folder cannot be emulated; test_unwritable_folder_code_path covers the check")
def test_read_only_output_folder(runner, inputs, tmp_path):
    locked = tmp_path / "locked"
    locked.mkdir()
    locked.chmod(0o555)
    try:
        check_refused(runner("warp", "swirl", inputs["ok.png"], locked / "o.png"), 2, ["not writable"])
        assert list(locked.iterdir()) == []
    finally:
        locked.chmod(0o755)


def test_unwritable_folder_code_path(runner, inputs, monkeypatch):
    """The writability probe (a temporary file) failing, as it does in a read-only folder."""
    def denied(*args, **kwargs):
        raise PermissionError(13, "Permission denied")

    monkeypatch.setattr(write.tempfile, "TemporaryFile", denied)
    check_refused(runner("warp", "swirl", inputs["ok.png"], inputs["out"]), 2,
                  ["OUTPUT", "not writable", "Permission denied"])


# --- odd inputs that must work --------------------------------------------------------------

@pytest.mark.parametrize("preset", ["stretch", "arc", "swirl", "bulge"])
@pytest.mark.parametrize("size", [(1, 1), (1, 7), (7, 1)])
def test_tiny_images(runner, tmp_path, preset, size):
    src = save(tmp_path / "tiny.png", textured(size))
    mask = save(tmp_path / "mask.png", np.full(size[::-1], 255, np.uint8))
    run = runner("warp", preset, src, tmp_path / "o.png", "-m", mask)
    assert run.code == 0, run.stderr
    assert decode.read_image(str(tmp_path / "o.png")).size > 0


def warp_bytes(runner, tmp_path, mask_image, *extra):
    """Warp the test scene with ``mask_image`` (an array, or None) and return the output bytes."""
    src = save(tmp_path / "in.png", textured())
    args = ["warp", "bulge", src, tmp_path / "o.png", "--strength", "1", *extra]
    if mask_image is not None:
        args += ["-m", save(tmp_path / "m.png", mask_image)]
    run = runner(*args)
    assert run.code == 0, run.stderr
    return (tmp_path / "o.png").read_bytes()


def test_black_mask_is_the_plain_warp(runner, tmp_path):
    assert warp_bytes(runner, tmp_path, np.zeros(SIZE[::-1], np.uint8)) == \
        warp_bytes(runner, tmp_path, None, "--mode", "plain")


def test_white_mask_works(runner, tmp_path):
    out = warp_bytes(runner, tmp_path, np.full(SIZE[::-1], 255, np.uint8))
    assert decode.decode_image(out, "o").shape[:2] == SIZE[::-1]


def test_mask_is_thresholded_at_128(runner, tmp_path):
    binary = square_mask()
    soft = np.where(binary > 0, 128, 127).astype(np.uint8)
    soft[::3, ::3] = np.where(binary[::3, ::3] > 0, 200, 40)
    assert warp_bytes(runner, tmp_path, soft) == warp_bytes(runner, tmp_path, binary)


def test_mask_with_alpha_counts_transparent_as_black(runner, tmp_path):
    white = np.full(SIZE[::-1], 255, np.uint8)
    rgba = np.dstack([white, white, white, square_mask()])          # white everywhere, opaque square
    assert warp_bytes(runner, tmp_path, rgba) == warp_bytes(runner, tmp_path, square_mask())


def test_colour_mask_uses_its_gray_value(runner, tmp_path):
    bgr = np.dstack([square_mask()] * 3)
    assert warp_bytes(runner, tmp_path, bgr) == warp_bytes(runner, tmp_path, square_mask())


def test_unicode_and_space_paths(runner, tmp_path):
    folder = tmp_path / "dossier été ☃"
    folder.mkdir()
    src = save(folder / "mon image.png", textured())
    mask = save(folder / "masque – 1.png", square_mask())
    out = folder / "sortie ünïcode.jpg"
    run = runner("warp", "swirl", src, out, "-m", mask, "--report", folder / "rapport é.json")
    assert run.code == 0, run.stderr
    assert out.exists() and (folder / "rapport é.json").exists()
    check_refused(runner("warp", "swirl", folder / "absent ☃.png", out), 2, ["absent ☃.png"])


@pytest.mark.parametrize("orientation", range(1, 9))
def test_exif_orientation_is_respected(orientation):
    image = textured((40, 24))
    image[:6, :10] = (0, 0, 255)                       # a red corner to see where "up" went
    data = jpeg_with_orientation(image, orientation)
    assert decode.read_header(data).orientation == orientation
    upright = cv2.imdecode(np.frombuffer(data, np.uint8), cv2.IMREAD_COLOR)   # OpenCV applies EXIF
    assert np.array_equal(decode.decode_image(data, "exif"), upright)


def test_exif_rotated_jpeg_through_the_cli(runner, tmp_path):
    src = tmp_path / "rotated.jpg"
    src.write_bytes(jpeg_with_orientation(textured(), 6))          # 48x36 stored, 36x48 shown
    upright_mask = save(tmp_path / "mask.png", np.zeros((48, 36), np.uint8))
    run = runner("warp", "stretch", src, tmp_path / "o.png", "-m", upright_mask, "--sx", "2")
    assert run.code == 0, run.stderr
    assert decode.read_image(str(tmp_path / "o.png")).shape[:2] == (48, 72)


def test_gray_alpha_png(runner, tmp_path):
    gray = textured(channels=1)
    alpha = np.full_like(gray, 200)
    src = tmp_path / "ga.png"
    src.write_bytes(png_bytes(np.dstack([gray, alpha]), 4))
    assert runner("warp", "swirl", src, tmp_path / "o.png", "--angle", "0").code == 0
    out = decode.read_image(str(tmp_path / "o.png"))
    assert out.shape == (SIZE[1], SIZE[0], 4) and (out[:, :, 3] == 200).all()
    assert np.abs(out[:, :, 0].astype(int) - gray).max() <= 1


def stored_mode(path) -> str:
    """Pillow's mode of the pixels an image file stores."""
    from PIL import Image

    with Image.open(path) as image:
        return image.mode


@pytest.mark.parametrize("fmt", ["png", "tiff"])
def test_gray_alpha_stays_gray_alpha(runner, tmp_path, fmt):
    """A gray + alpha input was written RGBA (twice the samples, another form than the input's;
    ImageMagick keeps it). It stays gray + alpha in PNG and TIFF, and so does a gray input whose
    canvas gains transparency; the report says 2 channels. A coloured background, a format
    without that form (WebP) or 16 bits (Pillow writes gray + alpha at 8 only) stay BGRA."""
    gray = textured(channels=1)
    alpha = np.where(np.arange(SIZE[0]) < 20, 0, 200).astype(np.uint8)[None, :].repeat(SIZE[1], axis=0)
    src, report = tmp_path / "ga.png", tmp_path / "r.json"
    src.write_bytes(png_bytes(np.dstack([gray, alpha]), 4))
    out = tmp_path / f"o.{fmt}"
    assert runner("warp", "arc", src, out, "--report", report).code == 0
    figures = json.loads(report.read_text())
    assert stored_mode(out) == "LA" and figures["input"]["channels"] == figures["output"]["channels"] == 2
    plain = tmp_path / "plain.webp"                # the same pixels as BGRA
    assert runner("warp", "arc", src, plain).code == 0 and stored_mode(plain) == "RGBA"
    kept, bgra = decode.read_image(str(out)), decode.read_image(str(plain))
    assert np.array_equal(kept, bgra) and (kept[:, :, 3] == 0).any()
    assert runner("warp", "arc", src, tmp_path / f"red.{fmt}", "--background", "red").code == 0
    assert stored_mode(tmp_path / f"red.{fmt}") == "RGBA"
    gray_src = tmp_path / "g.png"
    gray_src.write_bytes(png_bytes(gray, 0))
    assert runner("warp", "arc", gray_src, tmp_path / f"g.{fmt}").code == 0
    assert stored_mode(tmp_path / f"g.{fmt}") == "LA"
    deep = tmp_path / "deep.png"
    deep.write_bytes(png_bytes(np.dstack([gray, alpha]).astype(np.uint16) * 257, 4))
    assert runner("warp", "arc", deep, tmp_path / "deep-out.png").code == 0
    assert decode.read_image(str(tmp_path / "deep-out.png")).dtype == np.uint16
    assert stored_mode(tmp_path / "deep-out.png") == "RGBA"


@pytest.mark.parametrize("name", ["bilevel.png", "bilevel.tiff"])
def test_a_bilevel_input_whose_canvas_gains_transparency_is_gray_alpha(runner, tmp_path, name):
    """A 1-bit gray input (Pillow's mode "1") is a gray one: its canvas that gains transparency
    is written gray + alpha as a mode "L" input's is (it was RGBA: GRAY_MODES left "1" out)."""
    from PIL import Image

    src = tmp_path / name
    Image.fromarray(textured(channels=1) >= 128).save(src)
    assert stored_mode(src) == "1"
    out, report = tmp_path / "out.png", tmp_path / "r.json"
    assert runner("warp", "arc", src, out, "--report", report).code == 0
    assert stored_mode(out) == "LA" and json.loads(report.read_text())["output"]["channels"] == 2


@pytest.mark.parametrize("transparent", [False, True])
def test_palette_png(runner, tmp_path, transparent):
    palette = np.array([[255, 0, 0], [0, 255, 0], [0, 0, 255], [9, 9, 9]], np.uint8)
    index = (np.indices(SIZE[::-1]).sum(axis=0) // 5 % 4).astype(np.uint8)
    chunks = [(b"PLTE", palette.tobytes())] + ([(b"tRNS", bytes([255, 255, 255, 0]))] if transparent else [])
    src = tmp_path / "pal.png"
    src.write_bytes(png_bytes(index, 3, chunks))
    run = runner("warp", "swirl", src, tmp_path / "o.png", "--angle", "0")
    assert run.code == 0, run.stderr
    out = decode.read_image(str(tmp_path / "o.png"))
    assert out.shape[2] == (4 if transparent else 3)
    shown = index != 3 if transparent else np.ones(index.shape, bool)   # resampled premultiplied: 0 under alpha 0
    assert np.array_equal(out[:, :, :3][shown], palette[index][:, :, ::-1][shown])
    if transparent:
        assert (out[:, :, 3][~shown] == 0).all() and (out[:, :, 3][shown] == 255).all()


def test_diff_refuses_a_lab_page_after_the_first(runner, tmp_path):
    """diff compares every page: a Lab second page read as colours said 'differ' (exit 1)."""
    import io

    from PIL import Image

    rgb = Image.fromarray(cv2.cvtColor(textured(), cv2.COLOR_BGR2RGB))
    for name, second in (("a.tif", rgb.convert("LAB")), ("b.tif", rgb)):
        out = io.BytesIO()
        rgb.save(out, "TIFF", save_all=True, append_images=[second])
        (tmp_path / name).write_bytes(out.getvalue())
    run = runner("diff", tmp_path / "a.tif", tmp_path / "b.tif")
    assert run.code == 2 and "a.tif (page 2) holds CIELab colours" in run.stderr, run.stderr
    assert runner("diff", tmp_path / "b.tif", tmp_path / "b.tif").code == 0


def test_sixteen_bit_mask(runner, tmp_path):
    deep = square_mask().astype(np.uint16) * 257
    assert warp_bytes(runner, tmp_path, deep) == warp_bytes(runner, tmp_path, square_mask())


def test_a_newline_in_a_file_name_keeps_warnings_and_summaries_on_one_line(tmp_path):
    """Errors escaped it; warnings and -v's summary printed it raw, splitting their line."""
    import subprocess
    import sys

    import cv2
    import numpy as np

    name = tmp_path / "two\nlines.png"
    cv2.imwrite(str(tmp_path / "plain.png"), np.zeros((30, 40), np.uint8))
    name.write_bytes((tmp_path / "plain.png").read_bytes())
    cv2.imwrite(str(tmp_path / "empty.png"), np.zeros((30, 40), np.uint8))
    run = subprocess.run([sys.executable, "-m", "featurewarp_cli", "warp", "swirl", str(name), str(tmp_path / "o.png"),
                          "-m", str(tmp_path / "empty.png"), "-v"], capture_output=True, text=True, timeout=60)
    assert run.returncode == 0, run.stderr
    lines = run.stderr.splitlines()
    assert len(lines) == 2 and all(line.startswith("featurewarp: ") and "two\\nlines.png" in line for line in lines)


def test_an_input_that_decodes_to_another_size_than_its_header_is_named(monkeypatch):
    """The check named stdin '-' (reachable from stdin since it decodes beside the solve)."""
    from featurewarp_cli.io import decode as decoding

    whole = decoding.decode_image
    monkeypatch.setattr(decoding, "decode_image", lambda *args, **kw: whole(*args, **kw)[:-1])
    from click.testing import CliRunner

    from featurewarp_cli.cli.main import cli

    run = CliRunner().invoke(cli, ["warp", "swirl", "-", "-", "--format", "png"], input=FILES["ok.png"])
    assert run.exit_code == 1 and "stdin decodes to 48x35, its header says 48x36" in run.output, run.output

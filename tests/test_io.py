"""featurewarp_cli.io: header checks before decoding for every accepted format, EXIF
orientation, the input read once, colours, and the 16 -> 8-bit rule."""

from __future__ import annotations

import io
import struct

import cv2
import numpy as np
import pytest
from PIL import Image

from featurewarp_cli.app import pipeline
from featurewarp_cli.io import ImageError, decode, depth, encode
from featurewarp_cli.io.colours import parse_colour
from test_cli import command, square_mask, textured

#: Pillow's save arguments for each format whose header is read before decoding.
PILLOW_SAVES = {"PNG": {}, "JPEG": {"quality": 95}, "WEBP": {"lossless": True}, "TIFF": {}, "BMP": {},
                "GIF": {}, "PPM": {}, "JPEG2000": {}, "AVIF": {"quality": 90}}


def pillow_file(fmt: str, size=(40, 24), **extra) -> bytes:
    """A small RGB image saved by Pillow as ``fmt``."""
    image = Image.fromarray(textured(size)[:, :, ::-1].copy())
    buffer = io.BytesIO()
    image.save(buffer, fmt, **PILLOW_SAVES.get(fmt, {}), **extra)
    return buffer.getvalue()


def no_decoding(*args):
    raise AssertionError("pixels were decoded")


@pytest.mark.parametrize("fmt", [f for f in PILLOW_SAVES if f in decode.HEADER_FORMATS])
def test_every_header_format_is_checked_before_decoding(fmt, monkeypatch):
    data = pillow_file(fmt)
    assert decode.read_header(data).upright_size == (40, 24)
    assert decode.decode_image(data, "x", max_pixels=40 * 24).shape[:2] == (24, 40)   # OpenCV decodes it
    monkeypatch.setattr(decode.cv2, "imdecode", no_decoding)
    with pytest.raises(ImageError, match=r"40x24 = 960 pixels, above the limit of 959 \(--max-pixels\)"):
        decode.decode_image(data, "x", max_pixels=959)


def test_pillows_own_bomb_limit_does_not_decide(monkeypatch):
    """A header above Pillow's default limit (2 * 89 M pixels) is read and judged by max_pixels."""
    data = bytearray(pillow_file("PNG"))
    data[16:24] = struct.pack(">II", 20000, 10000)                   # IHDR: 200 M pixels
    data[29:33] = struct.pack(">I", __import__("zlib").crc32(bytes(data[12:29])))
    assert decode.read_header(bytes(data)).upright_size == (20000, 10000)
    monkeypatch.setattr(decode.cv2, "imdecode", no_decoding)
    with pytest.raises(ImageError, match="--max-pixels"):
        decode.decode_image(bytes(data), "x", max_pixels=199_999_999)


def test_jpeg_with_junk_before_a_segment_is_checked(monkeypatch):
    """libjpeg skips stray bytes between segments; so must the header check."""
    data = bytearray(encode.encode_image(textured(), "jpg"))
    sof = data.index(b"\xff\xc0")
    data[sof + 5 : sof + 9] = struct.pack(">HH", 32000, 32000)
    dqt = data.index(b"\xff\xdb")
    data[dqt:dqt] = b"\x00"
    monkeypatch.setattr(decode.cv2, "imdecode", no_decoding)
    with pytest.raises(ImageError, match="32000x32000"):
        decode.decode_image(bytes(data), "x", max_pixels=1000)


@pytest.mark.parametrize("ext,message", [
    (".pam", "above the limit of 599 pixels of the decoder (--max-pixels)"),
    (".hdr", "Radiance HDR holds float samples"),                  # refused before decoding
])
def test_formats_without_a_pillow_header_meet_opencvs_limit(tmp_path, ext, message):
    """PAM: Pillow cannot read it, OpenCV's limit (set from --max-pixels before OpenCV loads)
    refuses it inside its decoder. Radiance HDR (float samples) is refused from its first bytes."""
    image = textured((30, 20)) if ext == ".pam" else textured((30, 20)).astype(np.float32) / 255
    path = tmp_path / f"big{ext}"
    assert cv2.imwrite(str(path), image)
    assert decode.read_header(path.read_bytes()) is None
    run = command("warp", "swirl", path, tmp_path / "o.png", "--max-pixels", 599)
    lines = run.stderr.decode().splitlines()
    assert run.returncode == 1 and len(lines) == 1, lines
    assert message in lines[0]
    assert not (tmp_path / "o.png").exists()


@pytest.mark.parametrize("fmt", ["JPEG", "PNG", "WEBP", "TIFF"])
@pytest.mark.parametrize("orientation", [1, 3, 6, 7])
def test_exif_orientation_as_opencv_shows_it(fmt, orientation):
    """JPEG, PNG (eXIf) and WebP are turned here, TIFF by its decoder: all come out upright
    as OpenCV's 8-bit colour decoding shows them, and the header's upright size agrees."""
    if fmt == "TIFF":
        data = pillow_file(fmt, tiffinfo={0x0112: orientation})
    else:
        exif = Image.Exif()
        exif[0x0112] = orientation
        data = pillow_file(fmt, exif=exif)
    image = decode.decode_image(data, "x")
    upright = cv2.imdecode(np.frombuffer(data, np.uint8), cv2.IMREAD_COLOR)
    assert np.array_equal(image, upright)
    assert decode.read_header(data).upright_size == (image.shape[1], image.shape[0])


def test_input_is_read_once(tmp_path, monkeypatch):
    """Both the threaded path (header read) and the serial one (no header Pillow reads) read
    INPUT's bytes once."""
    reads = []
    real = decode.read_bytes
    monkeypatch.setattr(decode, "read_bytes", lambda path, *limit: reads.append(path) or real(path, *limit))
    settings = pipeline.Settings(preset="swirl", params={"angle": 90.0})
    mask = tmp_path / "m.png"
    mask.write_bytes(encode.encode_image(square_mask(), "png"))
    for ext in (".png", ".pam"):
        source = tmp_path / f"in{ext}"
        assert cv2.imwrite(str(source), textured())
        reads.clear()
        pipeline.warp_file(settings, str(source), str(tmp_path / "o.png"), str(mask))
        assert reads.count(str(source)) == 1


@pytest.mark.parametrize("text, rgb", [("white", (255, 255, 255)), (" Grey ", (128, 128, 128)),
                                       ("green", (0, 128, 0)), ("skyblue", (135, 206, 235)),
                                       ("#f80", (255, 136, 0)), ("#0000FF", (0, 0, 255)),
                                       ("rgb(1, 2, 3)", (1, 2, 3)), ("transparent", None), ("NONE", None)])
def test_colours(text, rgb):
    assert parse_colour(text) == rgb


@pytest.mark.parametrize("text, words", [("notacolour", "is not a colour"), ("#12", "is not a colour"),
                                         ("", "is not a colour"), ("rgb(300, 0, 0)", "outside 0..255"),
                                         ("#ff000080", "alpha")])
def test_bad_colours(text, words):
    with pytest.raises(ValueError, match=words):
        parse_colour(text)


def test_sixteen_to_eight_bits_is_rounding():
    every = np.arange(65536, dtype=np.uint16)
    assert np.array_equal(depth.to_eight_bit(every), np.round(every / 257.0).astype(np.uint8))
    assert np.array_equal(np.round(depth.on_eight_bit_scale(every)), depth.to_eight_bit(every))
    with pytest.raises(ValueError, match="float32"):
        depth.to_eight_bit(np.zeros(3, np.float32))


@pytest.mark.parametrize("fmt", ["webp", "bmp"])
def test_eight_bit_formats_use_the_rule(fmt):
    """A 16-bit image in a lossless 8-bit format is stored as the rule says."""
    image = textured(dtype=np.uint16) + np.arange(48, dtype=np.uint16)[None, :, None]
    stored = decode.decode_image(encode.encode_image(image, fmt), "x")
    assert np.array_equal(stored, depth.to_eight_bit(image))


def test_library_messages_are_captured_without_a_temporary_directory(monkeypatch):
    """With no writable temporary directory anywhere every command failed (FileNotFoundError):
    the capture of the C libraries' messages needs none (a file in memory)."""
    import os
    import tempfile

    from featurewarp_cli.io.capture import captured_stderr

    def nowhere(*args, **kwargs):
        raise FileNotFoundError("No usable temporary directory found")

    monkeypatch.setattr(tempfile, "TemporaryFile", nowhere)
    with captured_stderr() as lines:
        os.write(2, b"libpng warning: iCCP: known incorrect sRGB profile\n")
    assert lines == ["libpng warning: iCCP: known incorrect sRGB profile"]


@pytest.mark.parametrize("fmt", ["png", "webp", "tiff"])
def test_transparent_pixels_carry_colour_0(fmt):
    """CI trial finding 2: the colour under alpha 0 comes out as given (0 where the warp leaves
    0) in every format with alpha: OpenCV's lossless WebP filled it with nearby colour, so PNG
    and WebP of one result differed by RMSE 68.7."""
    image = np.dstack([textured(), np.full((36, 48), 255, np.uint8)])
    image[:, :20, 3] = 0
    image[:, :20, :3] = 0                     # what the warp leaves outside the picture
    image[5, 30, 3] = 1
    data = encode.encode_image(image, fmt)
    assert np.array_equal(decode.decode_image(data, fmt), image)
    assert encode.encode_image(image, fmt) == data                # the same pixels, the same bytes


def test_webp_with_alpha_keeps_metadata_path_exact():
    image = np.dstack([textured(), np.full((36, 48), 255, np.uint8)])
    image[:, :10] = 0
    exif = Image.Exif()
    exif[0x010E] = "caption"
    back = decode.decode_image(encode.encode_image(image, "webp", exif=exif.tobytes()), "webp")
    assert np.array_equal(back, image)


def _raw_png(samples: np.ndarray, depth: int, colour_type: int, trns: bytes | None) -> bytes:
    """A PNG of ``samples`` ((h, w) grey levels or (h, w, 3) RGB at ``depth`` bits) with a tRNS
    chunk (None: none), written by hand: Pillow writes no 16-bit RGB nor 2-bit grey with one."""
    import zlib

    def chunk(kind, payload):
        return struct.pack(">I", len(payload)) + kind + payload + struct.pack(">I", zlib.crc32(kind + payload))

    height, width = samples.shape[:2]
    rows = samples.reshape(height, -1)
    if depth < 8:                                    # pack the levels, 8 // depth to a byte
        per = 8 // depth
        rows = np.pad(rows, ((0, 0), (0, -rows.shape[1] % per))).reshape(height, -1, per)
        rows = sum(rows[:, :, k].astype(np.uint16) << (8 - depth * (k + 1)) for k in range(per))
    body = b"".join(b"\0" + row.astype(">u2" if depth == 16 else np.uint8).tobytes() for row in rows)
    header = struct.pack(">IIBBBBB", width, height, depth, colour_type, 0, 0, 0)
    return (b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", header) + (chunk(b"tRNS", trns) if trns is not None else b"")
            + chunk(b"IDAT", zlib.compress(body)) + chunk(b"IEND", b""))


@pytest.mark.parametrize("depth", [2, 8, 16])
def test_grey_png_with_trns_decodes_with_its_alpha(depth):
    """A grey PNG's tRNS level: OpenCV's IMREAD_UNCHANGED gives no alpha for it (it does for
    RGB and palette PNGs), so its transparent pixels came out opaque. Pillow reads the level
    but leaves 16-bit grey without alpha and compares a 2-bit level unscaled."""
    top = (1 << depth) - 1
    levels = np.arange(4 * 6).reshape(4, 6) % (top + 1)
    data = _raw_png(levels, depth, 0, struct.pack(">H", top // 3))
    image = decode.decode_image(data, "grey.png")
    dtype = np.uint16 if depth == 16 else np.uint8
    scale = np.iinfo(dtype).max // top if depth < 8 else 1
    assert image.shape == (4, 6, 4) and image.dtype == dtype
    assert np.array_equal(image[:, :, 0], (levels * scale).astype(dtype))
    assert np.array_equal(image[:, :, 3] == 0, levels == top // 3) and image[:, :, 3].max() == np.iinfo(dtype).max
    assert decode.decode_image(_raw_png(levels, depth, 0, None), "grey.png").ndim == 2   # none: no alpha
    outside = _raw_png(levels, depth, 0, struct.pack(">H", top + 1)) if depth < 16 else None
    assert outside is None or decode.decode_image(outside, "grey.png").ndim == 2


@pytest.mark.parametrize("depth", [8, 16])
def test_rgb_png_with_trns_decodes_with_its_alpha(depth):
    """OpenCV gives an RGB PNG's tRNS colour as alpha already, at 8 and 16 bits."""
    dtype = np.uint16 if depth == 16 else np.uint8
    rgb = np.array([[[1000, 2000, 3000], [5, 6, 7]]]) % (np.iinfo(dtype).max + 1)
    image = decode.decode_image(_raw_png(rgb, depth, 2, struct.pack(">3H", *rgb[0, 0])), "rgb.png")
    assert image.dtype == dtype and image.shape == (1, 2, 4)
    assert image[0, 0, 3] == 0 and image[0, 1, 3] == np.iinfo(dtype).max
    assert image[0, 1, :3].tolist() == [7, 6, 5]


@pytest.mark.parametrize("depth", [8, 16])
def test_mask_alpha_takes_a_grey_pngs_trns(tmp_path, depth):
    """--mask alpha said "no alpha channel" for a grey cut-out whose surround is its tRNS level,
    and the surround came out opaque."""
    from click.testing import CliRunner

    from featurewarp_cli.cli.main import cli

    y, x = np.mgrid[0:60, 0:80]
    subject = (abs(x - 40) < 15) & (abs(y - 30) < 12)
    grey = np.where(subject, (x * 3 + y) % 250 + 1, 0) * (257 if depth == 16 else 1)
    source, out = tmp_path / "cut.png", tmp_path / "out.png"
    source.write_bytes(_raw_png(grey, depth, 0, struct.pack(">H", 0)))
    run = CliRunner().invoke(cli, ["warp", "swirl", str(source), str(out), "--mask", "alpha", "--angle", "20"])
    assert run.exit_code == 0 and run.output == "", run.output
    written = cv2.imread(str(out), cv2.IMREAD_UNCHANGED)
    assert written.shape == (60, 80, 4) and written.dtype == (np.uint16 if depth == 16 else np.uint8)
    assert written[0, 0, 3] == 0 and written[30, 40, 3] == np.iinfo(written.dtype).max
    assert abs(int((written[:, :, 3] == 0).sum()) - int((~subject).sum())) < 0.05 * (~subject).sum()

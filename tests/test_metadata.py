"""The input's colours and metadata in the output: ICC profile, EXIF, XMP and resolution at 8
and 16 bits, CMYK through its profile, a grey profile on colour pixels, JPEG chroma, and the
warnings for what an output cannot keep (photo trial findings 2, 3, 4, 6, 7, 8)."""

from __future__ import annotations

import io
import pickle
import struct
import zlib

import cv2
import numpy as np
import pytest
from PIL import Image, ImageCms, JpegImagePlugin

from featurewarp_cli.io import decode, encode, metadata, profiles

XMP = (b'<x:xmpmeta xmlns:x="adobe:ns:meta/"><rdf:RDF xmlns:rdf="http://www.w3.org/1999/02/22-rdf-syntax-ns#">'
       b'<rdf:Description xmlns:dc="http://purl.org/dc/elements/1.1/" xmlns:tiff="http://ns.adobe.com/tiff/1.0/" '
       b'tiff:Orientation="6"><dc:rights>Copyright Jane</dc:rights></rdf:Description></rdf:RDF></x:xmpmeta>')


def _icc(space: bytes, pcs: bytes, cls: bytes, tags: list[tuple[bytes, bytes]]) -> bytes:
    """A version 2.1 ICC profile of ``tags`` (signature, bytes)."""
    table, body, at = b"", b"", 128 + 4 + 12 * len(tags)
    for signature, tag in tags:
        table += struct.pack(">4sII", signature, at + len(body), len(tag))
        body += tag + b"\0" * (-len(tag) % 4)
    header = struct.pack(">I4sI4s4s4s12s4s4sI4s4sQI12s4s16s28x", 0, b"lcms", 0x02100000, cls, space, pcs,
                         struct.pack(">6H", 2020, 1, 1, 0, 0, 0), b"acsp", b"APPL", 0, b"none", b"none", 0, 0,
                         struct.pack(">3i", 63190, 65536, 54061), b"test", bytes(16))
    whole = header + struct.pack(">I", len(tags)) + table + body
    return struct.pack(">I", len(whole)) + whole[4:]


def _desc(text: bytes) -> bytes:
    return b"desc\0\0\0\0" + struct.pack(">I", len(text) + 1) + text + b"\0" + bytes(78)


WHITE = b"XYZ \0\0\0\0" + struct.pack(">3i", 63190, 65536, 54061)


def gray_profile(gamma: float = 1.8) -> bytes:
    """A grey display profile of tone curve ``gamma`` (u8Fixed8)."""
    curve = b"curv\0\0\0\0" + struct.pack(">IH", 1, round(gamma * 256))
    return _icc(b"GRAY", b"XYZ ", b"mntr", [(b"desc", _desc(b"test grey")), (b"wtpt", WHITE), (b"kTRC", curve)])


def cmyk_profile() -> bytes:
    """A CMYK printer profile (lut8, 2 grid points a channel, to Lab) whose colours differ from the
    naive 255 - C ... conversion: cyan ink prints blue-green, every ink darkens by half as much."""
    grid = []
    for c in (0, 1):
        for m in (0, 1):
            for y in (0, 1):
                for k in (0, 1):
                    light = 100 - 25 * (c + m + y) - 50 * k
                    grid += [round(max(light, 5) * 255 / 100), 128 - 40 * c + 50 * m, 128 - 30 * c + 60 * y]
    identity = bytes(range(256))
    lut = (b"mft1\0\0\0\0" + bytes([4, 3, 2, 0]) + struct.pack(">9i", 65536, 0, 0, 0, 65536, 0, 0, 0, 65536)
           + identity * 4 + bytes(grid) + identity * 3)
    return _icc(b"CMYK", b"Lab ", b"prtr", [(b"desc", _desc(b"test cmyk")), (b"wtpt", WHITE), (b"A2B0", lut)])


def picture(shape=(48, 64, 3), dtype=np.uint8) -> np.ndarray:
    y, x = np.mgrid[0:shape[0], 0:shape[1]]
    top = np.iinfo(dtype).max
    planes = [x / shape[1], y / shape[0], (x + y) % 7 / 7, 0.5 + x % 2 / 2][:shape[2] if len(shape) == 3 else 1]
    return np.squeeze(np.dstack([np.round(p * top) for p in planes]).astype(dtype))


def srgb() -> bytes:
    return ImageCms.ImageCmsProfile(ImageCms.createProfile("sRGB")).tobytes()


def camera_exif() -> bytes:
    exif = Image.Exif()
    exif[270], exif[33432] = "a caption", "(c) Retoucher"
    return exif.tobytes()


def carried(dpi=(300.0, 300.0)) -> dict:
    """An EXIF block, an upright XMP packet and a resolution, as encode_image's keywords."""
    return {"exif": camera_exif(), "xmp": metadata.upright_xmp(XMP), "dpi": dpi}


def opened(data: bytes) -> Image.Image:
    return Image.open(io.BytesIO(data))


@pytest.mark.parametrize("fmt", ["png", "tiff"])
def test_16_bit_output_keeps_profile_exif_xmp_and_resolution(fmt):
    """16-bit PNG and TIFF went to OpenCV, which writes no metadata: the profile (an Adobe RGB
    master's) was dropped silently (finding 2)."""
    image, icc = picture(dtype=np.uint16), srgb()
    data = encode.encode_image(image, fmt, icc=icc, **carried())
    assert data == encode.encode_image(image, fmt, icc=icc, **carried())       # the same bytes each run
    back = cv2.imdecode(np.frombuffer(data, np.uint8), cv2.IMREAD_UNCHANGED)
    assert back.dtype == np.uint16 and np.array_equal(back, image)
    with opened(data) as written:
        assert written.info["icc_profile"] == icc
        assert written.getexif()[270] == "a caption" and written.getexif()[33432] == "(c) Retoucher"
        assert b"Copyright Jane" in written.info["xmp"] and b'tiff:Orientation="1"' in written.info["xmp"]
        assert [round(v) for v in written.info["dpi"]] == [300, 300]


def test_16_bit_tiff_with_alpha_keeps_its_alpha_tag_and_the_profile():
    image, icc = picture((20, 30, 4), np.uint16), srgb()
    data = encode.encode_image(image, "tiff", icc=icc)
    with opened(data) as written:
        assert written.info["icc_profile"] == icc and written.tag_v2[338] == (2,)
    back = decode.decode_image(data, "t")
    assert np.array_equal(back, image)


def test_16_bit_png_chunks_have_right_crcs():
    data = encode.encode_image(picture(dtype=np.uint16), "png", icc=srgb(), **carried())
    at, kinds = 8, []
    while at < len(data):
        length = int.from_bytes(data[at:at + 4], "big")
        kind, payload = data[at + 4:at + 8], data[at + 8:at + 8 + length]
        assert int.from_bytes(data[at + 8 + length:at + 12 + length], "big") == zlib.crc32(kind + payload), kind
        kinds.append(kind)
        at += 12 + length
    assert kinds[:5] == [b"IHDR", b"iCCP", b"pHYs", b"eXIf", b"iTXt"] and kinds[-1] == b"IEND"


@pytest.mark.parametrize("fmt", ["png", "jpg", "tiff", "bmp"])
def test_resolution_is_kept(fmt):
    """pHYs, JFIF density and BMP's pixels per metre were dropped (finding 4)."""
    data = encode.encode_image(picture(), fmt, dpi=(240.0, 240.0))
    with opened(data) as written:
        assert [round(v) for v in written.info["dpi"]] == [240, 240]


@pytest.mark.parametrize("fmt", ["jpg", "webp", "png", "tiff"])
def test_xmp_is_kept_upright(fmt):
    """XMP was dropped from JPEG and WebP (finding 6); its orientation is set to 1 as the EXIF's."""
    data = encode.encode_image(picture(), fmt, **carried())
    with opened(data) as written:
        xmp = written.info["xmp"]
        assert b"Copyright Jane" in (xmp if isinstance(xmp, bytes) else xmp.encode())
        assert b'tiff:Orientation="1"' in (xmp if isinstance(xmp, bytes) else xmp.encode())


def test_header_reads_xmp_resolution_and_iptc():
    buffer = io.BytesIO()
    Image.fromarray(picture()).save(buffer, "JPEG", xmp=XMP, dpi=(300, 300))
    header = decode.read_header(buffer.getvalue())
    assert header.dpi == (300.0, 300.0) and b'tiff:Orientation="1"' in header.xmp
    assert not header.iptc
    assert pickle.loads(pickle.dumps(header)) == header                # a batch's workers get it whole
    kept = metadata.Metadata.of(header)
    assert pickle.loads(pickle.dumps(kept)) == kept and kept.xmp == header.xmp and kept.dpi == header.dpi
    png = io.BytesIO()
    Image.fromarray(picture()).save(png, "PNG", dpi=(300, 300))
    assert round(decode.read_header(png.getvalue()).dpi[0]) == 300
    plain = io.BytesIO()
    Image.fromarray(picture()).save(plain, "PNG")
    bare = decode.read_header(plain.getvalue())
    assert (bare.exif, bare.xmp, bare.dpi, bare.iptc) == (None, None, None, False)


def test_header_keeps_the_orientation_it_turns_by_and_an_upright_exif():
    """The EXIF kept is set upright on Pillow's own cached block: read before the orientation,
    the header said 1 and a turned photo came out as stored."""
    exif = Image.Exif()
    exif[270], exif[0x0112] = "a caption", 6
    buffer = io.BytesIO()
    Image.fromarray(picture()).save(buffer, "JPEG", exif=exif.tobytes())
    header = decode.read_header(buffer.getvalue())
    kept = Image.Exif()
    kept.load(header.exif)
    assert header.orientation == 6 and header.upright_size == (48, 64)
    assert kept[0x0112] == 1 and kept[270] == "a caption"
    assert decode.decode_image(buffer.getvalue(), "turned.jpg").shape[:2] == (64, 48)


@pytest.mark.parametrize("quality, sampling", [(None, 0), (95, 0), (90, 0), (89, 2), (75, 2)])
@pytest.mark.parametrize("exif", [None, camera_exif()], ids=["bare", "exif"])
def test_jpeg_keeps_chroma_whole_from_quality_90(quality, sampling, exif):
    """4:2:0 always, even at the default 95 (finding 7); as ImageMagick: 4:4:4 from 90."""
    with opened(encode.encode_image(picture(), "jpg", quality=quality, exif=exif)) as written:
        assert JpegImagePlugin.get_sampling(written) == sampling


def test_gray_profile_on_colour_output_becomes_the_rgb_one_of_its_tone():
    """A grey photo whose canvas gains transparency is written RGBA where the format has no
    gray + alpha (WebP; 16-bit PNG and TIFF): its grey profile was dropped (finding 8). The RGB
    profile made of it shows R = G = B as the grey one shows grey. 8-bit PNG and TIFF store gray
    + alpha, with the grey profile as it is."""
    gray = gray_profile()
    gray_alpha = np.dstack([picture((30, 40, 1)), np.full((30, 40), 200, np.uint8)])
    for fmt in ("png", "tiff"):
        with opened(encode.encode_image(gray_alpha, fmt, icc=gray)) as written:
            assert written.mode == "LA" and written.info["icc_profile"] == gray
    for fmt, pixels in (("webp", gray_alpha), ("png", gray_alpha.astype(np.uint16) * 257)):
        with opened(encode.encode_image(pixels, fmt, icc=gray)) as written:
            rgb = written.info["icc_profile"]
        assert rgb[16:20] == b"RGB " and rgb == profiles.rgb_from_gray(gray)
    levels = np.arange(256, dtype=np.uint8).reshape(16, 16)
    target = ImageCms.createProfile("sRGB")
    shown_gray = ImageCms.profileToProfile(Image.fromarray(levels), ImageCms.ImageCmsProfile(io.BytesIO(gray)),
                                           target, outputMode="RGB")
    shown_rgb = ImageCms.profileToProfile(Image.fromarray(np.dstack([levels] * 3)),
                                          ImageCms.ImageCmsProfile(io.BytesIO(rgb)), target, outputMode="RGB")
    assert np.abs(np.asarray(shown_gray, int) - np.asarray(shown_rgb, int)).max() <= 1
    with opened(encode.encode_image(picture((30, 40, 1)), "png", icc=gray)) as written:
        assert written.info["icc_profile"] == gray                       # grey output: the profile as it is


def _cmyk_jpeg(icc: bytes | None) -> tuple[bytes, Image.Image]:
    rgb = Image.fromarray(picture())
    cmyk = rgb.convert("CMYK")
    buffer = io.BytesIO()
    cmyk.save(buffer, "JPEG", quality=100, subsampling=0, **({"icc_profile": icc} if icc else {}))
    return buffer.getvalue(), cmyk


def test_cmyk_jpeg_is_converted_through_its_profile_and_tagged_srgb():
    """OpenCV converts CMYK without its profile (10.6 % RMSE off a managed conversion; finding 3).
    Pillow writes the Adobe-inverted CMYK that Photoshop does."""
    icc = cmyk_profile()
    data, _ = _cmyk_jpeg(icc)
    header = decode.read_header(data)
    assert header.mode == "CMYK" and header.icc == profiles.srgb() and metadata.unkept(header, "png") == []
    decoded = decode.decode_image(data, "cmyk.jpg")
    with opened(data) as stored:
        expected = ImageCms.profileToProfile(stored, ImageCms.ImageCmsProfile(io.BytesIO(icc)),
                                             ImageCms.createProfile("sRGB"), outputMode="RGB",
                                             renderingIntent=ImageCms.Intent.RELATIVE_COLORIMETRIC,
                                             flags=ImageCms.Flags.BLACKPOINTCOMPENSATION)
    assert np.abs(decoded[:, :, ::-1].astype(int) - np.asarray(expected, int)).max() <= 1
    naive = cv2.imdecode(np.frombuffer(data, np.uint8), cv2.IMREAD_COLOR)
    assert np.abs(decoded.astype(int) - naive).mean() > 10
    assert profiles.srgb() == profiles.srgb.__wrapped__()                # the same bytes each call


def test_cmyk_without_a_profile_is_said():
    data, _ = _cmyk_jpeg(None)
    header = decode.read_header(data)
    assert header.icc is None
    said = metadata.unkept(header, "png", strip=True)
    assert len(said) == 1 and "CMYK without a colour profile" in said[0]
    assert decode.decode_image(data, "cmyk.jpg").shape == (48, 64, 3)


def test_what_an_output_cannot_keep_is_said():
    header = decode.Header("PNG", 4, 4, icc=srgb(), exif=camera_exif(), xmp=XMP * 300)
    assert "BMP output keeps none of the input's ICC profile, EXIF, XMP" in metadata.unkept(header, "bmp")[0]
    assert metadata.unkept(header, "bmp", strip=True) == []
    assert "XMP (" in metadata.unkept(header, "jpg")[0]
    assert metadata.unkept(header, "png") == []
    iptc = decode.Header("JPEG", 4, 4, iptc=True)
    assert "IPTC" in metadata.unkept(iptc, "jpg")[0]
    with opened(encode.encode_image(picture(), "jpg", **metadata.Metadata.of(header).keywords())) as written:
        assert "xmp" not in written.info and written.getexif()[270] == "a caption"


def test_eight_bit_output_without_new_metadata_is_unchanged():
    """The 8-bit files that were right stay byte for byte: a profile and EXIF by Pillow as before."""
    image, icc = picture(), srgb()
    buffer = io.BytesIO()
    Image.fromarray(image[:, :, ::-1]).save(buffer, "PNG", icc_profile=icc, exif=camera_exif(), compress_level=1)
    assert encode.encode_image(image, "png", icc=icc, exif=camera_exif()) == buffer.getvalue()


def test_cli_says_a_cmyk_jpeg_without_a_profile_and_strict_refuses_it(tmp_path):
    """metadata.unkept's lines were made but nothing called it: a CMYK JPEG without a usable
    profile was converted without colour management in silence. The line reaches stderr, the
    report's warnings and --strict, under --strip too (the colours are off either way)."""
    import json

    from click.testing import CliRunner

    from featurewarp_cli.cli.main import cli

    source, out, report = tmp_path / "cmyk.jpg", tmp_path / "out.png", tmp_path / "r.json"
    source.write_bytes(_cmyk_jpeg(None)[0])
    args = ["warp", "swirl", str(source), str(out), "--angle", "30", "--report", str(report)]
    for extra in ([], ["--strip"]):
        said = CliRunner().invoke(cli, args + extra)
        assert said.exit_code == 0 and out.exists(), said.output
        lines = said.output.strip().splitlines()
        assert len(lines) == 1 and "CMYK without a colour profile" in lines[0], said.output
        assert any("CMYK without a colour profile" in w for w in json.loads(report.read_text())["warnings"])
        out.unlink()
    strict = CliRunner().invoke(cli, args + ["--strict"])
    assert strict.exit_code == 1 and "--strict" in strict.output and "CMYK" in strict.output
    assert not out.exists() and json.loads(report.read_text())["refused"]["warnings"]


def test_cli_says_what_a_bmp_output_leaves_out(tmp_path):
    """BMP keeps the resolution only: the profile and EXIF left out are said, not with --strip."""
    from click.testing import CliRunner

    from featurewarp_cli.cli.main import cli

    source = tmp_path / "in.png"
    buffer = io.BytesIO()
    Image.fromarray(picture()).save(buffer, "PNG", icc_profile=srgb(), exif=camera_exif(), dpi=(300, 300))
    source.write_bytes(buffer.getvalue())
    args = ["warp", "swirl", str(source), str(tmp_path / "out.bmp"), "--angle", "30"]
    said = CliRunner().invoke(cli, args)
    assert said.exit_code == 0 and "BMP output keeps none of the input's ICC profile, EXIF" in said.output
    with opened((tmp_path / "out.bmp").read_bytes()) as written:
        assert [round(v) for v in written.info["dpi"]] == [300, 300]
    quiet = CliRunner().invoke(cli, args + ["--strip"])
    assert quiet.exit_code == 0 and quiet.output == "", quiet.output


def test_a_resolution_no_output_can_store_is_not_kept(tmp_path):
    """A TIFF at 4294967295 dpi (valid: its rationals are 32-bit) failed the write as BMP or PNG
    with a raw struct.error; resolutions above metadata.MOST_DPI are left out."""
    from PIL import Image

    from featurewarp_cli.io import metadata

    Image.fromarray(np.zeros((20, 30, 3), np.uint8)).save(tmp_path / "big.tif", dpi=(4294967295, 4294967295))
    Image.fromarray(np.zeros((20, 30, 3), np.uint8)).save(tmp_path / "fine.tif", dpi=(300, 300))
    assert metadata.resolution(Image.open(tmp_path / "big.tif")) is None
    assert metadata.resolution(Image.open(tmp_path / "fine.tif")) == pytest.approx((300, 300))


def _shot_exif(width: int, height: int) -> bytes:
    """A camera's EXIF: its Exif directory (capture date, the pixel size) and GPS position."""
    exif = Image.Exif()
    exif[271] = "Camera"
    exif.get_ifd(metadata.EXIF_IFD).update({0x9003: "2024:05:06 07:08:09", metadata.PIXEL_X_DIMENSION: width,
                                            metadata.PIXEL_Y_DIMENSION: height})
    exif.get_ifd(metadata.GPS_IFD).update({1: "N", 2: (48.0, 51.0, 29.0)})
    return exif.tobytes()


@pytest.mark.parametrize("fmt", ["jpg", "png", "webp"])
def test_the_exif_states_the_outputs_pixel_size_and_keeps_the_camera_data(tmp_path, fmt):
    """A stretched photo's EXIF still said the input's 64 px width (viewers and asset managers
    read it); its capture date and GPS position stay."""
    from click.testing import CliRunner

    from featurewarp_cli.cli.main import cli

    source = tmp_path / "in.jpg"
    Image.fromarray(picture()).save(source, "JPEG", exif=_shot_exif(64, 48))
    run = CliRunner().invoke(cli, ["warp", "stretch", str(source), str(tmp_path / f"out.{fmt}"), "--sx", "1.5"])
    assert run.exit_code == 0 and run.output == "", run.output
    with Image.open(tmp_path / f"out.{fmt}") as written:
        exif = written.getexif()
        camera = exif.get_ifd(metadata.EXIF_IFD)
        assert written.size == (96, 48)
        assert (camera[metadata.PIXEL_X_DIMENSION], camera[metadata.PIXEL_Y_DIMENSION]) == written.size
        assert camera[0x9003] == "2024:05:06 07:08:09" and exif.get_ifd(metadata.GPS_IFD)[1] == "N"


@pytest.mark.parametrize("dtype", [np.uint8, np.uint16])
def test_a_tiff_keeps_the_exifs_camera_and_gps_directories(dtype):
    """TIFF output kept the EXIF's descriptive tags only: the capture date and GPS position were
    dropped in silence, --strict passing. Its size is the TIFF's own (no PixelXDimension, which
    libtiff reads as LONG only)."""
    data = encode.encode_image(picture(dtype=dtype), "tiff", exif=_shot_exif(64, 48))
    with opened(data) as written:
        exif = written.getexif()
        camera = exif.get_ifd(metadata.EXIF_IFD)
        assert exif[271] == "Camera" and camera[0x9003] == "2024:05:06 07:08:09"
        assert exif.get_ifd(metadata.GPS_IFD)[1] == "N" and metadata.PIXEL_X_DIMENSION not in camera
    assert cv2.imdecode(np.frombuffer(data, np.uint8), cv2.IMREAD_UNCHANGED).dtype == dtype     # 16 bits: OpenCV's path


def test_what_a_tiff_leaves_out_of_the_exif_is_said_and_strict_refuses_it(tmp_path):
    """A main-directory tag outside the descriptive ones (DocumentName here) is said, and --strict
    refuses; camera and GPS data are kept, so a camera's EXIF says nothing."""
    from click.testing import CliRunner

    from featurewarp_cli.cli.main import cli

    extra = Image.Exif()
    extra.load(_shot_exif(64, 48))
    extra[269] = "a document"
    for name, exif, said in (("doc.jpg", extra.tobytes(), True), ("shot.jpg", _shot_exif(64, 48), False)):
        Image.fromarray(picture()).save(tmp_path / name, "JPEG", exif=exif)
        args = ["warp", "swirl", str(tmp_path / name), str(tmp_path / "out.tif"), "--angle", "30"]
        run = CliRunner().invoke(cli, args)
        assert run.exit_code == 0, run.output
        assert ("not the input's 1 other main tag (JPEG, PNG and WebP keep them)" in run.output) == said, run.output
        assert CliRunner().invoke(cli, args + ["--strict"]).exit_code == (1 if said else 0)
    with Image.open(tmp_path / "out.tif") as written:
        assert written.getexif().get_ifd(metadata.GPS_IFD)[1] == "N"


def test_a_tiff_inputs_camera_and_gps_directories_are_kept(tmp_path):
    """A TIFF input's EXIF was read as its descriptive tags only: its capture date and GPS
    position never reached any output."""
    from click.testing import CliRunner

    from featurewarp_cli.cli.main import cli

    (tmp_path / "in.tif").write_bytes(encode.encode_image(picture(), "tiff", exif=_shot_exif(64, 48)))
    for name in ("out.jpg", "out.tif"):
        run = CliRunner().invoke(cli, ["warp", "swirl", str(tmp_path / "in.tif"), str(tmp_path / name)])
        assert run.exit_code == 0 and run.output == "", run.output
        with Image.open(tmp_path / name) as written:
            exif = written.getexif()
            assert exif.get_ifd(metadata.EXIF_IFD)[0x9003] == "2024:05:06 07:08:09", name
            assert exif.get_ifd(metadata.GPS_IFD)[1] == "N" and exif[271] == "Camera", name


@pytest.mark.parametrize("command", [["warp", "stretch", "-", "out.png", "--sx", "1.5", "-m", "mask.png"],
                                     ["warp", "swirl", "-", "out.png"],
                                     ["compare", "stretch", "-", "out.png", "--sx", "1.5", "-m", "mask.png"],
                                     ["deform", "-", "out.png", "--move", "10,10:14,12", "--pin", "50,40"]])
def test_an_input_from_stdin_keeps_its_metadata_as_a_file_does(tmp_path, monkeypatch, command):
    """An image piped in lost its profile, EXIF, XMP and resolution in silence (even with
    --strict); the same file named on the command line kept them."""
    from click.testing import CliRunner

    from featurewarp_cli.cli.main import cli

    monkeypatch.chdir(tmp_path)
    profile = srgb()                                         # it holds the time it was made
    data = encode.encode_image(picture(), "jpg", icc=profile, **carried())
    (tmp_path / "in.jpg").write_bytes(data)
    mask = np.zeros((48, 64), np.uint8)
    mask[10:30, 20:40] = 255
    cv2.imwrite(str(tmp_path / "mask.png"), mask)
    piped = CliRunner().invoke(cli, command + ["--strict"], input=data)
    assert piped.exit_code == 0 and piped.output == "", piped.output
    with Image.open(tmp_path / "out.png") as written:
        assert written.info["icc_profile"] == profile and written.info["dpi"] == pytest.approx((300, 300), abs=0.01)
        assert written.getexif()[33432] == "(c) Retoucher" and b"xmpmeta" in written.info["XML:com.adobe.xmp"].encode()
    from_pipe = (tmp_path / "out.png").read_bytes()
    named = CliRunner().invoke(cli, [("in.jpg" if arg == "-" else arg) for arg in command])
    assert named.exit_code == 0 and (tmp_path / "out.png").read_bytes() == from_pipe


@pytest.mark.parametrize("channels", [1, 3, 4])
@pytest.mark.parametrize("kept", ["all", "exif"])
def test_a_tiff_with_metadata_is_compressed_as_one_without(channels, kept):
    """Pillow's path (a TIFF with metadata) wrote LZW without the horizontal predictor:
    about 40 % larger than OpenCV's for the same pixels; the EXIF's tags stay."""
    image = cv2.GaussianBlur(picture((96, 128, channels)), (0, 0), 3)
    plain = encode.encode_image(image, "tiff")
    with_metadata = encode.encode_image(image, "tiff", **(carried() if kept == "all" else {"exif": camera_exif()}))
    with opened(with_metadata) as written:
        assert written.tag_v2[317] == 2 and np.array_equal(np.asarray(written), np.asarray(opened(plain)))
        assert written.getexif()[33432] == "(c) Retoucher"
    assert len(with_metadata) < len(plain) * 1.05 + 2000        # the metadata's own bytes aside


@pytest.mark.parametrize("name", ["out.webp", "out.png"])
def test_an_animations_exif_states_its_frames_size(tmp_path, name):
    """An animated WebP's EXIF still stated the input's 64 px width (its encoder is not
    encode_image's)."""
    from click.testing import CliRunner

    from featurewarp_cli.cli.main import cli

    source = tmp_path / "in.jpg"
    Image.fromarray(picture()).save(source, "JPEG", exif=_shot_exif(64, 48))
    run = CliRunner().invoke(cli, ["animate", "stretch", str(source), str(tmp_path / name), "--vary", "sx=1.5:2",
                                   "--frames", "2"])
    assert run.exit_code == 0, run.output
    with Image.open(tmp_path / name) as written:
        camera = written.getexif().get_ifd(metadata.EXIF_IFD)
        assert written.size[0] > 64 and (camera[metadata.PIXEL_X_DIMENSION], camera[metadata.PIXEL_Y_DIMENSION]) \
            == written.size and camera[0x9003] == "2024:05:06 07:08:09"

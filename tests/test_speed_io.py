"""The whole-command speed work: the PNG settings, the plugin fast path, and the faster
metrics, feature analysis and automatic cell, which must give the same numbers as the
straightforward formulas they replace."""

from __future__ import annotations

import struct
import subprocess
import sys
import zlib

import cv2
import numpy as np
import pytest

from featurewarp_cli.engine import features
from featurewarp_cli.engine import fidelity
from featurewarp_cli.io import ImageError, decode, encode
from featurewarp_cli.io.capture import captured_stderr
from featurewarp_cli import plugins
from featurewarp_cli.engine import quality
from featurewarp_cli.engine.grid import Grid, signed_areas


# --------------------------------------------------------------------------- PNG

def opencv_decode(data: bytes) -> np.ndarray:
    return cv2.imdecode(np.frombuffer(data, np.uint8), cv2.IMREAD_UNCHANGED)


def chunks(data: bytes) -> list[tuple[bytes, bytes]]:
    """(type, body) of each chunk, checking every CRC."""
    assert data[:8] == b"\x89PNG\r\n\x1a\n"
    out, i = [], 8
    while i < len(data):
        (length,) = struct.unpack_from(">I", data, i)
        kind, body = data[i + 4 : i + 8], data[i + 8 : i + 8 + length]
        assert struct.unpack_from(">I", data, i + 8 + length)[0] == zlib.crc32(kind + body)
        out.append((kind, body))
        i += 12 + length
    return out


def expected_decode(image: np.ndarray) -> np.ndarray:
    """What OpenCV gives back for ``image``: gray + alpha comes back as BGRA."""
    if image.ndim == 3 and image.shape[2] == 2:
        return np.dstack([image[:, :, 0]] * 3 + [image[:, :, 1]])
    if image.ndim == 3 and image.shape[2] == 1:
        return image[:, :, 0]
    return image


@pytest.mark.parametrize("dtype", [np.uint8, np.uint16])
@pytest.mark.parametrize("channels", [None, 1, 2, 3, 4])
@pytest.mark.parametrize("size", [(1, 1), (1, 9), (7, 1), (33, 47), (120, 700)])
def test_png_is_lossless(rng, dtype, channels, size):
    """Every depth and channel count decodes to the same samples (noise and smooth ramps),
    in a PNG that holds the pixels only (no metadata chunk) and comes out the same twice."""
    shape = size if channels is None else size + (channels,)
    top = np.iinfo(dtype).max
    noise = rng.integers(0, top + 1, shape, dtype=dtype)
    ramp = (np.linspace(0, top, size[1])[None, :] * np.ones(size)).astype(dtype)
    ramp = ramp if channels is None else np.repeat(ramp[:, :, None], channels, axis=2)
    for image in (noise, ramp):
        data = encode.encode_image(image, "png")
        assert {kind for kind, _ in chunks(data)} == {b"IHDR", b"IDAT", b"IEND"}
        assert encode.encode_image(image, "png") == data
        back = opencv_decode(data)
        assert back is not None and back.dtype == dtype
        np.testing.assert_array_equal(back, expected_decode(image))


def test_png_of_a_view_and_of_a_copy_are_the_same(rng):
    """Strided views (a crop, reversed channels) encode like their contiguous copies."""
    big = rng.integers(0, 65536, (50, 80, 4), dtype=np.uint16)
    view = big[5:45:2, 10:70, 2::-1]
    data = encode.encode_image(view, "png")
    assert data == encode.encode_image(np.ascontiguousarray(view), "png")
    np.testing.assert_array_equal(opencv_decode(data), view)


@pytest.mark.parametrize("fmt", ["png", "jpg", "webp", "tiff", "bmp"])
def test_encoders_refuse_what_they_cannot_store(fmt):
    with pytest.raises(ImageError, match="float32"):
        encode.encode_image(np.zeros((4, 4), np.float32), fmt)
    with pytest.raises(ImageError, match="5 channels"):
        encode.encode_image(np.zeros((4, 4, 5), np.uint8), fmt)


# --------------------------------------------------------------------------- masks

@pytest.mark.parametrize("dtype", [np.uint8, np.uint16])
@pytest.mark.parametrize("channels", [None, 1, 3, 4])
def test_mask_threshold_is_the_float_comparison(rng, dtype, channels):
    """mask_from_image compares integers where the float formula is exact: same masks."""
    top = np.iinfo(dtype).max
    shape = (40, 50) if channels is None else (40, 50, channels)
    image = rng.integers(0, top + 1, shape, dtype=dtype)
    image.flat[:6] = [127, 128, 129, 32895, 32896, 32897] if dtype == np.uint16 else [127, 128, 129, 0, 255, 1]
    if channels is None:
        gray = image.astype(np.float64)
    else:
        colour = image[:, :, :3] if channels >= 3 else image[:, :, :1]
        gray = (cv2.cvtColor(colour, cv2.COLOR_BGR2GRAY) if channels >= 3 else colour[:, :, 0]).astype(np.float64)
        if channels == 4:
            gray = gray * image[:, :, 3] / top
    np.testing.assert_array_equal(decode.mask_from_image(image), gray >= 128 * top / 255)


# --------------------------------------------------------------------------- plugins

def test_builtin_table_matches_the_entry_points():
    """plugins.BUILTIN lists exactly what pyproject.toml registers for this package."""
    registered = {ep.name: ep.value for ep in plugins.entry_points() if ep.value.startswith("featurewarp_warps.")}
    assert registered == plugins.BUILTIN


def test_warp_command_does_not_scan_entry_points():
    """Resolving and loading a built-in preset imports no importlib.metadata."""
    code = ("import sys; from featurewarp_cli.cli import main as cli; from featurewarp_cli import plugins; "
            "assert cli.PresetGroup(name='warp').get_command(None, 'swirl') is not None; "
            "print('importlib.metadata' in sys.modules)")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "False"


# --------------------------------------------------------------------------- metrics

def reference_pl_error(grid, warp):
    """pl_error as first written: the largest np.linalg.norm of the midpoint gaps."""
    nodes = grid.nodes().reshape(grid.ny, grid.nx, 2)
    warped = warp(nodes.reshape(-1, 2)).reshape(grid.ny, grid.nx, 2)
    worst = 0.0
    for a, b, wa, wb in ((nodes[:, :-1], nodes[:, 1:], warped[:, :-1], warped[:, 1:]),
                         (nodes[:-1, :], nodes[1:, :], warped[:-1, :], warped[1:, :]),
                         (nodes[:-1, :-1], nodes[1:, 1:], warped[:-1, :-1], warped[1:, 1:])):
        middle = warp(((a + b) / 2.0).reshape(-1, 2))
        gap = np.linalg.norm(middle - ((wa + wb) / 2.0).reshape(-1, 2), axis=1)
        worst = max(worst, float(gap.max(initial=0.0)))
    return worst


@pytest.mark.parametrize("preset, params", [("swirl", {"angle": 200}), ("arc", {"angle": 120}),
                                            ("bulge", {"strength": 0.8}), ("stretch", {"sx": 0.7, "sy": 1.6})])
def test_grid_fidelity_numbers_are_unchanged(rng, preset, params):
    """pl_error's midpoints and the smallest triangle area are bit for bit the straightforward
    formulas (pl_error adds a lattice of points inside the cells: at least as large)."""
    w, h = 157, 93
    warp = plugins.load(preset)(w, h, **params)
    for cell in (1.0, 2.7, 4.0, 13.0):
        grid = Grid.for_image(w, h, cell)
        assert fidelity._deviation(grid, warp)[0] == reference_pl_error(grid, warp)
        assert fidelity.pl_error(grid, warp) >= reference_pl_error(grid, warp)
        points = warp(grid.nodes())
        for pts in (points, points + rng.normal(0, cell / 2, points.shape)):
            expected = signed_areas(pts, grid.triangles()).min()
            assert fidelity.smallest_area(pts.reshape(grid.ny, grid.nx, 2)) == expected


def test_quality_numbers_are_unchanged(rng):
    """background_rms and the per-label bounding boxes are bit for bit the former formulas
    (np.roll on gathered (K, 4, 2) blocks; np.minimum.at / np.maximum.at), absent labels included."""
    points, warped = rng.normal(size=(500, 2)), rng.normal(size=(500, 2))
    quads = rng.integers(0, 500, (300, 4))
    got = np.roll(points[quads], -1, axis=1) - points[quads]
    want = np.roll(warped[quads], -1, axis=1) - warped[quads]
    assert quality.background_rms(points, warped, quads) == float(np.sqrt(((got - want) ** 2).sum(axis=2).mean()))
    assert quality.background_rms(points, warped, quads[:0]) == 0.0
    labels = rng.integers(0, 9, 500)
    labels[labels == 4] = 5                                   # label 4 is absent
    lo, hi = np.full((9, 2), np.inf), np.full((9, 2), -np.inf)
    np.minimum.at(lo, labels, points)
    np.maximum.at(hi, labels, points)
    fits = quality.similarity_fits(points, warped, labels, 9)
    np.testing.assert_array_equal(fits["diameter_px"], np.hypot(*(hi - lo).T))


def test_feature_distances_are_exact_and_repeatable(rng):
    """Transition weights come from exact distances (sqrt of a whole number of squared
    pixels), the same on every call, whatever OpenCV's float32 rounding does."""
    for _ in range(30):
        h, w = (int(v) for v in rng.integers(8, 120, 2))
        mask = rng.random((h, w)) < 0.01
        mask[:4], mask[-4:], mask[:, :4], mask[:, -4:] = False, False, False, False  # nothing in the outer
        mask[h // 2, w // 2] = True        # cells, which features.short_of_frame would drop
        grid = Grid.for_image(w, h, 3.0)
        first = features.analyse(mask, grid)
        for _ in range(3):
            again = features.analyse(mask.copy(), grid)
            np.testing.assert_array_equal(again.weight, first.weight)
        # reference: brute-force distance from each quad centre to the nearest feature pixel
        sx, sy = grid.spacing
        qy, qx = grid.quad_shape
        cx = np.clip(np.round((np.arange(qx) + 0.5) * sx - 0.5).astype(int), 0, w - 1)
        cy = np.clip(np.round((np.arange(qy) + 0.5) * sy - 0.5).astype(int), 0, h - 1)
        fy, fx = np.nonzero(mask)
        squared = (cy[:, None, None] - fy) ** 2 + (cx[None, :, None] - fx) ** 2     # (qy, qx, features)
        distance = np.sqrt(squared.min(axis=2).astype(np.float64)).astype(np.float32) / ((sx + sy) / 2.0)
        f = np.where(first.is_feature.reshape(qy, qx), 1.0, features.decay(distance, 2.0))
        np.testing.assert_array_equal(first.weight, (10.0 * f + (1.0 - f)).ravel())


def test_feature_pooling_is_a_max_over_each_quads_pixels(rng):
    """A quad is a feature quad when any pixel the grid assigns to it is one."""
    mask = rng.random((97, 131)) < 0.003
    for cell in (1.0, 2.5, 4.0, 7.3):
        grid = Grid.for_image(131, 97, cell)
        rows, cols = grid.quad_of_pixel()
        expected = np.zeros(grid.quad_shape, bool)
        np.logical_or.at(expected, (rows[:, None], cols[None, :]), mask)
        np.testing.assert_array_equal(features._pooled(mask, grid).astype(bool), expected)
        inner = mask.copy()                 # analyse pools the same, less short_of_frame's drops
        inner[:8], inner[-8:], inner[:, :8], inner[:, -8:] = False, False, False, False
        expected[:] = False
        np.logical_or.at(expected, (rows[:, None], cols[None, :]), inner)
        np.testing.assert_array_equal(features.analyse(inner, grid).is_feature, expected.ravel())


@pytest.mark.parametrize("cell", [1.0, 3.0, 4.0, 9.5])
def test_quad_jacobians_are_the_einsum_numbers(rng, cell):
    """targets.quad_jacobians is bit for bit einsum over the gathered corners, as first written."""
    from featurewarp_cli.engine import targets

    grid = Grid.for_image(203, 121, cell)
    warped = grid.nodes() @ rng.normal(size=(2, 2)) + rng.normal(0, cell, (grid.n_nodes, 2))
    sx, sy = grid.spacing
    u = np.array([[-sx, -sy], [sx, -sy], [sx, sy], [-sx, sy]]) / 2.0
    expected = np.einsum("kcd,ce->kde", warped[grid.quads()], u) / np.array([sx * sx, sy * sy])
    np.testing.assert_array_equal(targets.quad_jacobians(grid, warped), expected)


def test_notices_printed_during_a_decode_still_show(capfd):
    """While INPUT decodes in a thread, file descriptor 2 is captured for the decoder's
    warnings; a featurewarp notice printed meanwhile is shown afterwards, not swallowed."""
    import os

    with captured_stderr() as lines:
        os.write(2, b"featurewarp: a notice from another thread\nlibpng warning: iCCP: something\n")
    assert lines == ["libpng warning: iCCP: something"]
    assert "featurewarp: a notice from another thread" in capfd.readouterr().err


def test_input_decodes_while_the_mesh_is_solved(tmp_path, monkeypatch):
    """warp_file starts decoding INPUT in a thread when its header gives the size; the
    result equals the serial path's."""
    import threading
    from concurrent.futures import Future

    import cv2
    import numpy as np

    from featurewarp_cli.app import pipeline as batch

    rng = np.random.default_rng(3)
    image = rng.integers(0, 255, (36, 48, 3), dtype=np.uint8)
    mask = np.zeros((36, 48), np.uint8)
    mask[10:25, 15:30] = 255
    cv2.imwrite(str(tmp_path / "in.png"), image)
    cv2.imwrite(str(tmp_path / "m.png"), mask)
    settings = batch.Settings(preset="swirl", params={"angle": 90.0})
    started = []
    start = threading.Thread.start

    def spy(thread):
        started.append(thread.name)
        start(thread)

    monkeypatch.setattr(threading.Thread, "start", spy)
    batch.warp_file(settings, str(tmp_path / "in.png"), str(tmp_path / "a.png"), str(tmp_path / "m.png"))
    assert "featurewarp-decode" in started
    serial = batch.load_image_and_mask(settings, str(tmp_path / "in.png"), str(tmp_path / "m.png"))
    decoded = Future()
    decoded.set_result(serial[0])
    decoded.start = lambda: None            # decoding starts once the checks without pixels pass
    monkeypatch.setattr(batch, "start_loading", lambda s, i, m, *piped: (decoded, serial[1], serial[2], (48, 36)))
    batch.warp_file(settings, str(tmp_path / "in.png"), str(tmp_path / "b.png"), str(tmp_path / "m.png"))
    assert (tmp_path / "a.png").read_bytes() == (tmp_path / "b.png").read_bytes()

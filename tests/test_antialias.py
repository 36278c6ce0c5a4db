"""The minification filter (featurewarp_cli/render/antialias.py, pyramid.py) against its invariants: a
shrink is about as sharp as cv2.resize's, keeps no jump in sharpness as the scale moves, leaves
no moire on a zone plate (against an analytic, supersampled reference), keeps the axis that is
not shrunk, honours --interp, and gives the same bytes on every machine, band split and thread
count (its level filters are exact integer sums)."""

from __future__ import annotations

import os

import cv2
import numpy as np
import pytest

from featurewarp_cli.engine.grid import Grid
from featurewarp_cli.engine.warper import load_warp
from featurewarp_cli.render import antialias, pyramid
from featurewarp_cli.render import raster as render

SAMPLES = os.path.join(os.path.dirname(os.path.dirname(os.path.abspath(__file__))), "samples")


def warp_mesh(width, height, preset="stretch", cell=8, **params):
    """The plain warp's mesh of a width x height image (W applied to the grid's nodes)."""
    grid = Grid.for_image(width, height, cell)
    w = load_warp(preset)(width, height, **params)
    return grid.nodes(), w(grid.nodes()), grid.triangles(), tuple(w.canvas)


@pytest.fixture(scope="module")
def china():
    return cv2.imread(os.path.join(SAMPLES, "china.png"))


def sharpness(image):
    """Variance of the Laplacian of the grey image (2-pixel border left out)."""
    grey = cv2.cvtColor(image, cv2.COLOR_BGR2GRAY) if image.ndim == 3 else image
    return cv2.Laplacian(grey.astype(np.float64), cv2.CV_64F)[2:-2, 2:-2].var()


def shrink(image, sx, sy=None, interp="cubic", **kw):
    h, w = image.shape[:2]
    return render.render(image, *warp_mesh(w, h, sx=sx, sy=sx if sy is None else sy), interp, (255, 255, 255), **kw)


@pytest.mark.parametrize("scale", [0.95, 0.9, 0.75, 0.5, 0.25])
def test_a_shrink_is_about_as_sharp_as_cv2_resize(china, scale):
    """A uniform shrink keeps at least 0.7 of the sharpness of cv2.resize's area average (a
    box filter: sharp where the factor is an integer, aliased; softer in between). The
    Gaussian pyramid kept 0.13 of it at 0.5 and 0.8 at 0.9."""
    out = shrink(china, scale)
    area = sharpness(cv2.resize(china, (out.shape[1], out.shape[0]), interpolation=cv2.INTER_AREA))
    assert sharpness(out) >= 0.7 * area


def test_sharpness_has_no_jump_across_scales(china):
    """From 0.80 to 0.995 in steps of 0.005, the sharpness moves less than 8 % a step (the
    pyramid lost 60 % from 0.910 to 0.909, where its filter began)."""
    scales = np.round(np.arange(0.80, 0.9951, 0.005), 3)
    values = np.array([sharpness(shrink(china, s)) for s in scales])
    steps = np.abs(np.diff(values)) / values[:-1]
    assert steps.max() < 0.08, (scales[steps.argmax()], steps.max())


def test_the_filter_starts_from_nothing(china):
    """Just above the start of the filter (a shrink of 1 / AA_START), the image is the plain
    sample's but for rounding; no pixel jumps."""
    scale = 1 / antialias.AA_START
    below, above = (shrink(china[:200, :300], scale * f).astype(int) for f in (1.0002, 0.9998))
    plain = shrink(china[:200, :300], scale * 0.9998, antialias=False).astype(int)
    assert below.shape == above.shape == plain.shape
    assert np.abs(above - plain)[2:-2, 2:-2].max() <= 2
    assert np.abs(above - below)[2:-2, 2:-2].mean() < 0.5


ZONE = 512


def zone_plate_at(x, y):
    """A zone plate whose local frequency grows from 0 at the centre to Nyquist at its edge."""
    x, y = x - ZONE / 2 + 0.5, y - ZONE / 2 + 0.5
    return 127.5 + 127.5 * np.cos(np.pi * (x * x + y * y) / ZONE)


def zone_plate_errors(mesh):
    """RMS distance to the zone plate's 4x supersampled, box-filtered truth (evaluated at the
    exact source positions, no raster) of the filtered render and of the plain one."""
    source, target, triangles, canvas = mesh
    coords, covered = render.inverse_map(source, (target + 0.5) * 4 - 0.5, triangles, (canvas[0] * 4, canvas[1] * 4))
    truth = zone_plate_at(coords[..., 0].astype(float), coords[..., 1].astype(float))
    truth = cv2.resize(truth, canvas, interpolation=cv2.INTER_AREA)
    inside = cv2.resize(covered.astype(float), canvas, interpolation=cv2.INTER_AREA) > 0.999
    ys, xs = np.mgrid[0:ZONE, 0:ZONE].astype(float)
    plate = np.rint(zone_plate_at(xs, ys)).astype(np.uint8)
    errors = []
    for antialiased in (True, False):
        out = render.render(plate, *mesh, "cubic", (127, 127, 127), antialias=antialiased).astype(float)
        errors.append(np.sqrt(np.mean((out[inside] - truth[inside]) ** 2)))
    return errors


@pytest.mark.parametrize("preset, params, ratio", [
    ("stretch", dict(sx=0.5, sy=0.5), 0.7), ("stretch", dict(sx=0.3, sy=0.3), 0.3),
    ("stretch", dict(sx=0.5, sy=1.0), 0.5), ("perspective", {}, 0.95), ("fish", {}, 0.9)])
def test_no_moire_on_a_zone_plate(preset, params, ratio):
    """Shrunk uniformly, along one axis, in perspective or by the fish, the zone plate comes
    out closer to its supersampled truth than the plain sample by the ratio (the plain
    sample's error is mostly moire; the Gaussian pyramid's was mostly blur: 1.9 and 1.4 times
    the new filter's at 0.5 and 0.3)."""
    filtered, plain = zone_plate_errors(warp_mesh(ZONE, ZONE, preset, **params))
    assert filtered < ratio * plain


def test_a_fine_checkerboard_shrinks_to_grey():
    """A one-pixel checkerboard shrunk to 0.5 and 0.3 is grey, without a beat."""
    board = ((np.add.outer(np.arange(300), np.arange(400)) % 2) * 255).astype(np.uint8)
    for scale in (0.5, 0.3):
        out = shrink(board, scale).astype(float)[3:-3, 3:-3]
        assert abs(out.mean() - 127.5) < 2 and out.std() < 4, (scale, out.mean(), out.std())


def test_the_axis_not_shrunk_stays_sharp(china):
    """Squeezed to 0.5 across, an image of rows (each row one random value) keeps every row
    as it was: the filter works along the shrunk axis only. On the photo, the vertical
    second differences keep 3/4 of those of cv2's area average (the filter across the
    rows takes some of them with it)."""
    rows = np.random.default_rng(2).integers(0, 256, (120, 1), dtype=np.uint8).repeat(200, axis=1)
    out = shrink(cv2.merge([rows] * 3), 0.5, 1.0)
    assert out.shape[:2] == (120, 100)
    assert np.abs(out.astype(int) - rows[:, :100, None])[:, 2:-2].max() <= 1
    out = shrink(china, 0.5, 1.0)
    area = cv2.resize(china, (out.shape[1], out.shape[0]), interpolation=cv2.INTER_AREA)

    def vertical(image):
        return np.diff(cv2.cvtColor(image, cv2.COLOR_BGR2GRAY).astype(float), 2, axis=0)[4:-4, 4:-4].var()

    assert vertical(out) >= 0.75 * vertical(area)


def test_interp_is_honoured_under_minification(china):
    """The levels are sampled with --interp: cubic, lanczos and linear differ at 0.5 (they
    were byte-identical), lanczos the sharpest, linear the softest."""
    outs = {interp: shrink(china, 0.5, interp=interp) for interp in ("linear", "cubic", "lanczos")}
    assert not np.array_equal(outs["cubic"], outs["lanczos"])
    assert sharpness(outs["linear"]) < sharpness(outs["cubic"]) < sharpness(outs["lanczos"])


@pytest.mark.parametrize("taps, halve", [(pyramid.SUBLEVEL_TAPS[0], False), (pyramid.SUBLEVEL_TAPS[-1], False),
                                         (pyramid.HALVING_TAPS, True)])
@pytest.mark.parametrize("depth", [np.uint8, np.uint16])
def test_levels_are_exact_integer_sums(monkeypatch, taps, halve, depth):
    """Every level is the float64 filter of its octave, rounded: 8-bit through OpenCV's
    float32 buffers, 16-bit in stripes of rows (forced small here); odd sizes keep their
    last row and column when halved."""
    monkeypatch.setattr(pyramid, "STRIPE_VALUES", 500)
    rng = np.random.default_rng(5)
    top = np.iinfo(depth).max
    for shape in [(61, 47, 3), (40, 38), (9, 4, 4)]:
        image = rng.integers(0, top, shape, dtype=depth, endpoint=True)
        kernel = np.asarray(taps, float) / 2 ** pyramid.TAP_BITS
        kernel = np.concatenate([kernel[::-1], kernel] if halve else [kernel[:0:-1], kernel])
        padded = cv2.copyMakeBorder(image, 0, shape[0] % 2, 0, shape[1] % 2, cv2.BORDER_REPLICATE) if halve else image
        expected = cv2.sepFilter2D(padded.astype(np.float64), cv2.CV_64F, kernel, kernel, borderType=cv2.BORDER_REPLICATE)
        expected = np.clip(np.rint(expected[1::2, 1::2] if halve else expected), 0, top).astype(depth)
        np.testing.assert_array_equal(pyramid._separable(image, taps, halve), expected.reshape(-1, *expected.shape[1:]))


@pytest.mark.parametrize("interp", ["cubic", "lanczos"])
@pytest.mark.parametrize("kind", ["gray8", "bgr16", "bgra8"])
def test_minified_render_does_not_depend_on_bands_or_threads(interp, kind):
    """Perspective and a strong anisotropic shrink, every kind of image: bands of 700 pixels
    in two threads give the bytes of one band in one thread."""
    rng = np.random.default_rng(7)
    depth = np.uint16 if kind.endswith("16") else np.uint8
    channels = {"gray": 1, "bgr": 3, "bgra": 4}[kind.rstrip("0123456789")]
    image = rng.integers(0, np.iinfo(depth).max, (90, 120, channels), dtype=depth, endpoint=True)
    image = cv2.GaussianBlur(image, (3, 3), 0).reshape(image.shape)
    if channels == 4:
        image[..., 3] = np.where(np.arange(120) < 60, np.iinfo(depth).max, np.iinfo(depth).max // 3)
    image = image[..., 0] if channels == 1 else image
    for mesh in (warp_mesh(120, 90, "perspective", cell=6), warp_mesh(120, 90, sx=0.2, sy=0.7, cell=6)):
        whole = render.render(image, *mesh, interp, None, band_pixels=10 ** 9, threads=1)
        banded = render.render(image, *mesh, interp, None, band_pixels=700, threads=2)
        assert whole.dtype == image.dtype
        np.testing.assert_array_equal(banded, whole)


def test_octaves_prepared_ahead_render_the_same_and_go_with_their_run():
    """The command line builds the first octaves while the mesh is solved (pyramid.prepare from
    the decoding thread, kept by its run's decoding): the render is the same whether they were
    ready or not; they are taken once, by the image they were made of; another image's render
    does not take them; they go with their holder (a refused run's); and a prepare that ends
    after its image's render began keeps nothing (a review found such octaves held after the run)."""
    import gc

    class SimpleNamespace:                              # a run's decoding: weakly referable
        pass

    image = (np.random.default_rng(3).integers(0, 255, (90, 120, 3))).astype(np.uint8)
    mesh = warp_mesh(120, 90, sx=0.2, sy=0.7, cell=6)
    plain = render.render(image.copy(), *mesh, "cubic", None, threads=1)
    run = SimpleNamespace()
    pyramid.prepare(image, run)
    assert len(run.octaves[1]) == pyramid.AHEAD_OCTAVES + 1
    np.testing.assert_array_equal(render.render(image, *mesh, "cubic", None, threads=1), plain)
    assert run.octaves is None                          # taken
    pyramid.prepare(image, run)
    np.testing.assert_array_equal(render.render(image.copy(), *mesh, "cubic", None, threads=1), plain)
    assert run.octaves is None                          # dropped: not its image
    refused = SimpleNamespace()
    pyramid.prepare(image, refused)
    held = pyramid._prepared[0]
    del refused
    gc.collect()
    assert held() is None                               # nothing outlives its run
    late = SimpleNamespace()
    other = image.copy()
    np.testing.assert_array_equal(render.render(other, *mesh, "cubic", None, threads=1), plain)
    pyramid.prepare(other, late)                        # its render began without them
    assert getattr(late, "octaves", None) is None and not any(ref() is late for ref in pyramid._prepared)
    pyramid.prepare(np.dstack([image, image[:, :, :1]]), late)      # alpha: resampled premultiplied
    assert getattr(late, "octaves", None) is None


def test_pyramid_levels_sit_where_the_filter_expects():
    """A level's pixel i lies on source (i + 0.5) 2^o - 0.5: a linear ramp sampled through
    any level (octaves 0 to 3) gives back the ramp's value at the source position."""
    ramp = np.tile(np.arange(256, dtype=np.uint16)[None, :] * 64, (64, 1))
    levels = pyramid.Pyramid(ramp)
    x = np.float32([40.0, 100.25, 177.5])
    for level in (0, 3, 8, 13, 16, 27):
        px, py = x.copy(), np.full(3, 30.0, np.float32)
        px *= np.float32(2.0 ** -level)            # as the compiled aa_probes places them
        py *= np.float32(2.0 ** -level)
        pyramid._to_level(px, py, level)
        got = pyramid.sample_points(levels[level], px, py, cv2.INTER_LINEAR)[:, 0].astype(float)
        np.testing.assert_allclose(got, x * 64, atol=2.0)


@pytest.mark.parametrize("kind", ["gray8", "bgr16", "bgra8"])
def test_levels_filtered_in_windows_equal_whole_levels(monkeypatch, kind):
    """A band filters a level over the window its probes reach unless that is most of the
    level: always windows or always whole levels, the bytes are the same (perspective, a
    strong shrink, a random mesh)."""
    from test_render import random_mesh

    rng = np.random.default_rng(11)
    depth = np.uint16 if kind.endswith("16") else np.uint8
    channels = {"gray": 1, "bgr": 3, "bgra": 4}[kind.rstrip("0123456789")]
    image = cv2.GaussianBlur(rng.integers(0, np.iinfo(depth).max, (50, 70, channels), dtype=depth, endpoint=True),
                             (3, 3), 0).reshape(50, 70, channels)
    image = image[..., 0] if channels == 1 else image
    meshes = (warp_mesh(70, 50, "perspective", cell=5), warp_mesh(70, 50, sx=0.3, sy=0.45, cell=5), random_mesh(3))
    for mesh in meshes:
        outs = []
        for share in (0.0, 10.0):
            monkeypatch.setattr(pyramid, "WHOLE_LEVEL_SHARE", share)
            outs.append(render.render(image, *mesh, "cubic", None, band_pixels=500, threads=1))
        np.testing.assert_array_equal(outs[0], outs[1])

"""The yardstick: distortion measured on the output image by a keypoint affine fit.

Validated on exact affine maps of a real photo (cv2.warpAffine by a known matrix):
the measured distortion, scale and rotation must match the matrix's.
"""

from __future__ import annotations

import json
from pathlib import Path

import cv2
import numpy as np
import pytest

from featurewarp_cli.app.measure import describe, measure, worst
from test_cli import runner  # noqa: F401  (fixture)

SAMPLES = Path(__file__).resolve().parent.parent / "samples"


@pytest.fixture(scope="module")
def astronaut():
    """(image, mask): the astronaut sample and its three-component mask (head, patch, shuttle)."""
    image = cv2.imread(str(SAMPLES / "astronaut.png"))
    mask = cv2.imread(str(SAMPLES / "astronaut_mask.png"), cv2.IMREAD_GRAYSCALE) >= 128
    return image, mask


def anisotropic(ratio: float, degrees: float, scale: float = 1.0) -> np.ndarray:
    """A 2x2 map: stretch by sqrt(ratio) along x and shrink by it along y, then rotate."""
    t = np.radians(degrees)
    rotation = np.array([[np.cos(t), -np.sin(t)], [np.sin(t), np.cos(t)]])
    return scale * rotation @ np.diag([np.sqrt(ratio), 1.0 / np.sqrt(ratio)])


def centre_error(fit, matrix: np.ndarray) -> float:
    """Distance in output pixels between where the fit and ``matrix`` put the component's box centre."""
    x, y, w, h = fit.bbox
    centre = np.array([x + (w - 1) / 2.0, y + (h - 1) / 2.0])
    return float(np.hypot(*(fit.linear @ centre + fit.translation - matrix[:, :2] @ centre - matrix[:, 2])))


def warp_affine(image: np.ndarray, linear: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``image`` mapped by ``linear`` onto a canvas that holds all of it; the 2x3 matrix used."""
    h, w = image.shape[:2]
    corners = np.array([[0, 0], [w, 0], [0, h], [w, h]], float) @ linear.T
    matrix = np.hstack([linear, -corners.min(axis=0)[:, None]])
    size = np.ceil(corners.max(axis=0) - corners.min(axis=0)).astype(int)
    return cv2.warpAffine(image, matrix, (int(size[0]), int(size[1])), flags=cv2.INTER_CUBIC), matrix


@pytest.mark.parametrize("ratio, degrees, scale", [
    (1.0, 0.0, 1.0), (1.2, 0.0, 1.0), (2.0, 0.0, 1.0), (1.0, 40.0, 0.8), (2.0, 135.0, 1.1)])
def test_exact_affine_is_measured_within_0_01(astronaut, ratio, degrees, scale):
    image, mask = astronaut
    linear = anisotropic(ratio, degrees, scale)
    output, matrix = warp_affine(image, linear)
    fits = measure(image, output, mask)
    assert len(fits) == 3
    for fit in fits:
        assert fit.distortion == pytest.approx(ratio - 1.0, abs=0.01), fit
        assert fit.scale == pytest.approx(scale, abs=0.01)
        assert fit.rotation == pytest.approx(degrees, abs=0.5)
        assert np.abs(fit.linear - linear).max() < 0.01
        assert centre_error(fit, matrix) < 0.5
        assert fit.inliers >= 10 and not fit.reflected


def test_rotation_is_clockwise_on_screen():
    # y points down: (1, 0) -> (0, 1) turns the x axis towards the bottom, clockwise as seen.
    assert describe(np.array([[0.0, -1.0], [1.0, 0.0]]))["rotation"] == pytest.approx(90.0)


def test_describe_a_mirror():
    d = describe(np.array([[-2.0, 0.0], [0.0, 2.0]]))
    assert d["reflected"] and d["distortion"] == pytest.approx(0.0) and d["scale"] == pytest.approx(2.0)


def test_a_component_that_fills_the_frame(astronaut):
    image, _ = astronaut
    output, _ = warp_affine(image, anisotropic(1.0, -30.0))
    (fit,) = measure(image, output, np.ones(image.shape[:2], bool))
    assert fit.distortion == pytest.approx(0.0, abs=0.01) and fit.rotation == pytest.approx(-30.0, abs=0.5)
    assert fit.coverage > 0.8


def test_too_small_for_keypoints_is_not_measured(astronaut):
    image, _ = astronaut
    mask = np.zeros(image.shape[:2], bool)
    mask[300:303, 300:303] = True                   # 9 px on the suit
    (fit,) = measure(image, image, mask)
    assert fit.distortion is None and fit.scale is None and fit.linear is None
    assert "fewer than" in fit.reason
    assert worst([fit]) is None


def test_empty_mask_measures_nothing(astronaut):
    image, _ = astronaut
    assert measure(image, image, np.zeros(image.shape[:2], bool)) == []


def test_mask_of_another_size_is_refused(astronaut):
    image, mask = astronaut
    with pytest.raises(ValueError, match="the mask is 100x512"):
        measure(image, image, mask[:, :100])


@pytest.mark.parametrize("share", [2, 6])
def test_downscaled_measure_reports_full_size_figures(astronaut, share):
    """Measured at about 0.71 and 0.41 of the size (what a 24 MP photo gets): the figures are
    the full-size ones, and an affine map is not read as bent (at 0.41 the shuttle keeps 100
    matches, a few of them stray: 88 % explained; the patch, 1 000 px there, gets 15 matches
    and no trustworthy figure, as before, so only regions of 10 000 px and more count)."""
    image, mask = astronaut
    linear = anisotropic(1.5, 20.0)
    output, matrix = warp_affine(image, linear)
    fits = measure(image, output, mask, max_pixels=image.shape[0] * image.shape[1] // share)
    for fit in [f for f in fits if share == 2 or f.pixels >= 10_000]:
        assert fit.distortion == pytest.approx(0.5, abs=0.02 if share > 2 else 0.01)
        assert fit.explained >= (0.85 if share > 2 else 0.9)
        assert centre_error(fit, matrix) < (4.0 if share > 2 else 1.0)     # 1.6 px where measured


def test_transparent_canvas_and_16_bit(astronaut):
    image, mask = astronaut
    linear = anisotropic(1.2, 10.0)
    bgra = cv2.cvtColor(image, cv2.COLOR_BGR2BGRA)
    output, _ = warp_affine(bgra, linear)           # transparent outside the picture
    fits = measure(image.astype(np.uint16) * 257, output, mask)
    assert all(f.distortion == pytest.approx(0.2, abs=0.01) for f in fits)


def test_measure_command(runner, tmp_path, astronaut):
    image, mask = astronaut
    output, _ = warp_affine(image, anisotropic(2.0, 0.0))
    paths = {}
    for name, picture in (("in", image), ("out", output), ("mask", mask.astype(np.uint8) * 255)):
        paths[name] = tmp_path / f"{name}.png"
        cv2.imwrite(str(paths[name]), picture)
    run = runner("measure", paths["in"], paths["out"], "-m", paths["mask"], "--json")
    assert run.code == 0 and run.stderr == ""
    report = json.loads(run.stdout)
    assert [c["label"] for c in report["components"]] == [1, 2, 3]
    assert report["worst_distortion"] == pytest.approx(1.0, abs=0.01)
    text = runner("measure", paths["in"], paths["out"], "-m", paths["mask"])
    assert text.code == 0 and len(text.stdout.decode().splitlines()) == 3
    assert "distortion 1.00" in text.stdout.decode() and "(noise 0.00" in text.stdout.decode()


def test_measure_command_bad_input(runner, tmp_path, astronaut):
    image, _ = astronaut
    cv2.imwrite(str(tmp_path / "in.png"), image)
    cv2.imwrite(str(tmp_path / "small.png"), np.zeros((10, 10), np.uint8))
    missing = runner("measure", tmp_path / "in.png", tmp_path / "nope.png", "-m", tmp_path / "small.png")
    assert missing.code == 2 and len(missing.lines) == 1 and "does not exist" in missing.stderr
    wrong = runner("measure", tmp_path / "in.png", tmp_path / "in.png", "-m", tmp_path / "small.png")
    assert wrong.code == 2 and len(wrong.lines) == 1 and "mask is 10x10 but the image is 512x512" in wrong.stderr
    # the pixel and memory limits of warp (three 400 MP bombs decoded to 4.4 GB, with no limit)
    big = runner("measure", tmp_path / "in.png", tmp_path / "in.png", "-m", tmp_path / "in.png", "--max-pixels", "1000")
    assert big.code == 1 and len(big.lines) == 1 and "--max-pixels" in big.stderr
    big = runner("measure", tmp_path / "in.png", tmp_path / "in.png", "-m", tmp_path / "in.png", "--max-memory", "1K")
    assert big.code == 1 and len(big.lines) == 1 and "--max-memory" in big.stderr


def swirled(image: np.ndarray, degrees: float) -> np.ndarray:
    """``image`` under the swirl preset (radius 0.5), resampled exactly: its inverse is the
    swirl by -degrees, since each circle about the centre maps onto itself."""
    from featurewarp_cli import load_warp

    h, w = image.shape[:2]
    y, x = np.mgrid[0:h, 0:w].astype(np.float64)
    back = load_warp("swirl")(w, h, angle=-degrees)(np.column_stack([x.ravel(), y.ravel()]))
    maps = back.reshape(h, w, 2).astype(np.float32)
    return cv2.remap(image, maps[:, :, 0], maps[:, :, 1], cv2.INTER_CUBIC, borderMode=cv2.BORDER_REFLECT)


def test_a_bent_component_is_told_apart_from_a_kept_one():
    # The close-up's mask covers 81 % of the frame; a plain swirl leaves its rim in place
    # and turns the face: the global fit is near the identity, the local fits are not.
    image = cv2.imread(str(SAMPLES / "closeup.png"))
    mask = cv2.imread(str(SAMPLES / "closeup_mask.png"), cv2.IMREAD_GRAYSCALE) >= 128
    (bent,) = measure(image, swirled(image, 180.0), mask)
    assert bent.explained < 0.95 and bent.local_p90 > 0.15
    kept, _ = warp_affine(image, anisotropic(1.0, 90.0, 1.3))
    (fit,) = measure(image, kept, mask)
    assert fit.explained > 0.98 and fit.local_p90 < 0.05 and fit.distortion < 0.01


def test_too_few_precise_matches_keep_the_ransac_map(monkeypatch):
    """Where fewer than ``min_inliers`` matches are confirmed within FIT_PX (here a limit no
    keypoint meets), the component keeps the RANSAC map it was given; otherwise the least
    squares over the confirmed ones replaces it."""
    from featurewarp_cli.app import measure as measuring

    rng = np.random.default_rng(4)
    src = rng.uniform(0, 200, (300, 2))
    given = np.array([[1.2, 0.1, 5.0], [-0.1, 0.9, 3.0]])
    dst = src @ given[:, :2].T + given[:, 2] + rng.uniform(-0.4, 0.4, (300, 2))
    opts = {"scale": 1.0, "threshold": 3.0, "min_inliers": 10}
    refitted = measuring.local_figures([(src, dst)], given + 0.01, 200 * 200, opts)
    assert np.abs(refitted["matrix"] - given).max() < 0.05 and refitted["fitted"][0] > 250
    monkeypatch.setattr(measuring, "FIT_PX", 1e-9)
    kept = measuring.local_figures([(src, dst)], given + 0.01, 200 * 200, opts)
    assert np.array_equal(kept["matrix"], given + 0.01) and kept["fitted"][1] == 300


def disc_mask(shape, where: str) -> np.ndarray:
    """Four discs of a fifth of the short side centred on the frame's corners or edges' middles."""
    h, w = shape[:2]
    mask = np.zeros((h, w), np.uint8)
    centres = ([(0, 0), (w - 1, 0), (0, h - 1), (w - 1, h - 1)] if where == "corners" else
               [(w // 2, 0), (w - 1, h // 2), (w // 2, h - 1), (0, h // 2)])
    for centre in centres:
        cv2.circle(mask, centre, min(h, w) // 5, 255, -1)
    return mask > 0


@pytest.mark.parametrize("where", ["corners", "edges"])
def test_an_image_against_itself_measures_0_where_the_frame_cuts(astronaut, where):
    """Hostile review D7: the same image on both sides read distortion up to 0.063, rms up to
    0.84 px and a local 90th percentile of 8114 on features cut by the frame (simulated views'
    approximate matches pooled in, and the rectified output's keypoints found on a crop
    while the input's were found on the whole image). Now every measured figure is exact."""
    image, _ = astronaut
    fits = measure(image, image, disc_mask(image.shape, where))
    measured = [f for f in fits if f.distortion is not None]
    assert len(measured) >= 3, [f.reason for f in fits]
    for fit in measured:
        assert fit.distortion < 1e-9 and fit.rms_px < 1e-6 and fit.noise < 1e-6, fit
        assert fit.scale == pytest.approx(1.0, abs=1e-9) and abs(fit.rotation) < 1e-6
        assert fit.local_p90 is None or fit.local_p90 < 1e-6


def test_a_feature_the_frame_cuts_measures_no_worse_than_its_keypoints(astronaut):
    """D7 on a real warp: stretched to 0.6 of its height, the astronaut with discs cut by the
    frame keeps every disc (the report's distortion ~1e-15), but keypoints read up to 0.031
    on a quarter disc (simulated views' matches, several to one output keypoint, counted as
    20). A figure is now given only where its matches fix the shape to 0.005 (its noise), and
    then reads at most 0.01; the others say why they are not measured."""
    from featurewarp_cli import FeatureWarper, load_warp

    image, _ = astronaut
    h, w = image.shape[:2]
    fits = []
    for where in ("corners", "edges"):
        mask = disc_mask(image.shape, where)
        warper = FeatureWarper(w, h, mask, boundary="slide")
        mesh = warper.solve(load_warp("stretch")(w, h, sy=0.6), "similarity")
        assert all(c["kept"] for c in mesh.info["components"])
        fits += measure(image, warper.render(image, mesh, background=(255, 255, 255)), mask)
    measured = [f for f in fits if f.distortion is not None]
    assert len(measured) >= 3 and max(f.distortion for f in measured) <= 0.01, measured
    assert all(f.noise <= 0.005 for f in measured)
    assert all("fewer than" in f.reason or "fix the distortion only to about" in f.reason
               for f in fits if f.distortion is None)


def test_local_fits_of_bunched_matches_give_no_map():
    """14 matches within 2.4 x 0.8 px (a keypoint found at several scales) were fitted a local
    map of scale 0.0097 and distortion 8000. They still confirm one another (consistent),
    but fix no linear map; a neighbourhood spread over the radius does."""
    from featurewarp_cli.app.keypoints import local_fits

    rng = np.random.default_rng(7)
    bunch = np.array([100.0, 100.0]) + rng.uniform(0, 1, (14, 2)) * (2.4, 0.8)
    spread = np.array([300.0, 300.0]) + rng.uniform(-8, 8, (14, 2))
    src = np.vstack([bunch, spread])
    dst = src + rng.normal(0, 0.3, src.shape)
    consistent, linear, scatter = local_fits(src, dst, 24.0, 3.0)
    assert consistent.all() and np.isfinite(scatter).all()
    assert np.isnan(linear[:14]).all()
    assert np.isfinite(linear[14:]).all() and np.abs(linear[14:] - np.eye(2)).max() < 0.1


def test_an_output_keypoint_matched_from_several_views_counts_once():
    from featurewarp_cli.app.keypoints import distinct, ransac

    src = np.array([[10.0, 10.0], [10.0, 10.0], [10.6, 9.2], [11.1, 10.4], [40.0, 12.0]])
    dst = np.array([[20.0, 20.0], [20.0, 20.0], [20.0, 20.0], [20.0, 20.0], [50.0, 22.0]])
    kept_src, kept_dst = distinct(src, dst)
    # the same pair twice (SIFT's two orientations) stays; other input positions go
    np.testing.assert_array_equal(kept_src, src[[0, 1, 4]])
    np.testing.assert_array_equal(kept_dst, dst[[0, 1, 4]])
    assert ransac(src, dst, 4, 3.0) == "3 keypoint matches, fewer than 4"


def test_shape_noise_is_the_mean_distortion_that_scatter_alone_gives():
    """The noise figure is calibrated: 20 matches in a 60 x 20 px band, positions off by 0.3 px
    (x and y), fitted 400 times: the mean distortion of the fits is the figure within 10 %."""
    from featurewarp_cli.app.measure import describe, shape_noise

    rng = np.random.default_rng(11)
    src = rng.uniform(0, 1, (20, 2)) * (60, 20)
    design = np.column_stack([src, np.ones(20)])
    truth = np.array([[0.8, -0.3, 5.0], [0.3, 0.8, 2.0]])
    readings = []
    for _ in range(400):
        dst = design @ truth.T + rng.normal(0, 0.3, (20, 2))
        fitted = np.linalg.lstsq(design, dst, rcond=None)[0].T
        readings.append(describe(fitted[:, :2])["distortion"])
    expected = shape_noise(src, np.zeros((20, 2)), truth[:, :2], variance=0.09)
    assert np.mean(readings) == pytest.approx(expected, rel=0.1)
    assert shape_noise(src[:3], np.zeros((3, 2)), truth[:, :2]) == float("inf")
    on_a_line = np.column_stack([np.arange(10.0), 2 * np.arange(10.0)])
    assert shape_noise(on_a_line, np.ones((10, 2)), truth[:, :2]) == float("inf")


def test_warp_affine_in_pieces_reads_as_one_call(monkeypatch):
    """D6: OpenCV's warpAffine asserts below 32767 px a side; past the limit (here made 37 px)
    the destination is cut into pieces that each read their own window of the source. The
    result is one call's, up to OpenCV's 1/32 px sampling grid."""
    from featurewarp_cli.app import keypoints

    rng = np.random.default_rng(3)
    image = cv2.resize(rng.integers(0, 256, (30, 40), dtype=np.uint8), (120, 90), interpolation=cv2.INTER_CUBIC)
    matrix = cv2.getRotationMatrix2D((60, 45), 25, 1.3)
    matrix[:, 2] += (10, 5)
    one = cv2.warpAffine(image, matrix, (150, 110), flags=cv2.INTER_LINEAR, borderValue=keypoints.FLAT_GRAY)
    monkeypatch.setattr(keypoints, "LIMIT", 37)
    pieces = keypoints.warp_affine(image, matrix, (150, 110))
    difference = np.abs(one.astype(int) - pieces)
    assert difference.max() <= 4 and difference.mean() < 0.05


def test_measure_past_opencvs_32767_px_limit(runner, tmp_path):
    """D6: a 33000 px wide strip failed with OpenCV's '(-215:Assertion failed) dst.cols <
    SHRT_MAX' from the rectifying warp; it is measured (itself: 0; stretched by 1.018 along
    x: that stretch)."""
    rng = np.random.default_rng(0)
    strip = cv2.resize(rng.integers(0, 255, (8, 1100), dtype=np.uint8), (33000, 32), interpolation=cv2.INTER_CUBIC)
    mask = np.zeros_like(strip)
    mask[4:28, 100:32900] = 255
    for name, picture in (("in", strip), ("mask", mask),
                          ("wide", cv2.resize(strip, (33600, 32), interpolation=cv2.INTER_CUBIC))):
        cv2.imwrite(str(tmp_path / f"{name}.png"), picture)
    same = runner("measure", tmp_path / "in.png", tmp_path / "in.png", "-m", tmp_path / "mask.png", "--json")
    assert same.code == 0, same.stderr
    (fit,) = json.loads(same.stdout)["components"]
    assert fit["distortion"] == pytest.approx(0.0, abs=1e-6) and fit["noise"] == pytest.approx(0.0, abs=1e-6)
    wide = runner("measure", tmp_path / "in.png", tmp_path / "wide.png", "-m", tmp_path / "mask.png", "--json")
    assert wide.code == 0, wide.stderr
    (fit,) = json.loads(wide.stdout)["components"]
    assert fit["distortion"] == pytest.approx(33600 / 33000 - 1, abs=0.005)


def test_a_region_matched_to_its_likeness_elsewhere_is_flagged(runner, tmp_path, astronaut):
    """The same subject twice (a composite, a reflection): a region whose own image is gone from
    the output matched the other copy, and measure gave confident figures of the wrong place
    (photo trial 9). Two disjoint regions that land on one spot are now named, on stderr and
    as ``lands_on``; where each is where it was, nothing is said."""
    image, _ = astronaut
    face = image[30:190, 160:320]
    scene = np.full((260, 460, 3), 128, np.uint8)
    scene[20:180, 20:180] = face
    scene[40:120, 300:380] = cv2.resize(face, (80, 80), interpolation=cv2.INTER_AREA)
    mask = np.zeros(scene.shape[:2], np.uint8)
    mask[20:180, 20:180] = mask[40:120, 300:380] = 255
    gone = scene.copy()
    gone[20:180, 20:180] = 128                      # the large copy is blanked out of the output
    assert [fit.lands_on for fit in measure(scene, scene, mask)] == [(), ()]
    fits = measure(scene, gone, mask)
    assert fits[0].lands_on == (2,) and fits[1].lands_on == (1,)
    paths = {name: tmp_path / f"{name}.png" for name in ("in", "out", "mask")}
    for name, picture in zip(paths, (scene, gone, mask)):
        cv2.imwrite(str(paths[name]), picture)
    run = runner("measure", paths["in"], paths["out"], "-m", paths["mask"])
    assert run.code == 0 and "component 1 lands where component 2 went" in run.stderr


def test_max_distortion_makes_measure_a_check(runner, tmp_path, astronaut):
    """measure exited 0 whatever it found, even with nothing measured (an unrelated OUTPUT), so
    CI had to parse --json (animate trial nit 9); --max-distortion exits 1 above D or with
    nothing measured. An animated OUTPUT's first frame is measured, and now it says so (nit 5)."""
    from PIL import Image

    image, mask = astronaut
    output, _ = warp_affine(image, anisotropic(2.0, 0.0))
    paths = {name: tmp_path / f"{name}.png" for name in ("in", "out", "mask", "flat")}
    for name, picture in zip(paths, (image, output, mask.astype(np.uint8) * 255, np.full_like(image, 128))):
        cv2.imwrite(str(paths[name]), picture)
    base = ["measure", paths["in"], paths["out"], "-m", paths["mask"]]
    assert runner(*base, "--max-distortion", "2").code == 0
    above = runner(*base, "--max-distortion", "0.5")
    assert above.code == 1 and "component 1 (around" in above.stderr and "above 0.5" in above.stderr
    assert len(above.stdout.decode().splitlines()) == 3                   # the figures, all the same
    cv2.imwrite(str(tmp_path / "empty.png"), np.zeros(mask.shape, np.uint8))
    empty = runner("measure", paths["in"], paths["out"], "-m", tmp_path / "empty.png")
    assert empty.code == 0 and "marks no feature" in empty.stderr and "nothing to measure" in empty.stderr
    assert "plain warp" not in empty.stderr                 # measure warps nothing
    for value in ("nan", "inf", "1e999", "-1"):        # nan passed every region: the check was off
        refused = runner(*base, "--max-distortion", value)
        assert refused.code == 2 and len(refused.lines) == 1 and refused.stdout == b"", value
    nothing = runner("measure", paths["in"], paths["flat"], "-m", paths["mask"], "--max-distortion", "1")
    assert nothing.code == 1 and nothing.stderr.count("could not be measured (0 keypoint matches") == 3
    frames = [Image.fromarray(cv2.cvtColor(picture, cv2.COLOR_BGR2RGB)) for picture in (output, output[::-1])]
    frames[0].save(tmp_path / "anim.png", save_all=True, append_images=frames[1:], duration=100)
    run = runner("measure", paths["in"], tmp_path / "anim.png", "-m", paths["mask"])
    assert run.code == 0 and "has several frames (animated or multi-page); the first is measured" in run.stderr


def test_measure_reads_as_warp_does_and_its_check_passes_nothing_it_could_not_see(runner, tmp_path, astronaut):
    """Review findings 2, 6, 7: a region wrecked past measuring passed --max-distortion (only a
    mask with no region measured at all failed); -m alpha was refused though the help says "as
    for warp"; its warnings ignored -q and an animated OUTPUT on stdin said nothing."""
    from PIL import Image

    image, mask = astronaut
    output, _ = warp_affine(image, anisotropic(1.0, 0.0))
    wrecked = output.copy()
    x, y, w, h = cv2.connectedComponentsWithStats(mask.astype(np.uint8), connectivity=8)[2][1][:4]   # region 1
    wrecked[y:y + h, x:x + w] = np.random.default_rng(0).integers(0, 255, (h, w, 3), dtype=np.uint8)
    cut = np.dstack([image, mask.astype(np.uint8) * 255])
    paths = {name: tmp_path / f"{name}.png" for name in ("in", "out", "bad", "mask", "cut")}
    for name, picture in zip(paths, (image, output, wrecked, mask.astype(np.uint8) * 255, cut)):
        cv2.imwrite(str(paths[name]), picture)
    run = runner("measure", paths["in"], paths["bad"], "-m", paths["mask"], "--max-distortion", "0.5")
    assert run.code == 1 and "component 1 (around" in run.stderr and "could not be measured" in run.stderr
    alpha = runner("measure", paths["cut"], paths["out"], "-m", "alpha", "--json")
    assert alpha.code == 0 and len(json.loads(alpha.stdout)["components"]) == 3
    frames = [Image.fromarray(cv2.cvtColor(p, cv2.COLOR_BGR2RGB)) for p in (output, output[::-1])]
    frames[0].save(tmp_path / "anim.png", save_all=True, append_images=frames[1:], duration=100)
    piped = runner("measure", paths["in"], "-", "-m", paths["mask"], input=(tmp_path / "anim.png").read_bytes())
    assert piped.code == 0 and "OUTPUT - has several frames" in piped.stderr
    quiet = runner("-q", "measure", paths["in"], tmp_path / "anim.png", "-m", paths["mask"])
    assert quiet.code == 0 and quiet.stderr == ""


def test_an_image_against_itself_passes_max_distortion_0(runner):
    """The README: an image measured against itself gives 0. Its SVD read 3e-15, so
    --max-distortion 0 failed it ("distortion 0.0000, above 0", exit 1) while --json printed
    0.0 per component and 3.1e-15 as worst_distortion."""
    shapes, mask = SAMPLES / "shapes.png", SAMPLES / "shapes_mask.png"
    run = runner("measure", shapes, shapes, "-m", mask, "--max-distortion", "0", "--json")
    assert run.code == 0, run.stderr
    report = json.loads(run.stdout)
    assert report["worst_distortion"] == 0.0
    assert describe(np.eye(2) * 0.7 @ np.array([[np.cos(1.0), -np.sin(1.0)], [np.sin(1.0), np.cos(1.0)]]))[
        "distortion"] == 0.0

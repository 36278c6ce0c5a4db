"""Issue-3 behaviour: intuitive feature scale, sliding borders, smoothness, saved grids, panels."""

import io

import cv2
import numpy as np
import pytest

import shapes
from samples import scenes
from featurewarp_cli.engine.warper import FeatureWarper, load_warp
from featurewarp_cli.engine.grid import signed_areas
from test_cli import Runner


@pytest.fixture(scope="module")
def scene():
    return scenes.scene()


def area_ratios(scene, preset, mode="similarity", **params):
    image, mask = scene
    h, w = mask.shape
    warper = FeatureWarper(w, h, mask)
    out = warper.render(image, warper.solve(load_warp(preset)(w, h, **params), mode))
    return np.array([shapes.area(out, colour) / shapes.area(image, colour)
                     for *_, colour in scenes.SHAPES])


def test_swirl_keeps_feature_area(scene):
    """Similarity mode under an area-preserving swirl keeps every feature's area within 10 %."""
    ratios = area_ratios(scene, "swirl", angle=150)
    assert np.all(np.abs(ratios - 1.0) <= 0.10), ratios


def test_one_axis_stretch_keeps_feature_size(scene):
    """Similarity mode under stretch sy=2 leaves features at their size (the paper's intent)."""
    ratios = area_ratios(scene, "stretch", sy=2)
    assert np.all(np.abs(ratios - 1.0) <= 0.05), ratios


def test_uniform_scale_scales_features(scene):
    """Similarity mode under a uniform 1.5x scale multiplies areas by 2.25."""
    ratios = area_ratios(scene, "stretch", sx=1.5, sy=1.5)
    assert np.all(np.abs(ratios / 2.25 - 1.0) <= 0.05), ratios


def border_cut_scene():
    """A disc cut by the left border and a square cut by the top border."""
    cut = (("disc", 0, 180, 40, (0, 0, 255)), ("square", 250, 0, 30, (0, 200, 0)))
    return scenes.scene(cut)


@pytest.mark.parametrize("params", [{"sy": 2}, {"sx": 2}, {"sx": 0.6, "sy": 1.4}])
def test_sliding_border_keeps_cut_features(params):
    """A feature cut by the border stays a similarity (<= 1 % RMS of its size) and the canvas
    stays exact. With slide (stretch's default) it slides along its side at about its own
    size; with a fixed border it takes the scale the pinned side imposes (sx along a top or
    bottom side, sy along a left or right one), the best the pins allow."""
    _, mask = border_cut_scene()
    residuals, scales = {}, {}
    for boundary in ("slide", "fixed"):
        warp = load_warp("stretch")(500, 360, **params)
        mesh = FeatureWarper(500, 360, mask, boundary=boundary).solve(warp)
        residuals[boundary] = max(c["residual_percent"] for c in mesh.info["quality"]["components"])
        scales[boundary] = sorted(c["scale"] for c in mesh.info["components"])
        corners = np.array([[-0.5, -0.5], [499.5, -0.5], [-0.5, 359.5], [499.5, 359.5]])
        at = [np.flatnonzero(np.all(np.abs(mesh.source - c) < 1e-9, axis=1))[0] for c in corners]
        np.testing.assert_allclose(mesh.target[at], warp(corners), atol=1e-9)
        xs, ys = mesh.target[:, 0], mesh.target[:, 1]
        assert xs.min() >= -0.5 - 1e-9 and xs.max() <= warp.canvas[0] - 0.5 + 1e-9
        assert ys.min() >= -0.5 - 1e-9 and ys.max() <= warp.canvas[1] - 0.5 + 1e-9
        assert mesh.flips() == 0
    assert residuals["slide"] <= 1.0 and residuals["fixed"] <= 1.0, residuals
    pinned = sorted((params.get("sx", 1.0), params.get("sy", 1.0)))
    np.testing.assert_allclose(scales["fixed"], pinned, rtol=1e-6)
    assert all(0.8 <= s <= 1.25 for s in scales["slide"]), scales


@pytest.mark.parametrize("preset,params", [("stretch", {"sy": 2}), ("stretch", {"sx": 0.5}),
                                           ("swirl", {"angle": 120}), ("arc", {"angle": 120}),
                                           ("bulge", {"strength": 0.5})])
@pytest.mark.parametrize("mode", ["similarity", "rigid"])
def test_no_crease_next_to_features(scene, preset, params, mode):
    """Background triangles next to features stay within 4x the warp's own anisotropy there."""
    _, mask = scene
    h, w = mask.shape
    quality = FeatureWarper(w, h, mask).solve(load_warp(preset)(w, h, **params), mode).info["quality"]
    assert quality["max_anisotropy_near_features"] <= 4.0 * max(quality["warp_anisotropy_near_features"], 1.0)


def test_report_quality_fields(scene):
    """The mesh info has the quality figures the report promises."""
    _, mask = scene
    h, w = mask.shape
    quality = FeatureWarper(w, h, mask).solve(load_warp("swirl")(w, h, angle=120)).info["quality"]
    assert len(quality["components"]) == 6
    for component in quality["components"]:
        assert set(component) == {"scale", "rotation_deg", "residual_rms_px", "residual_percent"}
        assert component["residual_percent"] < 1.0
    assert quality["flipped_triangles"] == 0
    assert 0 < quality["area_ratio"]["min"] <= 1.0 <= quality["area_ratio"]["max"]
    assert quality["background_rms_px"] > 0


def run(*args):
    """The command in-process (CliRunner): exit code and stderr as the console script's."""
    return Runner()(*args)


@pytest.fixture(scope="module")
def files(tmp_path_factory):
    folder = tmp_path_factory.mktemp("q")
    image, mask = scenes.scene()
    cv2.imwrite(str(folder / "in.png"), image)
    cv2.imwrite(str(folder / "mask.png"), mask.astype(np.uint8) * 255)
    return folder


@pytest.mark.parametrize("kind", ["transparent", "translucent", "16-bit", "gray"])
def test_a_drawn_grid_keeps_the_background_alpha_and_depth(files, kind):
    """--grid drew on an 8-bit BGR copy: a transparent or translucent --background came out
    grey (the panels' checkerboard), a 16-bit result 8-bit, with exit 0 and no word."""
    image = cv2.imread(str(files / "in.png"))
    source = {"16-bit": image.astype(np.uint16) * 257, "gray": image[:, :, 1]}.get(kind, image)
    cv2.imwrite(str(files / f"{kind}.png"), source)
    background = {"transparent": ["--background", "transparent"],
                  "translucent": ["--background", "rgba(0,0,255,0.5)"]}.get(kind, [])
    pictures = {}
    for extra in ([], ["--grid"]):
        name = files / f"{kind}{len(extra)}.png"
        out = run("warp", "arc", str(files / f"{kind}.png"), str(name), "--angle", "90", *background, *extra)
        assert out.code == 0 and out.stderr == "", out.stderr
        pictures[bool(extra)] = cv2.imread(str(name), cv2.IMREAD_UNCHANGED)
    plain, grid = pictures[False], pictures[True]       # PNG: transparent beyond the image by default
    assert grid.dtype == plain.dtype == source.dtype and grid.shape == plain.shape and grid.shape[2] == 4
    lines = np.any(grid != plain, axis=2)
    assert 0.01 < lines.mean() < 0.5
    assert np.array_equal(grid[~lines], plain[~lines]) and np.all(grid[lines, 3] >= plain[lines, 3])
    corner = plain[0, 0, 3] if not lines[0, 0] else plain[-1, 0, 3]      # where the arc leaves the canvas
    assert corner == (128 if kind == "translucent" else 0)


def test_save_grid_writes_the_mapping(files):
    """--save-grid: source (N, 2), target (N, 2), triangles (M, 3) counter-clockwise in source
    coordinates; target is where the warp put the nodes on the canvas."""
    out = run("warp", "swirl", str(files / "in.png"), str(files / "out.png"), "-m", str(files / "mask.png"),
              "--save-grid", str(files / "grid.npz"), "--angle", "90")
    assert out.code == 0, out.stderr
    grid = np.load(files / "grid.npz")
    assert set(grid.files) == {"source", "target", "triangles"}
    n = grid["source"].shape[0]
    assert grid["source"].shape == grid["target"].shape == (n, 2)
    assert grid["triangles"].ndim == 2 and grid["triangles"].shape[1] == 3
    assert signed_areas(grid["source"], grid["triangles"]).min() > 0
    assert signed_areas(grid["target"], grid["triangles"]).min() > 0
    assert grid["source"].min() == -0.5 and grid["source"][:, 0].max() == 499.5


def test_compare_writes_a_four_way_panel(files):
    """compare: one panel, input | plain | rigid | similarity, each view at the input's resolution,
    with caption bars; --grid draws lines; --panel-width scales it."""
    plain = files / "panel.png"
    gridded = files / "panel-grid.png"
    for path, extra in ((plain, []), (gridded, ["--grid"])):
        out = run("compare", "arc", str(files / "in.png"), str(path), "-m", str(files / "mask.png"),
                  "--angle", "90", *extra)
        assert out.code == 0, out.stderr
    a, b = cv2.imread(str(plain)), cv2.imread(str(gridded))
    source = cv2.imread(str(files / "in.png"))
    assert a.shape == b.shape and a.shape[0] >= source.shape[0] + 28        # views at the input's pixels
    assert a.shape[1] > 4 * source.shape[1]                                 # four views side by side
    assert np.abs(a.astype(int) - b.astype(int)).max() > 100   # the grid lines are visible
    small = files / "small.png"
    out = run("compare", "arc", str(files / "in.png"), str(small), "-m", str(files / "mask.png"), "--angle", "90",
              "--panel-width", "600")
    assert out.code == 0 and cv2.imread(str(small)).shape[1] == 600


def test_compare_rejects_mode(files):
    """compare always shows all modes, so --mode is not one of its options (usage error, exit 2)."""
    out = run("compare", "arc", str(files / "in.png"), str(files / "p.png"), "--mode", "rigid")
    assert out.code == 2
    assert not (files / "p.png").exists()


def test_the_plain_bounds_fits_are_exact_far_from_the_origin():
    """FeatureFigures' fits (linear operators made once) match a least-squares fit of centred
    positions on small components 12 000 px from the origin (weights not centred again: 5e-11)."""
    from types import SimpleNamespace

    from featurewarp_cli.engine import quality
    from featurewarp_cli.engine.plain_bound import FeatureFigures, middle_nodes

    rng = np.random.default_rng(3)
    nodes = np.concatenate([12000.0 + 3.0 * rng.random((9, 2)), 9000.0 + 2.0 * rng.random((7, 2)),
                            rng.random((4, 2))])
    node_component = np.repeat([0, 1, 2, -1], [9, 7, 3, 1])
    state = SimpleNamespace(nodes=nodes, triangles=np.array([[0, 1, 2], [9, 10, 11]]),
                            tri_component=np.array([0, 1]), node_component=node_component,
                            node_middle=middle_nodes(nodes, node_component, 3),
                            features=SimpleNamespace(n_components=3))
    maps = rng.normal(size=(3, 2, 2)) + 2.0 * np.eye(2)
    points = nodes.copy()
    for k in range(3):
        on = node_component == k
        points[on] = (nodes[on] - nodes[on].mean(axis=0)) @ maps[k].T + 500.0 * k
    _, fits = FeatureFigures(state).of(points)
    expected = quality.map_anisotropy(maps[:2])
    np.testing.assert_allclose(fits[0, :2], expected, rtol=1e-12)
    assert fits[0, 2] == pytest.approx(quality.map_anisotropy(maps[2:])[0], rel=1e-11)   # 3 points: exact

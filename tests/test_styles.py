"""Issue 14: the design tools' styles and the 3D wraps (arch, flag, fish, rise, inflate, squeeze,
shell, arc --where, perspective, cylinder, sphere): canvases, one-to-one over the declared
ranges, no fold with or without features, features kept, plain mode = the analytic map, and
the refusals that name their option.
"""

from __future__ import annotations

import functools
import json

import numpy as np
import pytest
from click.testing import CliRunner

from featurewarp_cli.cli.main import cli
from featurewarp_cli.engine.grid import Grid, signed_areas
from featurewarp_cli.engine.api import warp
from featurewarp_cli.engine.warper import FeatureWarper, load_warp
from samples.scenes import scene
from shapes import distortions
from test_presets import boundary_polygon, winding_numbers

W, H = 96, 72
STYLES = ("arch", "flag", "fish", "rise", "inflate", "squeeze", "shell")
NEW = STYLES + ("perspective", "cylinder", "sphere")
TILT = {"tl": "30%,10%", "tr": "95%,0%", "br": "80%,100%", "bl": "0%,85%"}

#: Every new preset at its default and at the ends of each declared range (and their combinations).
EXTREMES = (
    [(name, {}) for name in NEW]
    + [(name, {"bend": b, "hdistort": h, "vdistort": v}) for name in STYLES
       for b, h, v in ((100, 0, 0), (-100, 0, 0), (100, 90, 90), (-100, -90, -90), (0, 90, -90))]
    + [("flag", {"waves": 12, "bend": 100}), ("flag", {"waves": 12, "bend": -100})]
    + [("shell", {"side": "upper", "bend": b, "hdistort": 90}) for b in (100, -100)]
    + [("arc", {"where": w, "angle": a}) for w in ("lower", "upper") for a in (1e-6, 90, 150)]
    + [("perspective", TILT), ("perspective", {"tl": "43%,43%"}), ("perspective", {"br": "300%,400%"})]
    + [("cylinder", {"angle": a}) for a in (1e-6, 160)] + [("cylinder", {"angle": 160, "axis": "horizontal"})]
    + [("cylinder", {"angle": 1, "distance": 1.001}), ("cylinder", {"angle": 60, "distance": 1000}),
       ("cylinder", {"angle": 100, "distance": 3})]
    + [("sphere", {"angle": a}) for a in (1e-6, 120)]
    + [("sphere", {"angle": 1, "distance": 1.001}), ("sphere", {"angle": 80, "distance": 4})]
)
IDS = [f"{name}-{'-'.join(f'{k}{v}' for k, v in params.items()) or 'default'}" for name, params in EXTREMES]


def make(name, params, size=(W, H)):
    return load_warp(name)(*size, **params)


def blobs(width=W, height=H):
    """Two discs and a square, one of them cut by the bottom border."""
    y, x = np.mgrid[0:height, 0:width]
    mask = (x - 0.3 * width) ** 2 + (y - 0.35 * height) ** 2 < (0.12 * height) ** 2
    mask |= (abs(x - 0.7 * width) < 0.1 * height) & (abs(y - 0.45 * height) < 0.1 * height)
    mask |= (x - 0.5 * width) ** 2 + (y - height) ** 2 < (0.15 * height) ** 2
    return mask


# --- registry and listing -------------------------------------------------------------------

def test_warps_lists_the_presets_under_the_users_words():
    """featurewarp warps shows at least 12 presets and the names designers look for."""
    run = CliRunner().invoke(cli, ["warps"])
    assert run.exit_code == 0
    listed = json.loads(CliRunner().invoke(cli, ["warps", "--json"]).output)
    assert len(listed) >= 12 and set(NEW) <= {entry["name"] for entry in listed}
    for words in ("Arc Lower", "Arc Upper", "Shell Lower", "Shell Upper", "Fisheye", "Inflate", "Squeeze",
                  "Twist", "Flag", "Wave", "Fish", "Rise", "Arch", "Perspective", "lower|upper"):
        assert words in run.output, words


# --- canvases and one-to-one over the declared ranges ---------------------------------------

@pytest.mark.parametrize("name,params", EXTREMES, ids=IDS)
def test_canvas_is_the_bounding_box(name, params):
    """The canvas holds W of every source point in [-0.5, size - 0.5] and wastes under a pixel."""
    w = make(name, params)
    cw, ch = w.canvas
    gx, gy = np.meshgrid(np.arange(W, dtype=float), np.arange(H, dtype=float))
    pts = w(np.concatenate([np.stack([gx.ravel(), gy.ravel()], 1), boundary_polygon(W, H, step=0.05)]))
    lo, hi = pts.min(0), pts.max(0)
    assert (lo >= -0.5 - 1e-6).all() and lo == pytest.approx([-0.5, -0.5], abs=1e-3)
    assert (hi <= [cw - 0.5 + 1e-6, ch - 0.5 + 1e-6]).all() and (hi > [cw - 1.5, ch - 1.5]).all()


@pytest.mark.parametrize("name,params", EXTREMES, ids=IDS)
def test_map_is_one_to_one(name, params):
    """Jacobian determinant > 0 all over the source, and the border winds once around the inside."""
    w = make(name, params)
    xs, ys = np.meshgrid(np.linspace(-0.5, W - 0.5, 193), np.linspace(-0.5, H - 0.5, 145))
    p = np.stack([xs.ravel(), ys.ravel()], 1)
    step = 1e-4
    dx = (w(p + [step, 0]) - w(p - [step, 0])) / (2 * step)
    dy = (w(p + [0, step]) - w(p - [0, step])) / (2 * step)
    det = dx[:, 0] * dy[:, 1] - dx[:, 1] * dy[:, 0]
    assert np.isfinite(det).all() and (det > 0).all(), det.min()
    inner = w(np.stack(np.meshgrid(np.linspace(0, W - 1, 13), np.linspace(0, H - 1, 9)), -1).reshape(-1, 2))
    np.testing.assert_allclose(winding_numbers(w(boundary_polygon(W, H, step=0.5)), inner), 1.0, atol=1e-6)


#: Cases of test_no_fold_with_or_without_features run smaller than W x H, and why. perspective
#: with its top-left corner drawn 43 % in: the automatic grid is 1 px cells there (7081 nodes),
#: and the rigid solve's fold guard follows its path from W for 99 steps (half of the whole
#: test's time); at 64 x 48 (3185 nodes, a third of the time) it takes the same route in both
#: modes: folds that the path from W undoes with every feature kept (no release).
SMALLER = {"perspective-tl43%,43%": (64, 48)}


@pytest.mark.parametrize("name,params", EXTREMES, ids=IDS)
def test_no_fold_with_or_without_features(name, params):
    """The solved mesh has no flipped triangle, plain and feature-aware, with the mask and without
    (at W x H, or at the size SMALLER gives, by the fold guard's route it says)."""
    size = SMALLER.get(IDS[EXTREMES.index((name, params))], (W, H))
    w = make(name, params, size)
    for mask, mode in ((None, "plain"), (blobs(*size), "similarity"), (blobs(*size), "rigid")):
        mesh = FeatureWarper(*size, mask).solve(w, mode)
        assert mesh.flips() == 0, (mode, mesh.info.get("fold_guard"))
        assert np.isfinite(mesh.target).all()
        assert mesh.canvas == w.canvas
        guard = mesh.record.guard
        if size != (W, H) and mask is not None:
            assert guard.flipped_before > 0 and guard.path_steps > 0 and guard.release_rounds == 0, (mode, guard)


@pytest.mark.parametrize("name,params", EXTREMES, ids=IDS)
def test_plain_mode_is_the_analytic_map(name, params):
    """Plain mode puts the nodes on W exactly and the triangles' insides within 0.5 px of W."""
    w = make(name, params)
    mesh = FeatureWarper(W, H, None).solve(w, "plain")
    np.testing.assert_array_equal(mesh.target, w(mesh.source))
    assert mesh.info["grid"]["pl_error_px"] <= 0.5
    weights = np.array([[1, 1, 1], [4, 1, 1], [1, 4, 1], [1, 1, 4]]) / np.array([[3], [6], [6], [6]])
    for bary in weights:                      # centroids and points towards each corner
        inside = np.einsum("k,tkd->td", bary, mesh.source[mesh.triangles])
        linear = np.einsum("k,tkd->td", bary, mesh.target[mesh.triangles])
        assert np.abs(linear - w(inside)).max() <= 0.5


def test_signed_areas_of_a_plain_grid_are_positive_for_every_style_at_full_bend():
    """The proofs' bounds are tight enough for a 2 px grid: W itself folds no triangle at +-100 %."""
    grid = Grid.for_image(W, H, 2)
    for name in STYLES:
        for bend in (-100, 100):
            area = signed_areas(make(name, {"bend": bend})(grid.nodes()), grid.triangles())
            assert (area > 0).all(), (name, bend)


# --- features on the shapes scene -----------------------------------------------------------

@functools.lru_cache(maxsize=None)
def shapes_scene():
    return scene()


@pytest.mark.parametrize("name", NEW + ("arc-lower", "arc-upper"))
def test_similarity_keeps_the_shapes_at_the_default(name):
    """On the shapes scene at the default, every disc and square comes out within 0.02 of its
    shape (measured on the output image), while the plain warp distorts at least one."""
    preset, _, where = name.partition("-")
    params = {"where": where} if where else {}
    image, mask = shapes_scene()
    kept = distortions(warp(image, mask, preset, **params))
    assert max(kept) <= 0.02, [round(d, 4) for d in kept]
    plain = distortions(warp(image, mask, preset, mode="plain", **params))
    assert max(plain) > max(kept)


# --- geometry each preset promises ----------------------------------------------------------

def test_perspective_sends_the_corners_where_asked():
    """Corners measured from the image's top-left corner, in pixels or percentages."""
    w = make("perspective", TILT)
    corners = np.array([[-0.5, -0.5], [W - 0.5, -0.5], [W - 0.5, H - 0.5], [-0.5, H - 0.5]])
    asked = np.array([[0.30 * W, 0.10 * H], [0.95 * W, 0.0], [0.80 * W, H], [0.0, 0.85 * H]])
    np.testing.assert_allclose(w(corners) - w(corners)[3] , asked - asked[3], atol=1e-9)
    still = make("perspective", {"tl": "0,0", "tr": f"{W},0"})
    np.testing.assert_allclose(still(corners), corners, atol=1e-9)       # the identity
    mid = still(np.array([[W / 2 - 0.5, H / 2 - 0.5]]))
    np.testing.assert_allclose(mid, [[W / 2 - 0.5, H / 2 - 0.5]], atol=1e-9)


@pytest.mark.parametrize("corners,message", [
    ({"tl": "60%,60%"}, "concave at tl"),
    ({"br": "40%,40%"}, "concave at br"),
    ({"tl": "0,0", "tr": "100%,100%", "br": "100%,0%", "bl": "0%,100%"}, "crosses itself"),
    ({"tl": "100%,0%", "tr": "0%,0%", "br": "0%,100%", "bl": "100%,100%"}, "mirror order"),
    ({"tl": "90%,0%"}, "coincide"),
    ({"tl": "0,0", "tr": "100%,0%", "br": "100%,4%", "bl": "50%,4%"}, r"angle at (tl|bl) is"),
    ({"tl": "50%,49%", "tr": "100%,0%"}, r"angle at tl is 17\d"),
    ({"tl": "1,2,3"}, "^tl: "),
    ({"tl": "49.9%,0%", "tr": "50.1%,0%"}, r"^tl/tr/br/bl: the side from tl to tr is 0.2 %"),     # 60-120 s before
])
def test_perspective_refuses_a_bad_quadrilateral(corners, message):
    with pytest.raises(ValueError, match=message):
        make("perspective", corners)


def test_cylinder_keeps_columns_and_foreshortens_towards_the_silhouette():
    """Columns stay vertical; the middle keeps its scale and the edges come out narrower."""
    w = make("cylinder", {"angle": 120})
    col = w(np.stack([np.full(5, 10.0), np.linspace(0, H - 1, 5)], 1))
    assert np.ptp(col[:, 0]) < 1e-9
    row = w(np.stack([np.arange(W, dtype=float), np.full(W, H / 2)], 1))[:, 0]
    steps = np.diff(row)
    assert steps[W // 2] == pytest.approx(1.0, abs=1e-3) and steps[0] < 0.6
    assert w.canvas[0] == pytest.approx(2 * W / np.radians(120) * np.sin(np.radians(60)), abs=1)


@pytest.mark.parametrize("name,params,message", [
    ("cylinder", {"distance": 1.5}, "angle: 120 degrees wraps the cylinder too close to its silhouette seen from distance 1.5"),
    ("sphere", {"angle": 120, "distance": 2}, "angle: 120 degrees wraps the sphere"),
    ("arc", {"where": "lower", "angle": 171}, "angle: 171 is out of range when where is lower"),
    ("shell", {"side": "middle"}, "side: 'middle' is not one of lower, upper"),
    ("arch", {"bend": 101}, "bend: 101 is out of range"),
    ("inflate", {"hdistort": -91}, "hdistort"),
    ("flag", {"waves": 1.5}, "waves"),
    ("cylinder", {"distance": 1}, "distance: 1 is out of range"),
])
def test_bad_values_name_their_parameter(name, params, message):
    with pytest.raises(ValueError, match="^" + message.replace("(", r"\(")):
        make(name, params)


def test_a_refused_view_is_a_usage_error_on_the_command_line(tmp_path):
    import cv2

    source = tmp_path / "in.png"
    cv2.imwrite(str(source), np.full((30, 40, 3), 128, np.uint8))
    run = CliRunner().invoke(cli, ["warp", "cylinder", str(source), str(tmp_path / "o.png"), "--distance", "1.5"])
    assert run.exit_code == 2 and "--angle" in run.output and "(at most" in run.output
    assert "seen from --distance 1.5" in run.output
    ok = CliRunner().invoke(cli, ["warp", "shell", str(source), str(tmp_path / "o.png"), "--side", "Upper"])
    assert ok.exit_code == 0, ok.output


def test_arc_lower_and_upper_bow_one_edge_into_a_circular_arc():
    """Arc Lower: the top edge stays, columns stay vertical, the bottom edge is an arc of --angle
    degrees through its ends; Arc Upper is the same upside down."""
    xs = np.linspace(-0.5, W - 0.5, 401)
    for where, straight, bowed in (("lower", -0.5, H - 0.5), ("upper", H - 0.5, -0.5)):
        w = make("arc", {"where": where, "angle": 120})
        top = w(np.stack([xs, np.full_like(xs, straight)], 1))
        assert np.ptp(top[:, 1]) < 1e-9 and np.allclose(np.diff(top[:, 0]), xs[1] - xs[0])
        column = w(np.stack([np.full(9, 30.0), np.linspace(-0.5, H - 0.5, 9)], 1))
        assert np.ptp(column[:, 0]) < 1e-9
        edge = w(np.stack([xs, np.full_like(xs, bowed)], 1))
        (a, b), c = edge[0], edge[-1]
        chord_mid = (edge[0] + edge[-1]) / 2
        sag = np.abs(edge[200, 1] - chord_mid[1])
        radius = W / (2 * np.sin(np.radians(60)))
        assert a == pytest.approx(-0.5) and c[0] == pytest.approx(W - 0.5) and b == pytest.approx(c[1])
        assert sag == pytest.approx(radius * (1 - np.cos(np.radians(60))), rel=1e-9)
        centre = np.array([chord_mid[0], chord_mid[1] + (sag - radius) * (1 if where == "lower" else -1)])
        np.testing.assert_allclose(np.hypot(*(edge - centre).T), radius, rtol=1e-9)


def test_shell_upper_is_shell_lower_upside_down():
    w_low, w_up = make("shell", {"side": "lower"}), make("shell", {"side": "upper"})
    p = np.random.default_rng(1).uniform([-0.5, -0.5], [W - 0.5, H - 0.5], (200, 2))
    low = w_low(p)
    up = w_up(np.stack([p[:, 0], H - 1 - p[:, 1]], 1))
    np.testing.assert_allclose(low[:, 0], up[:, 0], atol=1e-9)
    np.testing.assert_allclose(low[:, 1], w_up.canvas[1] - 1 - up[:, 1], atol=1e-6)
    assert w_low.canvas == w_up.canvas


@pytest.mark.parametrize("hdistort", [-60, 60])
def test_horizontal_distortion_is_a_linear_keystone(hdistort):
    """With no bend, --hdistort H makes the right side (1 + H) / (1 - H) times the left side's height."""
    w = make("arch", {"bend": 0, "hdistort": hdistort})
    left, right = w(np.array([[-0.5, -0.5], [-0.5, H - 0.5]])), w(np.array([[W - 0.5, -0.5], [W - 0.5, H - 0.5]]))
    h = hdistort / 100
    assert (right[1, 1] - right[0, 1]) / (left[1, 1] - left[0, 1]) == pytest.approx((1 + h) / (1 - h))


@pytest.mark.parametrize("name,params", [(n, {}) for n in NEW] + [("squeeze", {"bend": 100}),
                                                                   ("sphere", {"angle": 120})])
def test_the_saved_grid_has_no_fold(tmp_path, name, params):
    """Through the command line with a mask: the --save-grid npz's triangles all keep a positive area."""
    import cv2

    image, mask = scene(((("disc", 30, 30, 12, (0, 0, 255)), ("square", 70, 45, 10, (0, 255, 0)))), (W, H))
    cv2.imwrite(str(tmp_path / "in.png"), image)
    cv2.imwrite(str(tmp_path / "mask.png"), mask.astype(np.uint8) * 255)
    options = [x for k, v in params.items() for x in (f"--{k}", str(v))]
    run = CliRunner().invoke(cli, ["warp", name, str(tmp_path / "in.png"), str(tmp_path / "out.png"), "-m",
                                   str(tmp_path / "mask.png"), "--save-grid", str(tmp_path / "g.npz"), *options])
    assert run.exit_code == 0, run.output
    saved = np.load(tmp_path / "g.npz")
    assert (signed_areas(saved["target"], saved["triangles"]) > 0).all()


def test_word_parameters():
    """A choice takes its words in any case; featurewarp warps --json lists them; a pair default prints as X,Y."""
    shell = load_warp("shell")
    assert shell(W, H, side=" UPPER ").values["side"] == "upper"
    side = next(p for p in shell.params if p.name == "side")
    assert (side.type_name, side.range_text(), side.default_text()) == ("choice", "lower|upper", "lower")
    listed = {e["name"]: e for e in json.loads(CliRunner().invoke(cli, ["warps", "--json"]).output)}
    assert {"name": "side", "choices": ["lower", "upper"]}.items() <= next(
        p for p in listed["shell"]["params"] if p["name"] == "side").items()
    tl = next(p for p in load_warp("perspective").params if p.name == "tl")
    assert tl.default_text() == "10%,0%"


def test_animate_refuses_to_vary_a_word(tmp_path):
    import cv2

    cv2.imwrite(str(tmp_path / "in.png"), np.full((30, 40, 3), 128, np.uint8))
    run = CliRunner().invoke(cli, ["animate", "shell", str(tmp_path / "in.png"), str(tmp_path / "o.gif"),
                                   "--vary", "side=lower:upper", "--frames", "2"])
    assert run.exit_code == 2 and "side is not a number" in run.output


STRIP_CASES = [(n, {"bend": b, "hdistort": d, "vdistort": -d}) for n in STYLES for b, d in ((100, 90), (-100, -90))]


@pytest.mark.parametrize("size", [(900, 2), (2, 900)])
@pytest.mark.parametrize("name,params", STRIP_CASES + [("perspective", {}), ("cylinder", {"angle": 160}),
                                                       ("sphere", {"angle": 120})])
def test_long_thin_strips_do_not_fold(size, name, params):
    """A strip two pixels thin at the ends of the ranges: the automatic grid follows W without a
    fold (no term of the maps grows with the aspect ratio), and the defaults accept any size."""
    w = make(name, params, size)
    mesh = FeatureWarper(*size, None).solve(w, "plain")
    assert mesh.flips() == 0 and mesh.info["grid"]["pl_error_px"] <= 0.5

"""The preset plugins: canvases, injectivity over the declared ranges, parameter checking."""

from __future__ import annotations

import math

import cv2
import numpy as np
import pytest

from featurewarp_cli import plugins
from featurewarp_cli.engine.warper import load_warp
from featurewarp_cli.engine.grid import Grid, signed_areas
from featurewarp_cli.plugins import Param

W, H = 160, 120


def source_points(width, height, n=1201):
    """Dense sample of the source pixel extent [-0.5, w-0.5] x [-0.5, h-0.5], edges included."""
    xs = np.linspace(-0.5, width - 0.5, max(n, 2 * width + 1))
    ys = np.linspace(-0.5, height - 0.5, max(n // 2, 2 * height + 1))
    gx, gy = np.meshgrid(xs, ys)
    return np.stack([gx.ravel(), gy.ravel()], 1)


def boundary_polygon(width, height, step=0.25):
    """The source border, counter-clockwise on screen (positive in x-right, y-down), densely sampled."""
    nx, ny = int(math.ceil(width / step)), int(math.ceil(height / step))
    xs = np.linspace(-0.5, width - 0.5, nx + 1)
    ys = np.linspace(-0.5, height - 0.5, ny + 1)
    top = np.stack([xs[:-1], np.full(nx, -0.5)], 1)
    right = np.stack([np.full(ny, width - 0.5), ys[:-1]], 1)
    bottom = np.stack([xs[::-1][:-1], np.full(nx, height - 0.5)], 1)
    left = np.stack([np.full(ny, -0.5), ys[::-1][:-1]], 1)
    return np.concatenate([top, right, bottom, left])


def winding_numbers(polygon, points):
    """Winding number of a closed polygon around each point."""
    total = np.zeros(len(points))
    for chunk in np.array_split(np.arange(len(points)), max(1, len(points) // 200)):
        d = polygon[None, :, :] - points[chunk, None, :]
        a = np.arctan2(d[..., 1], d[..., 0])
        step = np.diff(np.concatenate([a, a[:, :1]], 1), axis=1)
        total[chunk] = ((step + np.pi) % (2 * np.pi) - np.pi).sum(1) / (2 * np.pi)
    return total


# --- canvases -----------------------------------------------------------------------------

@pytest.mark.parametrize("params,canvas", [
    ({}, (160, 120)),
    ({"sx": 2, "sy": 2}, (320, 240)),
    ({"sy": 2}, (160, 240)),
    ({"sx": 0.5}, (80, 120)),
    ({"sx": 1.33, "sy": 0.77}, (round(160 * 1.33), round(120 * 0.77))),
    ({"sx": 0.001, "sy": 0.001}, (1, 1)),
    ({"width": 300}, (300, 120)),
    ({"height": 77, "sx": 3}, (480, 77)),
    ({"width": 90, "height": 45, "sx": 3, "sy": 3}, (90, 45)),
])
def test_stretch_canvas(params, canvas):
    """stretch's canvas is round(w*sx) x round(h*sy); --width / --height override the factors."""
    w = load_warp("stretch")(W, H, **params)
    assert w.canvas == canvas
    assert all(isinstance(v, int) for v in w.canvas)


@pytest.mark.parametrize("params", [{"sx": 2.5, "sy": 0.4}, {"width": 77, "height": 311}])
def test_stretch_maps_pixel_extent_onto_canvas_extent(params):
    """stretch sends the source extent's corners exactly onto the canvas extent's corners."""
    w = load_warp("stretch")(W, H, **params)
    cw, ch = w.canvas
    corners = np.array([[-0.5, -0.5], [W - 0.5, H - 0.5], [W / 2 - 0.5, -0.5]])
    np.testing.assert_allclose(w(corners), [[-0.5, -0.5], [cw - 0.5, ch - 0.5], [cw / 2 - 0.5, -0.5]],
                               atol=1e-12)


@pytest.mark.parametrize("preset", ["swirl", "bulge"])
def test_swirl_and_bulge_keep_the_input_size(preset):
    """swirl and bulge draw on a canvas of the input's size and fix the image border."""
    w = load_warp(preset)(W, H)
    assert w.canvas == (W, H)
    border = boundary_polygon(W, H, step=1.0)
    np.testing.assert_allclose(w(border), border, atol=1e-12)


@pytest.mark.parametrize("size", [(160, 120), (120, 160), (500, 40), (7, 300)])
@pytest.mark.parametrize("angle", [0.5, 1, 45, 90, 120, 179, 180, 181, 270, 359, 360])
def test_arc_canvas_is_the_bounding_box(size, angle):
    """Arc's canvas holds every W(point) of the source extent, in [-0.5, W-0.5], to within
    ``CANVAS_SLACK`` (a sliver that thin gets no row of its own), and is no larger."""
    from featurewarp_cli.plugins import CANVAS_SLACK

    w = load_warp("arc")(*size, angle=angle)
    cw, ch = w.canvas
    # every pixel centre, plus the extent's border very densely (the extremes lie on it)
    gx, gy = np.meshgrid(np.arange(size[0], dtype=float), np.arange(size[1], dtype=float))
    centres = np.stack([gx.ravel(), gy.ravel()], 1)
    pts = w(np.concatenate([centres, boundary_polygon(*size, step=min(size) / 4000)]))
    lo, hi = pts.min(0), pts.max(0)
    eps = 1e-7
    assert lo[0] >= -0.5 - eps and lo[1] >= -0.5 - eps
    assert hi[0] <= cw - 0.5 + CANVAS_SLACK + eps and hi[1] <= ch - 0.5 + CANVAS_SLACK + eps
    # tight: the box touches the top-left and wastes less than a pixel (plus sampling) at the far sides
    assert lo == pytest.approx([-0.5, -0.5], abs=0.05)
    assert hi[0] > cw - 1.6 and hi[1] > ch - 1.6


@pytest.mark.parametrize("angle", [30, 90, 120, 200])
def test_arc_geometry(angle):
    """Arc: top edge on the outer arc, rows concentric h apart, middle row keeps its length, symmetric."""
    w = load_warp("arc")(W, H, angle=angle)
    theta = math.radians(angle)
    xs = np.linspace(-0.5, W - 0.5, 801)
    rows = {y: w(np.stack([xs, np.full_like(xs, y)], 1)) for y in (-0.5, H / 2 - 0.5, H - 0.5)}
    # centre of the circles: the point all columns converge to
    col = w(np.array([[-0.5, -0.5], [-0.5, H - 0.5], [W - 0.5, -0.5], [W - 0.5, H - 0.5]]))
    d1, d2 = col[1] - col[0], col[3] - col[2]
    t = np.linalg.solve(np.stack([d1, -d2], 1), col[2] - col[0])
    centre = col[0] + t[0] * d1
    radii = {y: np.hypot(*(p - centre).T) for y, p in rows.items()}
    for r in radii.values():
        assert np.ptp(r) < 1e-6                                     # each row is an arc
    assert radii[-0.5][0] == pytest.approx(radii[H - 0.5][0] + H)   # top outside, h thick
    middle = rows[H / 2 - 0.5]
    length = np.hypot(*np.diff(middle, axis=0).T).sum()
    if W / theta - H / 2 >= H / 10:
        assert length == pytest.approx(W, rel=1e-4)
    # the sector spans the angle and is symmetric about the vertical through the centre
    ends = rows[-0.5][[0, -1]] - centre
    span = abs(math.atan2(ends[0, 0], -ends[0, 1]) - math.atan2(ends[1, 0], -ends[1, 1]))
    assert span == pytest.approx(theta, abs=1e-9)
    assert rows[-0.5][0, 1] == pytest.approx(rows[-0.5][-1, 1], abs=1e-9)


def test_arc_360_seam_maps_both_edges_onto_one_ray():
    """At 360 degrees the left and right edges meet on the same ray."""
    w = load_warp("arc")(W, H, angle=360)
    ys = np.linspace(-0.5, H - 0.5, 50)
    left = w(np.stack([np.full_like(ys, -0.5), ys], 1))
    right = w(np.stack([np.full_like(ys, W - 0.5), ys], 1))
    np.testing.assert_allclose(left, right, atol=1e-9)


def test_swirl_turns_as_imagemagick_and_keeps_the_centre():
    """swirl: the centre is fixed; positive angles turn counter-clockwise on screen (x right, y down),
    the way ImageMagick's ``-swirl`` turns (issue 25 item 4)."""
    w = load_warp("swirl")(W, H, angle=90, radius=0.5)
    c = np.array([(W - 1) / 2, (H - 1) / 2])
    np.testing.assert_allclose(w(c[None]), c[None], atol=1e-12)
    p = w(c[None] + [[5.0, 0.0]])[0] - c             # a point right of the centre moves up
    assert p[1] < 0 and abs(np.hypot(*p) - 5.0) < 1e-9


#: ``convert pts.png -swirl 120`` (ImageMagick 6.9.11) on a white 200 x 200 PNG with 3 x 3 red
#: dots centred at (100, 50) and (150, 99.5): where the dots' red weight lands, in pixel
#: coordinates. ImageMagick's swirl fades over radius max(w, h) / 2 as (1 - d/R)^2, as ours
#: does at --radius 0.5 on a square; its centre is half a pixel from ours (w/2 against (w-1)/2).
MAGICK_SWIRL_120 = {(100.0, 50.0): (75.03, 56.65), (150.0, 99.5): (142.78, 74.17)}
MAGICK_SWIRL_MINUS_120 = {(100.0, 50.0): (124.97, 56.65), (150.0, 99.5): (143.83, 124.10)}


@pytest.mark.parametrize("angle,measured", [(120, MAGICK_SWIRL_120), (-120, MAGICK_SWIRL_MINUS_120)])
def test_swirl_moves_points_where_imagemagick_swirl_moves_them(angle, measured):
    """--angle A takes a point where ``convert -swirl A`` takes it, within a pixel: the same
    direction of turn (the opposite sign would land the first dot 50 px away)."""
    w = load_warp("swirl")(200, 200, angle=angle, radius=0.5)
    sources = np.array(list(measured))
    np.testing.assert_allclose(w(sources), np.array(list(measured.values())), atol=1.0)


# --- injectivity over the declared range ----------------------------------------------------

INJECTIVITY_CASES = (
    [("swirl", {"angle": a}) for a in (-540, -90, 0, 120, 540)]
    + [("swirl", {"angle": -540, "radius": 10})]
    + [("bulge", {"strength": s}) for s in (-0.95, -0.5, 0.5, 2.95)]
    + [("bulge", {"strength": -0.95, "radius": 10})]
    + [("arc", {"angle": a}) for a in (1, 90, 359, 360)]
    + [("arc", {"angle": 1e-6})]
    + [("stretch", p) for p in ({"sx": 100, "sy": 0.01}, {"sx": 0.01, "sy": 100}, {"sx": 0.01, "sy": 0.01},
                                {"width": 1, "height": 65535})]
)

#: 0.25 px cells: the 81 x 61 grid of the brief is too coarse for swirl +-540 and bulge 2.95,
#: whose linear interpolation folds there although the maps themselves are injective.
FINE = (641, 481)


@pytest.mark.parametrize("preset,params", INJECTIVITY_CASES)
def test_preset_is_locally_injective(preset, params):
    """Every triangle of a fine grid keeps a positive area under W (and, on 81 x 61, all gentle cases)."""
    w = load_warp(preset)(W, H, **params)
    grid = Grid(W, H, 1, *FINE)
    nodes, tris = grid.nodes(), grid.triangles()
    area = signed_areas(w(nodes), tris)
    assert np.isfinite(area).all()
    assert (area > 0).all(), f"{np.count_nonzero(area <= 0)} triangles fold"


@pytest.mark.parametrize("preset,params", INJECTIVITY_CASES + [
    ("swirl", {"angle": 540, "radius": 0.25}), ("swirl", {"angle": -540}), ("bulge", {"strength": 2.95, "radius": 0.05}),
    ("bulge", {"strength": 2.95, "radius": 10})])
def test_preset_jacobian_has_positive_determinant(preset, params):
    """The map's own Jacobian (central differences, h = 1e-5 px) has det > 0 all over the source."""
    w = load_warp(preset)(W, H, **params)
    p = source_points(W, H, n=801)
    h = 1e-5
    ex, ey = np.array([h, 0.0]), np.array([0.0, h])
    dx = (w(p + ex) - w(p - ex)) / (2 * h)
    dy = (w(p + ey) - w(p - ey)) / (2 * h)
    det = dx[:, 0] * dy[:, 1] - dx[:, 1] * dy[:, 0]
    assert (det > 0).all(), f"det <= 0 at {np.count_nonzero(det <= 0)} points, min {det.min()}"


@pytest.mark.parametrize("preset,params", [c for c in INJECTIVITY_CASES
                                           if c[1] not in ({"angle": -540}, {"angle": 540}, {"strength": 2.95})])
def test_preset_is_injective_on_a_coarse_grid(preset, params):
    """On the 81 x 61 node grid all but the most extreme cases keep every triangle positive."""
    w = load_warp(preset)(W, H, **params)
    grid = Grid(W, H, 2, 81, 61)
    assert (signed_areas(w(grid.nodes()), grid.triangles()) > 0).all()


@pytest.mark.parametrize("preset,params", INJECTIVITY_CASES)
def test_preset_is_globally_injective(preset, params):
    """The image of the border winds exactly once around the image of every interior point.

    With all triangles positive (test above), the number of preimages of a point is this
    winding number, so 1 means no two source points share a target point.
    """
    w = load_warp(preset)(W, H, **params)
    polygon = w(boundary_polygon(W, H))
    gx, gy = np.meshgrid(np.linspace(0.0, W - 1.0, 33), np.linspace(0.0, H - 1.0, 25))
    inner = w(np.stack([gx.ravel(), gy.ravel()], 1))
    np.testing.assert_allclose(winding_numbers(polygon, inner), 1.0, atol=1e-6)


def test_winding_check_detects_an_overlap():
    """Control for the check above: a map that wraps more than once is caught."""
    w = load_warp("arc")(W, H, angle=360)
    polygon = w(boundary_polygon(W, H))
    doubled = np.concatenate([polygon, polygon])     # the border traversed twice: winding 2
    gx, gy = np.meshgrid(np.linspace(0.0, W - 1.0, 9), np.linspace(0.0, H - 1.0, 7))
    inner = w(np.stack([gx.ravel(), gy.ravel()], 1))
    assert np.allclose(winding_numbers(doubled, inner), 2.0)


@pytest.mark.parametrize("preset", ["swirl", "bulge", "arc", "stretch"])
def test_declared_ranges_match_the_advertised_limits(preset):
    """bulge stays inside -1 < S < 3; arc is 0 < DEG <= 360; swirl two turns either way; stretch F > 0."""
    params = {p.name: p for p in load_warp(preset).params}
    if preset == "bulge":
        s = params["strength"]
        assert s.min > -1 and s.max < 3
    elif preset == "arc":
        a = params["angle"]
        assert (a.min, a.min_open, a.max, a.max_open) == (0, True, 360, False)
    elif preset == "swirl":
        assert (params["angle"].min, params["angle"].max) == (-540, 540)
    else:
        for name in ("sx", "sy"):
            assert params[name].min == 0 and params[name].min_open


# --- parameter checking ---------------------------------------------------------------------

@pytest.mark.parametrize("preset,name,value,message", [
    ("swirl", "angle", float("nan"), "angle: nan is not a finite number"),
    ("swirl", "angle", float("inf"), "angle: inf is not a finite number"),
    ("swirl", "angle", "-inf", "angle: '-inf' is not a finite number"),
    ("swirl", "angle", "ninety", "angle: 'ninety' is not a number"),
    ("swirl", "radius", 0, "radius: 0 is out of range (0.001 <= F <= 10)"),
    ("swirl", "radius", 10.5, "radius: 10.5 is out of range"),
    ("arc", "angle", 0, "angle: 0 is out of range (0 < DEG <= 360)"),
    ("arc", "angle", 360.0001, "angle: 360.0001 is out of range"),
    ("arc", "angle", -30, "angle: -30 is out of range"),
    ("bulge", "strength", 3, "strength: 3 is out of range (-0.95 <= S <= 2.95)"),
    ("bulge", "strength", -1, "strength: -1 is out of range"),
    ("bulge", "strength", float("nan"), "strength"),
    ("stretch", "sx", 0, "sx: 0 is out of range (0 < F <= 100)"),
    ("stretch", "sy", -2, "sy: -2 is out of range"),
    ("stretch", "sy", float("inf"), "sy: inf is not a finite number"),
    ("stretch", "width", 10.5, "width: 10.5 is not a whole number"),
    ("stretch", "height", "7.25", "height: '7.25' is not a whole number"),
    ("stretch", "width", 0, "width: 0 is out of range (1 <= PX <= 65535)"),
    ("stretch", "height", 70000, "height: 70000 is out of range"),
    ("stretch", "width", float("nan"), "width: nan is not a finite number"),
])
def test_param_check_rejects_bad_values(preset, name, value, message):
    """Bad values (nan, inf, text, out of range, fractional ints) raise a ValueError that names the
    parameter as the API calls it (issue 25 item 3): ``angle: ...``, not the option ``--angle``."""
    cls = load_warp(preset)
    with pytest.raises(plugins.ParamError) as err:
        cls(W, H, **{name: value})
    assert str(err.value).startswith(message) and "--" not in str(err.value)
    assert err.value.render(plugins.option_flag).startswith(f"--{message}")
    param = next(p for p in cls.params if p.name == name)
    with pytest.raises(ValueError, match=f"^{name}: "):
        param.check(value)


@pytest.mark.parametrize("preset,name,value,expected", [
    ("stretch", "width", 300.0, 300), ("stretch", "width", "300", 300), ("stretch", "sx", "2.5", 2.5),
    ("arc", "angle", 360, 360.0), ("bulge", "strength", -0.95, -0.95), ("bulge", "strength", 2.95, 2.95),
    ("swirl", "angle", -540, -540.0),
])
def test_param_check_accepts_and_converts_good_values(preset, name, value, expected):
    """Valid values (bounds included where closed) pass and come back with the declared type."""
    w = load_warp(preset)(W, H, **{name: value})
    assert w.values[name] == expected
    assert type(w.values[name]) is next(p.type for p in w.params if p.name == name)


def test_param_names_with_underscores_become_dashed_options():
    """A parameter named with an underscore keeps its name in the API and is its --dashed option
    on the command line."""
    p = Param("inner_radius", float, 1.0, "help", min=0)
    with pytest.raises(ValueError, match="^inner_radius: -1 is out of range") as err:
        p.check(-1)
    assert err.value.render(plugins.option_flag).startswith("--inner-radius: -1 is out of range")


@pytest.mark.parametrize("preset", plugins.names())
def test_unknown_parameter_names_raise(preset):
    """An unknown parameter name is a ParamError (a ValueError) that names it and the preset,
    and the parameter it is closest to."""
    with pytest.raises(plugins.ParamError, match=rf"bogus: {preset} has no such parameter"):
        load_warp(preset)(W, H, bogus=1)
    with pytest.raises(plugins.ParamError, match=r"angel: swirl has no such parameter \(did you mean angle\?\)"):
        load_warp("swirl")(W, H, angel=1)


@pytest.mark.parametrize("size", [(0, 10), (10, 0), (-5, 5)])
def test_empty_image_size_is_rejected(size):
    """A warp of an empty image is a ValueError."""
    with pytest.raises(ValueError, match="empty"):
        load_warp("swirl")(*size)


def test_builtin_presets_are_registered_as_entry_points():
    """The four built-ins come through the featurewarp.warps entry-point group with their names."""
    assert {"stretch", "arc", "swirl", "bulge"} <= set(plugins.names())
    for name in ("stretch", "arc", "swirl", "bulge"):
        assert load_warp(name).name == name
    with pytest.raises(LookupError, match="unknown preset 'twirl'"):
        load_warp("twirl")


@pytest.mark.parametrize("preset", plugins.names())
def test_presets_are_pure_and_vectorized(preset, rng):
    """W maps (N, 2) to (N, 2), row by row the same as one point at a time, without touching its input."""
    w = load_warp(preset)(W, H)
    pts = rng.uniform([-0.5, -0.5], [W - 0.5, H - 0.5], size=(50, 2))
    keep = pts.copy()
    out = w(pts)
    assert out.shape == (50, 2) and out.dtype == np.float64
    np.testing.assert_array_equal(pts, keep)
    np.testing.assert_allclose(np.concatenate([w(p[None]) for p in pts]), out, rtol=0, atol=1e-12)
    np.testing.assert_array_equal(w(pts), out)


def test_stretch_factors_take_percentages():
    """--sx 150% is 1.5; other parameters do not take percentages."""
    w = load_warp("stretch")(W, H, sx="150%", sy=" 50% ")
    assert (w.values["sx"], w.values["sy"]) == (1.5, 0.5)
    with pytest.raises(ValueError, match="^angle: "):
        load_warp("swirl")(W, H, angle="50%")


def test_radial_presets_take_a_centre_and_stretch_a_size():
    """--center X,Y (pixels or percentages; 50%,50% is the default centre) for swirl and bulge;
    stretch --size WxH (pixels or percentages of the input)."""
    for name, extra in (("swirl", {"angle": 90}), ("bulge", {"strength": 0.8})):
        default = load_warp(name)(W, H, **extra)
        middle = load_warp(name)(W, H, center="50%,50%", **extra)
        corner = load_warp(name)(W, H, center="10,20", **extra)
        np.testing.assert_allclose(middle.centre, default.centre)
        np.testing.assert_allclose(corner(np.array([[10.0, 20.0]])), [[10.0, 20.0]])    # the centre stays
        assert not np.allclose(corner(np.array([[30.0, 30.0]])), default(np.array([[30.0, 30.0]])))
    assert load_warp("stretch")(W, H, size="300x100").canvas == (300, 100)
    assert load_warp("stretch")(W, H, size="150%x50%").canvas == (round(1.5 * W), round(0.5 * H))
    for bad in ("300", "ax3", "0x10"):
        with pytest.raises(ValueError, match="^size: "):
            load_warp("stretch")(W, H, size=bad)


def test_a_shape_a_hair_past_whole_pixels_gets_no_blank_row():
    """Arc 0.001 bows 0.001 px: its canvas was 513 x 513 for a 512 x 512 image, the last row and
    column blank."""
    assert load_warp("arc")(512, 512, angle=0.001).canvas == (512, 512)
    assert load_warp("arc")(512, 512, angle=1).canvas[1] > 512          # 0.2 px: a row of its own


@pytest.mark.parametrize("preset", plugins.names())
def test_preset_help_is_for_users_with_an_example(preset):
    """A preset's --help is its docstring's first paragraph (the maths stays out of it) and one
    example line of each command; the --boundary default shown is the preset's own."""
    from click.testing import CliRunner

    from featurewarp_cli.cli.main import cli
    from featurewarp_cli.cli.presets import preset_doc

    warp = plugins.load(preset)
    for command in ("warp", "compare", "batch"):
        text = preset_doc(warp, "", command)
        assert f"featurewarp {command} {preset} " in text.split("Example:")[1]
        for internal in ("Jacobian", "EDGE_MAX", "MIN_SQUEEZE", "ParamError", "ValueError", "tests/", "``"):
            assert internal not in text, (command, internal)
    shown = CliRunner().invoke(cli, ["warp", preset, "--help"]).output
    assert f"[default for {preset}: {warp.boundary}]" in " ".join(shown.split())


def test_a_plugin_without_docstring_or_example_is_helped_by_its_summary():
    from featurewarp_cli.cli.presets import preset_doc

    class Ripple(plugins.Warp):
        name, summary = "ripple", "Ripple the image."

    class Wave(plugins.Warp):
        """Wave it, --height PX high.

        Maths for developers."""

        name, summary, example = "wave", "A wave.", "--height 4"
        params = (Param("height", float, 2.0, "Height in pixels.", metavar="PX"),)

    assert preset_doc(Ripple) == "Ripple the image."
    assert preset_doc(Wave, "Intro.", "animate") == ("Intro.\n\nWave it, --height PX high.\n\n\b\nExample:\n  "
                                                     "featurewarp animate wave in.png out.gif -m mask.png "
                                                     "--vary height=0:4 --frames 24")


@pytest.mark.parametrize("args, shown", [
    (["stretch", "--sx", "100.0000001"], "100.0000001 is out of range (0 < F <= 100)"),
    (["arc", "--where", "lower", "--angle", "150.0000001"], "150.0000001 is out of range when --where is lower"),
    (["cylinder", "--distance", "1.0000001", "--angle", "1"], "from --distance 1.0000001 (at most 0.03"),
])
def test_a_refused_value_is_shown_as_given(tmp_path, args, shown):
    """Rounded to six digits, the value read as inside its range (100 is out of range (<= 100)),
    and the cylinder's largest angle at a close view came out 'at most 0'."""
    from click.testing import CliRunner

    from featurewarp_cli.cli.main import cli

    cv2.imwrite(str(tmp_path / "in.png"), np.zeros((40, 50, 3), np.uint8))
    run = CliRunner().invoke(cli, ["warp", args[0], str(tmp_path / "in.png"), str(tmp_path / "o.png"), *args[1:]])
    assert run.exit_code == 2 and shown in run.output, run.output


def test_a_stretch_below_a_pixel_says_its_side_is_one_pixel():
    """--sx 0.001 on a 256 px image gave a 1 px canvas in silence, the report keeping 0.001."""
    warp = load_warp("stretch")(256, 100, sx=0.001)
    assert warp.canvas == (1, 100)
    assert warp.review(None) == ["--sx 0.001 makes the width 0.256 px: it is 1 px"]
    assert load_warp("stretch")(256, 100, sx=0.5).review(None) == []

"""Rendering: inverse map by rasterized triangles, resampling, alpha and background."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from featurewarp_cli.render import raster as render
from featurewarp_cli.render.antialias import AA_START, Footprints
from featurewarp_cli.engine.api import warp
from featurewarp_cli.engine.warper import FeatureWarper, load_warp
from featurewarp_cli.engine.grid import Grid
from reference_render import ReferenceMap, reference_footprint

W, H = 160, 120


def inverse(mesh):
    return render.inverse_map(mesh.source, mesh.target, mesh.triangles, mesh.canvas)


def channels(image):
    return 1 if image.ndim == 2 else image.shape[2]


@pytest.fixture(scope="module")
def images(textured_bgr):
    """The same picture as gray, BGR and BGRA, in 8 and 16 bits."""
    bgr = textured_bgr
    gray = cv2.cvtColor(bgr, cv2.COLOR_BGR2GRAY)
    alpha = np.full((H, W), 255, np.uint8)
    alpha[20:50, 30:70] = 90
    bgra = np.dstack([bgr, alpha])
    eight = {"gray": gray, "bgr": bgr, "bgra": bgra}
    # 16 bits with content in the low byte too (not just 8-bit values times 257).
    ramp = (np.arange(W) % 200)[None, :]
    sixteen = {"gray": (gray * 250.0 + ramp).astype(np.uint16),
               "bgr": (bgr * 250.0 + ramp[..., None]).astype(np.uint16)}
    sixteen["bgra"] = np.dstack([sixteen["bgr"], alpha.astype(np.uint16) * 257])
    return {("uint8", k): v for k, v in eight.items()} | {("uint16", k): v for k, v in sixteen.items()}


# --- identity -----------------------------------------------------------------------------

@pytest.mark.parametrize("interp", ["linear", "cubic", "lanczos"])
@pytest.mark.parametrize("with_mask", [False, True])
def test_identity_stretch_reproduces_the_image(textured_bgr, blob_mask, interp, with_mask):
    """stretch sx = sy = 1 gives back the input (max abs difference <= 1 on uint8), and says it moved nothing."""
    from featurewarp_cli import FeatureWarpWarning

    with pytest.warns(FeatureWarpWarning, match="moves no pixel"):
        out = warp(textured_bgr, blob_mask if with_mask else None, "stretch", sx=1, sy=1, interp=interp)
    assert out.shape == textured_bgr.shape and out.dtype == np.uint8
    assert np.abs(out.astype(int) - textured_bgr).max() <= 1


def test_inverse_map_of_a_stretch_is_the_analytic_inverse():
    """Each pixel of a stretched canvas maps back to ((x + 0.5) / s - 0.5) in the source."""
    w = load_warp("stretch")(W, H, sx=2.5, sy=0.7)
    mesh = FeatureWarper(W, H).solve(w, "plain")
    coords, covered = inverse(mesh)
    cw, ch = w.canvas
    assert coords.shape == (ch, cw, 2) and covered.shape == (ch, cw)
    assert covered.all()
    y, x = np.mgrid[0:ch, 0:cw]
    np.testing.assert_allclose(coords[..., 0], (x + 0.5) * W / cw - 0.5, atol=2e-4)
    np.testing.assert_allclose(coords[..., 1], (y + 0.5) * H / ch - 0.5, atol=2e-4)


def test_inverse_map_of_a_rotated_grid_matches_barycentric_reference(rng):
    """inverse_map gives, per pixel, the barycentric source position of the triangle holding it."""
    grid = Grid.for_image(40, 30, 5)
    source = grid.nodes()
    a = np.radians(20)
    m = np.array([[np.cos(a), -np.sin(a)], [np.sin(a), np.cos(a)]]) * 1.4
    target = source @ m.T + [20.0, 3.0]
    coords, covered = render.inverse_map(source, target, grid.triangles(), (80, 70))
    y, x = np.mgrid[0:70, 0:80]
    expected = (np.stack([x, y], -1) - [20.0, 3.0]) @ np.linalg.inv(m).T
    inside = ((expected[..., 0] >= -0.5) & (expected[..., 0] <= 39.5)
              & (expected[..., 1] >= -0.5) & (expected[..., 1] <= 29.5))
    # Covered exactly where the pixel centre lies inside the warped rectangle (ties aside).
    margin = ((expected[..., 0] > -0.49) & (expected[..., 0] < 39.49)
              & (expected[..., 1] > -0.49) & (expected[..., 1] < 29.49))
    assert covered[margin].all()
    assert not covered[~inside].any()
    np.testing.assert_allclose(coords[covered], expected[covered], atol=1e-3)
    assert (coords[~covered] == -1).all()


# --- no cracks ----------------------------------------------------------------------------

GENTLE = [("swirl", {"angle": 120}), ("bulge", {"strength": 0.5}), ("bulge", {"strength": -0.9}),
          ("stretch", {"sx": 1.7, "sy": 0.6}), ("stretch", {"width": 57, "height": 140})]
STRONG = [("swirl", {"angle": -300}), ("swirl", {"angle": 200, "radius": 0.3}),
          ("bulge", {"strength": 2.5, "radius": 0.3}), ("stretch", {"sx": 0.33, "sy": 3.1}),
          ("stretch", {"width": 57, "height": 301})]


@pytest.mark.parametrize("preset,params,with_mask",
                         [(*c, False) for c in GENTLE + STRONG] + [(*c, True) for c in GENTLE])
def test_canvas_fully_covered(small_scene, preset, params, with_mask):
    """Swirl, bulge and stretch cover every canvas pixel: no cracks between triangles."""
    _, mask = small_scene
    h, w = mask.shape
    mesh = FeatureWarper(w, h, mask if with_mask else None).solve(load_warp(preset)(w, h, **params))
    coords, covered = inverse(mesh)
    assert covered.shape == (mesh.canvas[1], mesh.canvas[0])
    assert covered.all()
    assert (coords >= -0.5 - 1e-3).all()
    assert (coords[..., 0] <= w - 0.5 + 1e-3).all() and (coords[..., 1] <= h - 0.5 + 1e-3).all()


@pytest.mark.parametrize("angle", [60, 120, 360])
@pytest.mark.parametrize("dtype", [np.uint8, np.uint16])
def test_arc_corners_are_transparent(textured_bgr, dtype, angle):
    """Without antialiasing, arc leaves the canvas corners uncovered; with background None they get alpha 0, the sector alpha max."""
    image = textured_bgr.astype(dtype) * (257 if dtype == np.uint16 else 1)
    w = load_warp("arc")(W, H, angle=angle)
    warper = FeatureWarper(W, H)
    mesh = warper.solve(w)
    _, covered = inverse(mesh)
    out = warper.render(image, mesh, background=None, antialias=False)
    top = np.iinfo(dtype).max
    assert out.shape == (w.canvas[1], w.canvas[0], 4) and out.dtype == dtype
    assert not covered[-1, 0] and not covered[-1, -1]           # bottom corners lie outside the sector
    assert (~covered).sum() > 0.05 * covered.size
    assert (out[..., 3][~covered] == 0).all()
    assert (out[..., :3][~covered] == 0).all()
    assert (out[..., 3][covered] == top).all()
    np.testing.assert_array_equal(out[..., 3] == 0, ~covered)


@pytest.mark.parametrize("background", [None, (10, 200, 30)])
def test_antialiased_silhouette(textured_bgr, background):
    """With antialiasing (default) the sector's edge is feathered: pixels two or more pixels outside
    the mesh are exactly the background (or alpha 0), pixels two or more inside are untouched by
    it, and the edge holds partial values."""
    warper = FeatureWarper(W, H)
    mesh = warper.solve(load_warp("arc")(W, H, angle=150))
    _, covered = inverse(mesh)
    out = warper.render(textured_bgr, mesh, background=background, order="bgr").astype(int)
    ring = np.ones((5, 5), np.uint8)
    far_out = cv2.dilate(covered.astype(np.uint8), ring) == 0
    deep_in = cv2.erode(covered.astype(np.uint8), ring, borderType=cv2.BORDER_CONSTANT, borderValue=0) == 1
    if background is None:
        alpha = out[..., 3]
        assert (alpha[far_out] == 0).all() and (alpha[deep_in] == 255).all()
        edge = alpha[~far_out & ~deep_in]
        assert ((edge > 0) & (edge < 255)).sum() > 50
    else:
        expected = np.array(background[::-1])
        assert (out[far_out] == expected).all()
        plain = warper.render(textured_bgr, mesh, background=background, antialias=False, order="bgr").astype(int)
        assert (out[deep_in] != expected).any(axis=-1).mean() > 0.9
        assert np.abs(out - plain)[~far_out & ~deep_in].max() > 0


# --- kinds of images ----------------------------------------------------------------------

@pytest.mark.parametrize("kind", ["gray", "bgr", "bgra"])
@pytest.mark.parametrize("depth", ["uint8", "uint16"])
@pytest.mark.parametrize("preset,params", [("swirl", {"angle": 100}), ("stretch", {"sx": 1.5, "sy": 0.8})])
def test_output_keeps_dtype_and_channels(images, blob_mask, kind, depth, preset, params):
    """Gray, BGR, BGRA in 8 and 16 bits come out with the same dtype and channel count when covered."""
    image = images[(depth, kind)]
    out = warp(image, blob_mask, preset, **params)
    w = load_warp(preset)(W, H, **params)
    assert out.dtype == image.dtype
    assert out.ndim == image.ndim and channels(out) == channels(image)
    assert out.shape[:2] == (w.canvas[1], w.canvas[0])
    # and the content is a resampling of the input, not zeros or a rescaled copy
    assert abs(float(out.mean()) - float(image.mean())) < 0.1 * float(image.mean())


@pytest.mark.parametrize("depth", ["uint8", "uint16"])
def test_sixteen_bit_keeps_its_low_bits(images, depth):
    """A 16-bit image is resampled in 16 bits (not through 8 bits): identity keeps it within 1 step."""
    from featurewarp_cli import FeatureWarpWarning

    image = images[(depth, "bgr")]
    with pytest.warns(FeatureWarpWarning, match="moves no pixel"):
        out = warp(image, None, "stretch", interp="linear")
    assert np.abs(out.astype(np.int64) - image).max() <= 1
    if depth == "uint16":
        assert np.count_nonzero(out % 257) > 0.5 * out.size


@pytest.mark.parametrize("preset,params,move", [
    ("stretch", {"sx": 2.0, "sy": 1.5}, lambda x, y: ((x + 0.5) * 2.0 - 0.5, (y + 0.5) * 1.5 - 0.5)),
    ("stretch", {"sx": 0.5, "sy": 2.0}, lambda x, y: ((x + 0.5) * 0.5 - 0.5, (y + 0.5) * 2.0 - 0.5)),
])
@pytest.mark.parametrize("depth", [np.uint8, np.uint16])
def test_input_alpha_travels_with_its_pixels(textured_bgr, preset, params, move, depth):
    """A transparent square in the input is transparent at its warped place, opaque elsewhere."""
    top = np.iinfo(depth).max
    bgr = textured_bgr.astype(depth) * (257 if depth == np.uint16 else 1)
    alpha = np.full((H, W), top, depth)
    x0, x1, y0, y1 = 40, 80, 30, 70
    alpha[y0:y1, x0:x1] = 0
    out = warp(np.dstack([bgr, alpha]), None, preset, **params)
    assert out.shape[2] == 4
    (ax, ay), (bx, by) = move(x0, y0), move(x1 - 1, y1 - 1)
    inner = out[int(np.ceil(ay)) + 2 : int(by) - 1, int(np.ceil(ax)) + 2 : int(bx) - 1, 3]
    assert inner.size > 0 and (inner == 0).all()
    outside = np.ones(out.shape[:2], bool)
    outside[int(ay) - 3 : int(np.ceil(by)) + 4, int(ax) - 3 : int(np.ceil(bx)) + 4] = False
    assert (out[..., 3][outside] == top).all()


def test_alpha_travels_under_a_feature_aware_swirl(textured_bgr):
    """Under a feature-aware swirl, alpha and colour move together: wherever a pixel shows at all
    it is the white of the opaque squares (resampled premultiplied), and it is clear elsewhere."""
    alpha = np.where((np.arange(W)[None, :] // 10 + np.arange(H)[:, None] // 10) % 2 == 0, 255, 0).astype(np.uint8)
    bgr = np.zeros((H, W, 3), np.uint8)
    bgr[alpha == 255] = (255, 255, 255)
    mask = np.zeros((H, W), bool)
    mask[40:80, 60:100] = True
    out = warp(np.dstack([bgr, alpha]), mask, "swirl", angle=120, interp="linear")
    np.testing.assert_array_equal(out[..., 0], np.where(out[..., 3] > 0, 255, 0))
    assert 0.3 < (out[..., 3] > 128).mean() < 0.7


# --- background -----------------------------------------------------------------------------

@pytest.mark.parametrize("rgb", [(10, 20, 30), (255, 0, 128), (0, 0, 0)])
@pytest.mark.parametrize("kind", ["bgr", "bgra"])
@pytest.mark.parametrize("depth", ["uint8", "uint16"])
def test_background_fills_uncovered_pixels_exactly(images, rgb, kind, depth):
    """Without antialiasing, an (r, g, b) background lands in uncovered pixels as (b, g, r[, opaque]); 16-bit as value * 257."""
    image = images[(depth, kind)]
    w = load_warp("arc")(W, H, angle=150)
    warper = FeatureWarper(W, H)
    mesh = warper.solve(w)
    _, covered = inverse(mesh)
    out = warper.render(image, mesh, background=rgb, antialias=False, order="bgr")
    assert out.dtype == image.dtype and channels(out) == channels(image)
    factor = 257 if depth == "uint16" else 1
    expected = [rgb[2] * factor, rgb[1] * factor, rgb[0] * factor]
    if kind == "bgra":
        expected.append(np.iinfo(image.dtype).max)
    assert (~covered).any()
    np.testing.assert_array_equal(out[~covered], np.broadcast_to(expected, (np.count_nonzero(~covered), len(expected))))
    # covered pixels hold the image, not the background
    assert not np.all(out[covered] == expected, axis=-1).all()


def test_background_on_gray_is_its_luma(images):
    """Without antialiasing, a gray image keeps one channel; the fill is the colour's gray value."""
    w = load_warp("arc")(W, H, angle=150)
    warper = FeatureWarper(W, H)
    mesh = warper.solve(w)
    _, covered = inverse(mesh)
    out = warper.render(images[("uint8", "gray")], mesh, background=(200, 100, 50), antialias=False)
    assert out.ndim == 2
    assert (out[~covered] == round(0.299 * 200 + 0.587 * 100 + 0.114 * 50)).all()


def test_gray_with_transparent_background_gains_alpha(images):
    """Without antialiasing, a gray image with uncovered pixels and no background gains alpha 0 there:
    as BGRA for the command line's files, as grey + alpha in the API."""
    w = load_warp("arc")(W, H, angle=150)
    warper = FeatureWarper(W, H)
    mesh = warper.solve(w)
    _, covered = inverse(mesh)
    gray = images[("uint8", "gray")]
    out = warper.render(gray, mesh, background=None, antialias=False, order="bgr")
    assert out.shape[2] == 4
    np.testing.assert_array_equal(out[..., 3] == 0, ~covered)
    assert (out[..., 0] == out[..., 1]).all() and (out[..., 1] == out[..., 2]).all()
    api = warper.render(gray, mesh, background=None, antialias=False)        # the API: grey stays grey
    assert api.shape[2] == 2
    np.testing.assert_array_equal(api[..., 1] == 0, ~covered)
    np.testing.assert_array_equal(api[..., 0], out[..., 0])


# --- the compiled rasterizer against the reference (tests/reference_render.py) ----------------

def random_mesh(seed, width=70, height=50, nodes=60, triangles=120):
    """Random triangles over and around a canvas: most between near nodes, some across it;
    partly or wholly off it, huge and tiny ones, overlapping ones, flat edges, collinear
    (zero-area) ones and nodes on pixel centres (ties between neighbours). Sources are
    the targets scaled by 0.3-4 so that some triangles minify, anisotropically, down
    several pyramid levels, then clipped to the image (a source position below -0.75
    would read as the renderer's "uncovered")."""
    rng = np.random.default_rng(seed)
    target = rng.uniform([-0.4 * width, -0.4 * height], [1.4 * width, 1.4 * height], (nodes, 2))
    target[:10] = np.round(target[:10])                                  # on pixel centres
    target[10:14] = [[-3 * width, -2 * height], [4 * width, -height], [width / 2, 5 * height],
                     [-width, 3 * height]]                              # huge triangles
    target[14:20] = target[20:26] + rng.uniform(-0.6, 0.6, (6, 2))      # tiny triangles
    target[26:30, 1] = target[30:34, 1]                                 # flat edges
    target[34] = 0.5 * (target[35] + target[36])                        # collinear
    near = np.argsort(np.hypot(*(target[:, None] - target[None]).transpose(2, 0, 1)), axis=1)[:, 1:7]
    first = rng.integers(0, nodes, triangles)
    tri = np.column_stack([first, np.array([rng.choice(near[i], 2, replace=False) for i in first])])
    tri[:10] = rng.integers(0, nodes, (10, 3))                           # across the canvas
    tri[:6] = [[10, 11, 0], [12, 13, 1], [14, 20, 21], [15, 21, 22], [26, 30, 3], [34, 35, 36]]
    scale = rng.uniform(0.3, 4.0, (nodes, 2))
    source = (target - target.mean(0)) * scale + [width / 2, height / 2]
    source += rng.normal(0, 2, source.shape)
    source = np.clip(source, -0.5, [width - 0.5, height - 0.5])
    return source, target, tri, (width, height)


def warped_grid(preset, width=90, height=60, cell=3, **params):
    """The plain warp's mesh (W applied to the grid's nodes; folds where W is too curved)."""
    grid = Grid.for_image(width, height, cell)
    w = load_warp(preset)(width, height, **params)
    return grid.nodes(), w(grid.nodes()), grid.triangles(), tuple(w.canvas)


def solved_mesh(preset, mask, **params):
    """A feature-aware mesh of the 160 x 120 test images."""
    mesh = FeatureWarper(W, H, mask).solve(load_warp(preset)(W, H, **params))
    return mesh.source, mesh.target, mesh.triangles, mesh.canvas


def assert_inverse_map_matches_reference(mesh):
    """Coverage as the reference's except within 1e-6 px of an edge; every covered pixel's
    source position within 1e-3 px of what a triangle holding its centre gives it."""
    coords, covered = render.inverse_map(*mesh)
    ref = ReferenceMap(*mesh)
    sure = ~ref.near_edge
    np.testing.assert_array_equal(covered[sure], ref.covered[sure])
    assert ref.error(coords)[covered].max() <= 1e-3
    assert (coords[~covered] == -1).all()
    return covered


@pytest.mark.parametrize("seed", range(8))
def test_inverse_map_matches_reference_on_random_meshes(seed):
    covered = assert_inverse_map_matches_reference(random_mesh(seed))
    assert covered.any() and not covered.all()


PRESET_MESHES = [("swirl", {"angle": 300}), ("arc", {"angle": 150}), ("bulge", {"strength": 2.5, "radius": 0.4}),
                 ("stretch", {"sx": 0.3, "sy": 1.7})]


@pytest.mark.parametrize("preset, params", PRESET_MESHES)
def test_inverse_map_matches_reference_on_presets(preset, params, blob_mask):
    """The four presets, plain (folded where W curves faster than the grid) and feature-aware."""
    assert_inverse_map_matches_reference(warped_grid(preset, 48, 40, **params))
    assert_inverse_map_matches_reference(solved_mesh(preset, blob_mask, **params))


def footprints_of(jacobians):
    """Footprints of (n, 2, 2) Jacobians, through records that hold only J."""
    rec = np.zeros((jacobians.shape[0], len(render.Triangles.FIELDS)))
    rec[:, render.Triangles.J] = jacobians.reshape(-1, 4)
    return Footprints(rec)


def assert_footprints_match_svd(jacobians):
    """Filtered exactly where J's largest singular value exceeds AA_START (ties aside) and the
    reference's filter is more than one probe on level 0; axis within 1e-6 of J's major left
    singular vector; probes, their spacing and the pyramid level (eighth octaves of m2) as
    :func:`reference_footprint` gives them from numpy's SVD and log2."""
    foot = footprints_of(jacobians)
    sv = np.linalg.svd(jacobians, compute_uv=False)
    minified = foot.index >= 0
    clear = np.abs(sv[:, 0] - AA_START) > 1e-9
    over = np.flatnonzero(clear & (sv[:, 0] > AA_START))
    _, k_over, _, level_over = reference_footprint(jacobians[over])
    np.testing.assert_array_equal(minified[over], (k_over > 1) | (level_over > 0))
    assert not minified[clear & (sv[:, 0] <= AA_START)].any()
    sel = np.flatnonzero(minified)
    np.testing.assert_array_equal(foot.index[sel], np.arange(sel.size))
    axis, k, spacing, level = reference_footprint(jacobians[sel])
    np.testing.assert_array_equal(foot.ints[:, 0], k)
    step = foot.floats[:, :2].astype(np.float64)
    length = np.hypot(step[:, 0], step[:, 1])
    np.testing.assert_allclose(length, np.where(k > 1, spacing, length), rtol=1e-6)
    moving = k > 1
    cosine = np.abs(np.einsum("ni,ni->n", step[moving] / length[moving, None], axis[moving]))
    assert cosine.size == 0 or cosine.min() > 1 - 1e-6
    base, blend, frac = foot.ints[:, 1], foot.ints[:, 2], foot.floats[:, 2].astype(np.float64)
    np.testing.assert_allclose(base + frac, level, atol=1e-6)
    assert ((frac >= 0) & (frac <= 1)).all()         # 1 where float32 rounds it up: all on b + 1
    np.testing.assert_array_equal(blend, frac > 1e-4)
    assert foot.max_level == (base + blend).max(initial=0)
    return foot


@pytest.mark.parametrize("scale", [0.5, 1.0, 3.0, 40.0])
def test_footprints_follow_the_singular_value_decomposition(scale):
    """Random Jacobians, axis-aligned ones, scaled rotations right at the threshold."""
    rng = np.random.default_rng(int(scale * 10))
    jac = rng.normal(0, scale, (20000, 4))
    jac[:500] = np.round(jac[:500])
    jac[500:1000, 1:3] = 0                                               # axis-aligned
    angle = rng.uniform(0, 2 * np.pi, 1000)
    near = AA_START * (1 + rng.uniform(-1e-12, 1e-12, 1000))             # s1 at the threshold
    jac[1000:2000] = np.stack([np.cos(angle), -np.sin(angle), np.sin(angle), np.cos(angle)], 1) * near[:, None]
    jac[2000:2100] = [AA_START, 0.0, 0.0, 0.5]
    foot = assert_footprints_match_svd(jac.reshape(-1, 2, 2))
    assert np.unique(foot.ints[:, 0]).size >= 3                          # several probe counts


def test_footprints_of_odd_jacobians():
    """NaN and overflowing Jacobians are not filtered; rank-one, isotropic, huge and tiny
    ones get the SVD's footprint (isotropic: one probe, so no axis is needed)."""
    odd = np.array([[5.0, 5.0, 5.0, 5.0], [30.0, 0, 0, 29.0], [1e-5, 0, 0, 1.2], [-2.0, 0, 0, -2.0],
                    [0, 3.0, -3.0, 0], [1e15, 0, 0, 1.0], [0, 0, 0, 0], [1e-300, 0, 0, 1e-300]])
    foot = assert_footprints_match_svd(odd.reshape(-1, 2, 2))
    assert (foot.index[:6] >= 0).all() and (foot.index[6:] < 0).all()
    assert foot.ints[3, 0] == foot.ints[4, 0] == 1
    with np.errstate(invalid="ignore"):
        bad = footprints_of(np.array([[np.nan, 0, 0, 1], [1e200, 0, 0, 1e200], [1e200, 0, 0, 1e199],
                                      [np.inf, 0, 0, 1]]).reshape(-1, 2, 2))
    assert (bad.index < 0).all() and bad.ints.shape == (0, 3) and bad.max_level == 0


@pytest.mark.parametrize("mesh", [random_mesh(3), warped_grid("swirl", angle=300),
                                  warped_grid("stretch", sx=0.15, sy=0.4)], ids=["random", "swirl", "stretch"])
def test_triangle_records_and_their_footprints_match_reference(mesh):
    """Each kept triangle's J is the reference's (relative 1e-9), and its footprint the SVD's."""
    tris = render.Triangles(*mesh)
    ref = ReferenceMap(*mesh)
    jac = np.full((len(mesh[2]), 2, 2), np.nan)
    jac[ref.kept] = ref.jacobians
    expected = jac[tris.index]
    assert 0 < tris.count and not np.isnan(expected).any()
    got = tris.records(np.arange(tris.count))[:, render.Triangles.J].reshape(-1, 2, 2)
    scale = np.abs(expected).max(axis=(1, 2), keepdims=True)
    assert (np.abs(got - expected) <= 1e-9 * scale).all()
    assert (np.diff(tris.ylo) >= 0).all()                                # rasterizing order
    assert_footprints_match_svd(got)


def test_nan_and_huge_coordinates_are_safe(textured_bgr):
    """Triangles with a NaN node cover nothing (the others render as without them); a node
    thrown to 1e300 neither crashes nor puts a non-finite source position on the canvas."""
    source, target, tri, canvas = warped_grid("swirl", W, H, cell=8, angle=90)
    bad = np.zeros(len(target), bool)
    bad[[5, 40, 41, 200]] = True
    target = target.copy()
    target[bad] = np.nan
    coords, covered = render.inverse_map(source, target, tri, canvas)
    keep = ~bad[tri].any(axis=1)
    expected, expected_covered = render.inverse_map(source, target, tri[keep], canvas)
    np.testing.assert_array_equal(coords, expected)
    np.testing.assert_array_equal(covered, expected_covered)
    target[bad] = [1e300, -1e300]
    coords, covered = render.inverse_map(source, target, tri, canvas)
    assert np.isfinite(coords).all() and covered.any()
    for antialias in (True, False):
        out = render.render(textured_bgr, source, target, tri, canvas, antialias=antialias)
        assert out.shape[:2] == (canvas[1], canvas[0]) and out.shape[2] in (3, 4)


@pytest.mark.parametrize("seed", range(8))
@pytest.mark.parametrize("antialias", [True, False])
def test_render_on_random_meshes_does_not_depend_on_bands_or_threads(seed, antialias):
    """Gray, BGR and BGRA, 8 and 16 bits, transparent or coloured background: small bands
    in two threads give the same bytes as one band in one thread."""
    rng = np.random.default_rng(100 + seed)
    depth = (np.uint8, np.uint16)[seed % 2]
    channels = (3, 1, 4, 3)[seed % 4]
    image = rng.integers(0, np.iinfo(depth).max, (50, 70, channels), dtype=depth, endpoint=True)
    image = cv2.GaussianBlur(image, (3, 3), 0).reshape(image.shape)
    image = image[..., 0] if channels == 1 else image
    kw = dict(interp="linear", background=None if seed % 3 else (10, 200, 30), antialias=antialias)
    whole = render.render(image, *random_mesh(seed), band_pixels=10**9, threads=1, **kw)
    banded = render.render(image, *random_mesh(seed), band_pixels=600, threads=2, **kw)
    assert whole.dtype == image.dtype
    np.testing.assert_array_equal(banded, whole)


def test_render_refuses_other_dtypes(textured_bgr):
    with pytest.raises(ValueError, match="uint8 or uint16, not float32"):
        render.render(textured_bgr.astype(np.float32), *warped_grid("swirl", W, H, angle=90))


@pytest.mark.parametrize("kind", ["gray", "bgr", "bgra"])
@pytest.mark.parametrize("depth", [np.uint8, np.uint16])
@pytest.mark.parametrize("sx, sy", [(0.2, 0.3), (0.15, 0.4)])
def test_strong_shrink_approaches_the_area_average(kind, depth, sx, sy):
    """Shrunk 3-7x (several pyramid levels, up to 4 probes a side), fine noise in every kind
    of image comes out within half the plain sampling's error of cv2's area average."""
    rng = np.random.default_rng(1)
    image = cv2.GaussianBlur(rng.integers(0, 256, (H, W, 3), dtype=np.uint8), (0, 0), 0.7)
    if kind == "gray":
        image = cv2.cvtColor(image, cv2.COLOR_BGR2GRAY)
    elif kind == "bgra":
        image = np.dstack([image, np.where(np.arange(W) < 80, 255, 90).astype(np.uint8)[None].repeat(H, 0)])
    image = image.astype(depth) * (257 if depth == np.uint16 else 1)
    mesh = warped_grid("stretch", W, H, cell=4, sx=sx, sy=sy)
    out = render.render(image, *mesh, "cubic", (0, 0, 0))
    plain = render.render(image, *mesh, "cubic", (0, 0, 0), antialias=False)
    assert out.dtype == image.dtype and out.shape[2:] == image.shape[2:]
    area = cv2.resize(image, (out.shape[1], out.shape[0]), interpolation=cv2.INTER_AREA).astype(float)

    def error(a):
        return np.abs(a.astype(float) - area)[2:-2, 2:-2].mean()

    assert error(out) < 0.5 * error(plain)


@pytest.mark.parametrize("interp", [cv2.INTER_LINEAR, cv2.INTER_CUBIC, cv2.INTER_LANCZOS4])
def test_tiled_remap_equals_one_call(monkeypatch, interp):
    """remap() splits what OpenCV refuses (a side >= 32767) into tiles with source windows;
    with a small limit forced, the tiles give exactly what one cv2.remap call gives."""
    from featurewarp_cli.render import remap as remap_module

    rng = np.random.default_rng(3)
    image = rng.integers(0, 255, (90, 120, 3), np.uint8)
    my, mx = np.mgrid[0:70, 0:150].astype(np.float32)
    mx = mx * 0.7 + 5 * np.sin(my / 9) - 2          # reaches past the left edge: replicated
    my = my * 1.2 + 3 * np.cos(mx / 7)
    whole = cv2.remap(image, mx, my, interp, borderMode=cv2.BORDER_REPLICATE)
    monkeypatch.setattr(remap_module, "LIMIT", 23)
    assert np.array_equal(remap_module.remap(image, mx, my, interp), whole)


def test_sides_beyond_opencv_limit_render(tmp_path):
    """A 40000-px-wide input and a 1 x 500000 canvas: OpenCV's remap asserts below 32767 px per
    side; the renderer tiles instead of failing."""
    image = np.tile(np.arange(40000, dtype=np.uint16)[None, :, None] % 251, (2, 1, 3)).astype(np.uint8)
    warper = FeatureWarper(40000, 2)
    out = warper.render(image, warper.solve(load_warp("stretch")(40000, 2, sx=0.5), "plain"))
    assert out.shape[:2] == (2, 20000)
    column = np.zeros((5000, 1, 3), np.uint8)
    column[::2] = 255
    warper = FeatureWarper(1, 5000)
    tall = warper.render(column, warper.solve(load_warp("stretch")(1, 5000, sy=100), "plain"))
    assert tall.shape[:2] == (500000, 1)


def test_the_api_speaks_rgb_and_keeps_dtype_and_grey():
    """issue 13: an RGB image with background (255, 0, 0) gets red where uncovered; a float32
    image in [0, 1] comes back float32 in [0, 1]; a grey image keeps one channel when a
    background is given; colour names work; bad values and dtypes are ValueErrors."""
    rng = np.random.default_rng(1)
    rgb = rng.integers(0, 255, (H, W, 3), np.uint8)
    mask = np.zeros((H, W), bool)
    mask[20:40, 30:60] = True
    red = warp(rgb, mask, "arc", angle=150, background=(255, 0, 0))
    corner = red[0, 0] if (red[0, 0] != 0).any() else red[-1, 0]
    assert tuple(corner) == (255, 0, 0)
    assert tuple(warp(rgb, mask, "arc", angle=150, background="white")[0, 0]) == (255, 255, 255)
    floats = warp(rgb.astype(np.float32) / 255, mask, "swirl", angle=60)
    assert floats.dtype == np.float32 and 0.0 <= floats.min() and floats.max() <= 1.0
    assert np.abs(floats * 255 - warp(rgb, mask, "swirl", angle=60)).max() < 1.0
    grey = warp(rgb[..., 0], mask, "arc", angle=150, background=(0, 0, 0))
    assert grey.ndim == 2 or grey.shape[2] == 1
    for bad in ((300, 0, 0), (1, 2), "nocolour"):
        with pytest.raises(ValueError):
            warp(rgb, mask, "arc", angle=150, background=bad)
    for image in (rgb.astype(np.complex64), rng.integers(0, 255, (H, W, 5), np.uint8), rgb.astype(np.float32) * 2):
        with pytest.raises(ValueError):
            warp(image, mask, "swirl", angle=60)


def test_one_mask_rule_in_the_api():
    """bool as is; integers at or above 128 (as the CLI reads 8-bit masks; 32896 for uint16, 64
    for int8: 128/255 of their range); floats at or above 0.5."""
    from featurewarp_cli.engine.arrays import mask_array

    values = np.array([[0, 127, 128, 255]], np.uint8)
    assert mask_array(values, (1, 4)).tolist() == [[False, False, True, True]]
    assert mask_array(values.astype(np.uint16) * 257, (1, 4)).tolist() == [[False, False, True, True]]
    for kind in (np.int32, np.int64, np.uint32):                     # 0/255 masks as numpy makes them
        assert mask_array(values.astype(kind), (1, 4)).tolist() == [[False, False, True, True]]
    assert mask_array(np.array([[0, 63, 64, 127]], np.int8), (1, 4)).tolist() == [[False, False, True, True]]
    assert mask_array(np.array([[0.2, 0.5]]), (1, 2)).tolist() == [[False, True]]


def test_nearest_copies_labels_only(tmp_path):
    """--interp nearest on a label map: every output value is one of the input's (or the
    background), with no blend at the mesh's edge."""
    labels = np.zeros((H, W), np.uint8)
    labels[:, W // 3:] = 50
    labels[H // 2:, : W // 2] = 200
    mask = np.zeros((H, W), bool)
    mask[10:30, 10:30] = True
    out = warp(labels, mask, "arc", angle=150, interp="nearest", background=(0, 0, 0))
    assert set(np.unique(out)) <= {0, 50, 200}
    out = warp(labels, mask, "swirl", angle=120, interp="nearest")
    assert set(np.unique(out)) <= {0, 50, 200}


def test_static_gif_output(tmp_path):
    from click.testing import CliRunner

    from featurewarp_cli.cli.main import cli

    source = tmp_path / "in.png"
    cv2.imwrite(str(source), np.random.default_rng(4).integers(0, 255, (H, W, 3), np.uint8))
    run = CliRunner().invoke(cli, ["warp", "swirl", str(source), str(tmp_path / "o.gif")])
    assert run.exit_code == 0, run.output
    assert cv2.imread(str(tmp_path / "o.gif")).shape == (H, W, 3)


def test_gray_and_alpha_gets_the_silhouettes_partial_alpha_as_rgba_does():
    """Through the API a (h, w, 2) image's alpha came out 0 or 255 along the arc's edge (the
    coverage went to an alpha only a fourth channel had); RGBA's had 249 levels."""
    gray_alpha = warp(np.full((H, W, 2), 255, np.uint8), None, "arc", angle=120)
    rgba = warp(np.full((H, W, 4), 255, np.uint8), None, "arc", angle=120)
    assert gray_alpha.shape[2] == 2 and np.array_equal(gray_alpha[..., 1], rgba[..., 3])


def test_gray_and_alpha_is_resampled_premultiplied_too():
    """A (h, w, 2) gray + alpha array through the API kept the dark fringe."""
    image = np.zeros((H, W, 2), np.uint8)
    cv2.circle(image, (W // 2, H // 2), 40, (255, 255), -1)
    out = warp(image, None, "swirl", angle=120)
    edge = (out[..., 1] > 0) & (out[..., 1] < 255)
    assert edge.sum() > 50 and out[..., 0][edge].min() >= 250


@pytest.mark.parametrize("dtype", [np.uint8, np.uint16])
def test_the_colour_under_transparent_pixels_does_not_bleed_into_edges(dtype):
    """Colour and alpha were resampled apart (straight alpha): the green left under the
    transparent ground of a white cut-out tinted its edges (alpha 163 with G 92 of 255), and
    flattened on white they showed a gray ring. Premultiplied, an edge is the disc's white."""
    top = np.iinfo(dtype).max
    image = np.zeros((H, W, 4), dtype)
    image[..., 1] = top                                       # green, wholly transparent
    cv2.circle(image, (W // 2, H // 2), 40, (top, top, top, top), -1)
    out = warp(image, None, "swirl", angle=120)
    edge = (out[..., 3] > 0) & (out[..., 3] < top)
    assert edge.sum() > 50
    assert out[..., :3][edge].min() >= top * 0.98
    opaque = out[..., 3] == top
    assert out[..., :3][opaque].min() >= top * 0.98


def test_an_opaque_rgba_image_renders_as_it_did():
    """Wholly opaque alpha takes the straight path: the same bytes as the colour alone."""
    rng = np.random.default_rng(8)
    colour = rng.integers(0, 255, (H, W, 3), np.uint8)
    rgba = np.dstack([colour, np.full((H, W), 255, np.uint8)])
    a = warp(rgba, None, "bulge", background=(0, 0, 0))
    b = warp(colour, None, "bulge", background=(0, 0, 0))
    assert np.array_equal(a[..., :3], b)


def test_alpha_is_added_only_where_some_pixel_is_not_opaque():
    """A swirl centred half a pixel off the middle gave an alpha channel that was 255 everywhere
    (silhouette pixels whose coverage rounded to opaque): RGB one way, RGBA the other, and
    ``featurewarp diff`` refused to compare the two."""
    image = np.random.default_rng(3).integers(0, 255, (H, W, 3), np.uint8)
    for centre in ((W / 2, H / 2), ((W - 1) / 2, (H - 1) / 2)):
        assert warp(image, None, "swirl", angle=90, center=centre).shape == (H, W, 3)


def test_no_colour_is_left_under_a_fully_transparent_pixel():
    """The README promises colour 0 under alpha 0: a triangle's sliver of coverage rounded the
    alpha to 0 and left the colour (squeeze of the astronaut: 3 such pixels, fish 2, arc 1;
    WebP, whose encoder may keep or smear that colour, then differed from PNG)."""
    from featurewarp_cli import warp

    image = cv2.cvtColor(cv2.imread("samples/astronaut.png"), cv2.COLOR_BGR2RGB)
    mask = cv2.imread("samples/astronaut_mask.png", cv2.IMREAD_GRAYSCALE)
    out = warp(image, mask, "squeeze")
    assert out.shape[2] == 4 and (out[..., 3] == 0).any()
    assert not out[out[..., 3] == 0][:, :3].any()


@pytest.mark.parametrize("dtype", [np.uint8, np.uint16])
@pytest.mark.parametrize("channels", [2, 4])
@pytest.mark.parametrize("contiguous", [True, False])
def test_the_colour_under_alpha_0_is_zeroed_exactly_and_only_there(dtype, channels, contiguous):
    """Each pixel is read as one integer whose top bits are its alpha (0.19 -> 0.01 s at 15 MP):
    the same pixels as channel by channel, for every dtype and channel count, in any layout."""
    top = np.iinfo(dtype).max
    rng = np.random.default_rng(7)
    image = rng.integers(0, top + 1, (40, 30, channels), dtype=dtype)
    image[rng.random((40, 30)) < 0.3, -1] = 0
    image[:4, :, -1] = 1                              # the lowest alpha keeps its colour
    expected = image.copy()
    expected[expected[..., -1] == 0] = 0
    given = image.copy() if contiguous else np.asfortranarray(image)
    np.testing.assert_array_equal(render._zero_under_transparent(given), expected)

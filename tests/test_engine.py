"""The engine's invariants (DESIGN.md), factorization reuse and fold-overs."""

from __future__ import annotations

import math

import numpy as np
import pytest

from featurewarp_cli import plugins
from featurewarp_cli.engine.api import warp
from featurewarp_cli.engine.warper import FeatureWarper, load_warp
from featurewarp_cli.engine.grid import signed_areas
from featurewarp_cli.plugins import Param, Warp

FORMULATIONS = ["exact", "paper"]
PRESET_CASES = [
    ("stretch", {"sx": 1.6, "sy": 0.8}),
    ("stretch", {"sy": 2.0}),
    ("arc", {"angle": 120}),
    ("arc", {"angle": 270}),
    ("swirl", {"angle": 120}),
    ("swirl", {"angle": -90, "radius": 0.8}),
    ("bulge", {"strength": 0.5}),
    ("bulge", {"strength": -0.5}),
]


class Similarity(Warp):
    """Rotation by ``angle`` degrees, uniform ``scale`` and a translation, on a canvas that fits."""

    name = "similarity-test"
    params = (Param("angle", float, 30.0, "degrees"), Param("scale", float, 1.3, "factor", min=0, min_open=True))

    def _setup(self, angle, scale):
        a = math.radians(angle)
        self.m = scale * np.array([[math.cos(a), -math.sin(a)], [math.sin(a), math.cos(a)]])
        corners = np.array([[-0.5, -0.5], [self.width - 0.5, -0.5],
                            [self.width - 0.5, self.height - 0.5], [-0.5, self.height - 0.5]]) @ self.m.T
        lo, hi = corners.min(0), corners.max(0)
        self.t = -lo - 0.5 + np.array([3.0, 2.0])
        self.canvas = (int(math.ceil(hi[0] - lo[0])) + 6, int(math.ceil(hi[1] - lo[1])) + 4)

    def forward(self, points):
        return points @ self.m.T + self.t


# --- invariant (a): W a similarity -> output equals W for any mask ------------------------

@pytest.mark.parametrize("formulation", FORMULATIONS)
@pytest.mark.parametrize("mask_name", ["blob_mask", "random_mask", "border_mask"])
@pytest.mark.parametrize("angle,scale", [(30.0, 1.3), (-150.0, 0.6)])
def test_similarity_warp_is_reproduced_exactly(request, formulation, mask_name, angle, scale):
    """For W = rotation + uniform scale + translation, every node lands on W(node) for any mask."""
    mask = request.getfixturevalue(mask_name)
    w = Similarity(160, 120, angle=angle, scale=scale)
    warper = FeatureWarper(160, 120, mask, formulation=formulation)
    mesh = warper.solve(w, "similarity")
    assert warper.factorizations == 1            # the feature-aware system really ran
    assert len(mesh.info["components"]) >= 2
    np.testing.assert_allclose(mesh.target, w(mesh.source), rtol=0, atol=1e-6)
    assert mesh.flips() == 0


@pytest.mark.parametrize("formulation", FORMULATIONS)
def test_similarity_warp_renders_like_the_plain_warp(textured_bgr, blob_mask, formulation):
    """The rendered image of a similarity W with a mask equals the plain warp's render."""
    w = Similarity(160, 120)
    warper = FeatureWarper(160, 120, blob_mask, formulation=formulation)
    featured = warper.render(textured_bgr, warper.solve(w, "similarity"), background=(0, 0, 0))
    plain = warper.render(textured_bgr, warper.solve(w, "plain"), background=(0, 0, 0))
    # Node positions agree to ~1e-11 px, so rasterization may only differ on exact ties.
    assert featured.shape == plain.shape
    assert np.count_nonzero(np.any(featured != plain, axis=-1)) <= 0.001 * plain.shape[0] * plain.shape[1]


def test_rigid_mode_does_not_reproduce_a_scaling_similarity(blob_mask):
    """Control: with rigid features a scaling similarity is NOT reproduced (the check above can fail)."""
    w = Similarity(160, 120, scale=1.3)
    mesh = FeatureWarper(160, 120, blob_mask).solve(w, "rigid")
    assert np.abs(mesh.target - w(mesh.source)).max() > 1.0


# --- invariant (b): empty mask -> plain warp ----------------------------------------------

@pytest.mark.parametrize("formulation", FORMULATIONS)
@pytest.mark.parametrize("preset", plugins.names())
def test_empty_mask_gives_the_plain_warp(textured_bgr, formulation, preset):
    """An all-False mask gives exactly the plain warp: same nodes, same image, no factorization."""
    w = load_warp(preset)(160, 120)
    warper = FeatureWarper(160, 120, np.zeros((120, 160), bool), formulation=formulation)
    mesh = warper.solve(w, "similarity")
    np.testing.assert_array_equal(mesh.target, w(mesh.source))
    plain = FeatureWarper(160, 120, None)
    expected = plain.render(textured_bgr, plain.solve(w, "plain"))
    out = warper.render(textured_bgr, mesh)
    assert out.dtype == expected.dtype and out.shape == expected.shape
    np.testing.assert_array_equal(out, expected)
    assert warper.factorizations == 0


@pytest.mark.parametrize("preset, params", [("stretch", {"sx": 1.3}), ("swirl", {})])
def test_api_warp_with_empty_mask_equals_plain_mode(textured_bgr, blob_mask, preset, params):
    """api.warp: empty mask == no mask == plain mode with a real mask, byte for byte; a mask that
    marks nothing is said (an int64 0/255 mask marked nothing, silently: it marks its 255s now)."""
    from featurewarp_cli import FeatureWarpWarning

    with pytest.warns(FeatureWarpWarning, match="the mask marks no feature"):
        empty = warp(textured_bgr, np.zeros((120, 160), bool), preset, **params)
    assert FeatureWarper(160, 120, blob_mask.astype(np.int64) * 255).mask.sum() == blob_mask.sum()
    np.testing.assert_array_equal(empty, warp(textured_bgr, None, preset, **params))
    np.testing.assert_array_equal(empty, warp(textured_bgr, blob_mask, preset, mode="plain", **params))


def on_border(source, width, height):
    """(N,) bool: the source node lies on the image's pixel-extent border."""
    x, y = source[:, 0], source[:, 1]
    return (x == -0.5) | (x == width - 0.5) | (y == -0.5) | (y == height - 0.5)


# --- invariant (c): boundary nodes land exactly on W(boundary) -----------------------------

def sides(source, width, height):
    """Node indices of the top, right, bottom and left sides, each ordered along the side."""
    x, y = source[:, 0], source[:, 1]
    top = np.flatnonzero(y == -0.5)
    bottom = np.flatnonzero(y == height - 0.5)
    left = np.flatnonzero(x == -0.5)
    right = np.flatnonzero(x == width - 0.5)
    return {"top": top[np.argsort(x[top])], "bottom": bottom[np.argsort(x[bottom])],
            "left": left[np.argsort(y[left])], "right": right[np.argsort(y[right])]}


@pytest.mark.parametrize("formulation", FORMULATIONS)
@pytest.mark.parametrize("mode", ["similarity", "rigid"])
@pytest.mark.parametrize("preset,params", PRESET_CASES)
@pytest.mark.parametrize("mask_name", ["blob_mask", "border_mask"])
def test_boundary_nodes_are_fixed_to_the_warp(request, formulation, mode, preset, params, mask_name):
    """With the paper's fixed border, border nodes equal W at those nodes bit for bit, for every preset."""
    mask = request.getfixturevalue(mask_name)
    w = load_warp(preset)(160, 120, **params)
    warper = FeatureWarper(160, 120, mask, formulation=formulation, boundary="fixed")
    mesh = warper.solve(w, mode)
    boundary = on_border(mesh.source, 160, 120)
    assert np.count_nonzero(boundary) >= 2 * (160 + 120) / 8
    np.testing.assert_array_equal(mesh.target[boundary], w(mesh.source[boundary]))
    # ... while the interior really moved away from W (features were honoured), unless
    # features held by pins no similarity satisfies came out worse than W and were moved
    # back towards it (never worse than plain).
    if mesh.info["plain_blend"] == 1.0:
        assert np.abs(mesh.target[~boundary] - w(mesh.source[~boundary])).max() > 0.5
    else:
        assert all(c["anisotropy_worst"] <= c["plain_anisotropy_worst"] + 1e-6 for c in mesh.info["components"])


@pytest.mark.parametrize("formulation", FORMULATIONS)
@pytest.mark.parametrize("preset,params", PRESET_CASES)
@pytest.mark.parametrize("mask_name", ["blob_mask", "border_mask"])
def test_default_boundary_stays_on_the_warped_border(request, formulation, preset, params, mask_name):
    """With default options border nodes stay on W(border): corners exact, each side on its image, in order,
    except the nodes of features cut by a border whose pins no similarity satisfies (let go of them to
    keep their shape, and reported as unpinned)."""
    mask = request.getfixturevalue(mask_name)
    w = load_warp(preset)(160, 120, **params)
    warper = FeatureWarper(160, 120, mask, formulation=formulation)
    mesh = warper.solve(w)
    target, expected = mesh.target, w(mesh.source)
    unpinned = [k for k, c in enumerate(mesh.info["components"]) if c["unpinned"]]
    if unpinned:
        assert formulation == "exact" and preset in ("arc", "swirl", "bulge")
        let_go = np.isin(mesh.node_component, unpinned)
        expected = np.where(let_go[:, None], target, expected)
    for name, idx in sides(mesh.source, 160, 120).items():
        np.testing.assert_array_equal(target[idx[[0, -1]]], expected[idx[[0, -1]]])   # corners
        exact = np.all(target[idx] == expected[idx])
        if not exact:
            # A side may only slide along itself, where W maps it onto an axis-parallel line.
            across = 1 if name in ("top", "bottom") else 0
            assert np.ptp(expected[idx, across]) == 0, f"{name} side moved off a curved W(border)"
            np.testing.assert_array_equal(target[idx, across], expected[idx, across])
            along = target[idx, 1 - across]
            assert (np.diff(along) > 0).all(), f"{name} side nodes overtake each other"


# --- factorization reuse --------------------------------------------------------------------

def solve_all(warper, solves, width, height, mode="similarity"):
    """Solve each (preset, params); return the meshes and the factorization count after each."""
    meshes, counts = [], []
    for preset, params in solves:
        meshes.append(warper.solve(load_warp(preset)(width, height, **params), mode))
        counts.append(warper.factorizations)
    return meshes, counts


@pytest.mark.parametrize("formulation", FORMULATIONS)
def test_factorization_is_reused_for_gentle_warps(small_scene, formulation):
    """Gentle swirls, bulges and arcs of one image and mask share one factorization."""
    _, mask = small_scene
    h, w = mask.shape
    warper = FeatureWarper(w, h, mask, formulation=formulation)
    assert warper.factorizations == 0
    solves = [("swirl", {"angle": 60}), ("swirl", {"angle": 90}), ("bulge", {"strength": 0.7}),
              ("bulge", {"strength": -0.4}), ("swirl", {"angle": 60})]
    meshes, counts = solve_all(warper, solves, w, h)
    assert counts == [1] * len(solves)
    assert solve_all(warper, [("arc", {"angle": 60}), ("arc", {"angle": 100})], w, h)[1] == [1, 1]
    assert all(m.info["solver"] == "cholmod" for m in meshes)
    assert solve_all(warper, [("swirl", {"angle": 45})], w, h, "rigid")[1] == [1]
    # Reusing the factorization gives the same answer as a fresh one.
    fresh = FeatureWarper(w, h, mask, formulation=formulation).solve(load_warp("swirl")(w, h, angle=90))
    np.testing.assert_allclose(meshes[1].target, fresh.target, atol=1e-9)
    np.testing.assert_array_equal(meshes[0].target, meshes[-1].target)
    # Different warps give different meshes (the solves were not all the same).
    assert np.abs(meshes[0].target - meshes[1].target).max() > 1.0


@pytest.mark.parametrize("formulation", FORMULATIONS)
def test_factorization_is_reused_by_stretch(small_scene, formulation):
    """Stretches of any factor share one sliding-border factorization (one for x, one for y)."""
    _, mask = small_scene
    h, w = mask.shape
    warper = FeatureWarper(w, h, mask, formulation=formulation)
    solves = [("stretch", {"sy": 2}), ("stretch", {"sx": 2, "sy": 2}), ("stretch", {"sx": 0.7})]
    assert solve_all(warper, solves, w, h)[1] == [2, 2, 2]


def test_the_record_says_the_border_conditions_used(small_scene):
    """The report's ``boundary`` said "slide" for a swirl, whose border nothing can slide along
    (W leaves it in place): it is "fixed" there, "slide" where a side slides."""
    _, mask = small_scene
    h, w = mask.shape
    warper = FeatureWarper(w, h, mask)
    assert warper.solve(load_warp("swirl")(w, h, angle=90)).record.boundary == "fixed"
    assert warper.solve(load_warp("stretch")(w, h, sx=2)).record.boundary == "slide"
    assert FeatureWarper(w, h, mask, boundary="fixed").solve(load_warp("stretch")(w, h, sx=2)).record.boundary == "fixed"


@pytest.mark.parametrize("formulation", FORMULATIONS)
def test_factorization_is_reused_across_presets_and_parameters(small_scene, formulation):
    """With one grid and one border rule, every preset and parameter shares one factorization.

    (The automatic cell refines for strong warps and arc's sides cannot slide, so a
    caller who needs the guarantee across all of them fixes ``cell`` and ``boundary``.)
    """
    _, mask = small_scene
    h, w = mask.shape
    warper = FeatureWarper(w, h, mask, formulation=formulation, cell=4, boundary="fixed")
    solves = [("swirl", {"angle": 90}), ("swirl", {"angle": 180}), ("stretch", {"sy": 2}),
              ("stretch", {"sx": 0.5, "sy": 1.5}), ("bulge", {"strength": 0.7}), ("arc", {"angle": 90}),
              ("swirl", {"angle": 90})]
    assert solve_all(warper, solves, w, h)[1] == [1] * len(solves)


def test_plain_mode_never_factors(small_scene):
    """Plain mode (mask ignored) solves nothing: no factorization, solver 'none'."""
    _, mask = small_scene
    h, w = mask.shape
    warper = FeatureWarper(w, h, mask)
    for preset in plugins.names():
        mesh = warper.solve(load_warp(preset)(w, h), "plain")
        assert mesh.info["solver"] == "none"
        np.testing.assert_array_equal(mesh.target, load_warp(preset)(w, h)(mesh.source))
    assert warper.factorizations == 0


# --- argument checks ------------------------------------------------------------------------

def test_warper_rejects_mismatched_sizes_and_bad_options(blob_mask):
    """Mask/warp/image of another size and unknown mode/formulation are ValueErrors naming the problem."""
    with pytest.raises(ValueError, match="mask is 160x120"):
        FeatureWarper(100, 120, blob_mask)
    warper = FeatureWarper(160, 120, blob_mask)
    with pytest.raises(ValueError, match="warp is for 100x120"):
        warper.solve(load_warp("swirl")(100, 120))
    with pytest.raises(ValueError, match="mode"):
        warper.solve(load_warp("swirl")(160, 120), "conformal")
    with pytest.raises(ValueError, match="formulation"):
        FeatureWarper(160, 120, blob_mask, formulation="fancy")
    for bad in (0, -1, float("nan"), float("inf")):
        with pytest.raises(ValueError, match="feature_weight"):
            FeatureWarper(160, 120, blob_mask, feature_weight=bad)
        with pytest.raises(ValueError, match="decay"):
            FeatureWarper(160, 120, blob_mask, decay=bad)
    with pytest.raises(ValueError, match="cell"):
        FeatureWarper(160, 120, blob_mask, cell=0.5)
    mesh = warper.solve(load_warp("swirl")(160, 120))
    with pytest.raises(ValueError, match="image is 100x120"):
        warper.render(np.zeros((120, 100, 3), np.uint8), mesh)


# --- fold-overs -------------------------------------------------------------------------------

def flipped(mesh):
    return int(np.count_nonzero(signed_areas(mesh.target, mesh.triangles) <= 0))


@pytest.mark.parametrize("formulation", FORMULATIONS)
@pytest.mark.parametrize("mode", ["similarity", "rigid"])
@pytest.mark.parametrize("preset,params", [
    ("stretch", {"sy": 2}), ("stretch", {"sx": 1.7, "sy": 0.6}), ("bulge", {"strength": 0.5}),
    ("bulge", {"strength": 1.5}), ("arc", {"angle": 270}), ("swirl", {"angle": 60}),
])
def test_no_fold_overs_for_moderate_warps(small_scene, formulation, mode, preset, params):
    """Moderate warps of the small scene give a mesh with no triangle of area <= 0."""
    _, mask = small_scene
    h, w = mask.shape
    mesh = FeatureWarper(w, h, mask, formulation=formulation).solve(load_warp(preset)(w, h, **params), mode)
    assert flipped(mesh) == mesh.flips() == mesh.info["flipped_triangles"] == 0


@pytest.mark.parametrize("formulation,mode,preset,params", [
    ("exact", "similarity", "swirl", {"angle": 180}),
    ("paper", "similarity", "swirl", {"angle": 180}),
    ("exact", "similarity", "stretch", {"sx": 0.6, "sy": 1.7}),
    ("exact", "similarity", "stretch", {"sx": 1.7, "sy": 0.6}),
    ("exact", "similarity", "arc", {"angle": 360}),
])
def test_no_fold_overs_where_least_squares_alone_folds(small_scene, formulation, mode, preset, params):
    """Warps whose plain least-squares solution folds (109, 106, 61, 4, 48 triangles) come out fold-free."""
    _, mask = small_scene
    h, w = mask.shape
    mesh = FeatureWarper(w, h, mask, formulation=formulation).solve(load_warp(preset)(w, h, **params), mode)
    assert flipped(mesh) == mesh.flips() == 0


def test_no_fold_overs_in_the_acceptance_swirl():
    """The acceptance case swirl 120 with default options (16 folds by least squares alone) does not fold."""
    from samples.scenes import scene

    _, mask = scene()
    h, w = mask.shape
    mesh = FeatureWarper(w, h, mask).solve(load_warp("swirl")(w, h, angle=120))
    assert flipped(mesh) == 0


@pytest.mark.parametrize("angle", [540, -540])
def test_plain_swirl_mesh_does_not_fold(angle):
    """The plain swirl is injective for every angle, so its mesh has no flipped triangle."""
    mesh = FeatureWarper(500, 360, None).solve(load_warp("swirl")(500, 360, angle=angle), "plain")
    assert flipped(mesh) == 0


@pytest.mark.parametrize("top, cut", [(2, False), (0, True)])
def test_a_mask_that_stops_short_of_the_frame_is_inside_it(top, cut):
    """A lasso that ends 2 px under the top edge (inside the first row of 4 px cells) is read as
    ending a cell short: under an arc, which curves the top edge, the feature stays one
    similarity and is kept. One that reaches the edge is cut by it and gives way."""
    mask = np.zeros((96, 128), bool)
    mask[top:40, 70:100] = True
    mesh = FeatureWarper(128, 96, mask, cell=4).solve(load_warp("arc")(128, 96, angle=120), "similarity")
    component, = mesh.record.components
    assert component.tied is not cut and component.kept is not cut
    assert mesh.record.outline_departure <= 1.0


def test_a_speck_in_the_outer_cells_is_kept_whole():
    """A feature lying wholly in the frame's outer cells keeps them (it would vanish)."""
    from featurewarp_cli.engine import features
    from featurewarp_cli.engine.grid import grid_for

    mask = np.zeros((96, 128), bool)
    mask[1:3, 60:66] = True
    grid = grid_for(128, 96, 4.0)
    pooled = features._pooled(mask, grid)
    same, again, _ = features.short_of_frame(mask, grid, pooled)
    assert same is mask and again is pooled and features.analyse(mask, grid).n_components == 1


@pytest.mark.parametrize("seed", range(4))
def test_the_distance_to_features_is_the_exact_transform_within_reach(seed):
    """features.feature_distance: bit for bit the exact Euclidean distance transform (OpenCV's,
    its squares rounded to the whole numbers they are) wherever it is within reach, and
    beyond reach elsewhere; on both of its paths (bounded pass, whole transform), with
    sub-pixel cells repeating rows and columns."""
    import cv2

    from featurewarp_cli.engine.features import feature_distance

    rng = np.random.default_rng(seed)
    paths = set()
    for _ in range(60):
        h, w = (int(v) for v in rng.integers(1, 120, 2))
        mask = np.zeros((h, w), np.uint8)
        for _ in range(int(rng.integers(1, 5))):
            cv2.circle(mask, (int(rng.integers(0, w)), int(rng.integers(0, h))), int(rng.integers(0, 15)), 1, -1)
        mask = (mask > 0) | (rng.random((h, w)) < 0.005)
        if not mask.any():
            continue
        spacing, rho = rng.uniform(0.3, 9.0), float(rng.choice([0.5, 2.0, 40.0]))
        rows = np.clip(np.round((np.arange(math.ceil(h / spacing)) + 0.5) * spacing - 0.5).astype(int), 0, h - 1)
        cols = np.clip(np.round((np.arange(math.ceil(w / spacing)) + 0.5) * spacing - 0.5).astype(int), 0, w - 1)
        reach = math.ceil(rho * spacing)
        paths.add((2 * min(reach, h + w) + 1) * rows.size * cols.size > mask.size)
        exact = cv2.distanceTransform((~mask).view(np.uint8), cv2.DIST_L2, cv2.DIST_MASK_PRECISE)
        exact = exact[np.ix_(rows, cols)].astype(np.float64)
        exact = np.sqrt(np.rint(exact * exact)).astype(np.float32)
        found = feature_distance(mask, rows, cols, reach)
        within = exact <= reach
        assert found.dtype == np.float32 and np.array_equal(found[within], exact[within])
        assert np.all(found[~within] > reach)
    assert paths == {False, True}


def test_a_lasso_joined_only_in_the_outer_cells_stays_one_feature():
    """An arch whose legs meet 2 px under the top edge would fall apart without its outer cells:
    it keeps them (one feature, as the mask draws it)."""
    from featurewarp_cli.engine import features
    from featurewarp_cli.engine.grid import grid_for

    mask = np.zeros((60, 80), bool)
    mask[2:4, 10:60] = True
    mask[2:40, 10:16] = True
    mask[2:40, 54:60] = True
    assert features.analyse(mask, grid_for(80, 60, 4.0)).n_components == 1


def test_rigid_mode_keeps_a_feature_cut_by_a_border_the_warp_leaves_in_place():
    """A swirl keeps its border where it is: a feature cut by it can stay put as one rigid map
    (the identity), which rigid mode now takes instead of the warp's rotation there (which no
    pin allowed, so the feature gave way, 0.18 worst-triangle anisotropy, with a warning)."""
    h, w = 120, 160
    y, x = np.mgrid[0:h, 0:w]
    mask = (x - 110) ** 2 + (y - 119) ** 2 < 22 ** 2             # a half disc on the bottom edge
    for mode in ("rigid", "similarity"):
        mesh = FeatureWarper(w, h, mask).solve(load_warp("swirl")(w, h, angle=120), mode)
        feature = mesh.record.components[0]
        assert feature.tied and feature.kept and feature.anisotropy_worst < 1e-9, mode
        assert abs(feature.rotation_deg) < 1e-6 and abs(feature.scale - 1.0) < 1e-9
        assert mesh.record.warnings == [] and mesh.flips() == 0


def test_a_warper_keeps_its_own_copy_of_the_mask():
    """The mask's analysis is kept per grid: a caller that reuses its mask buffer after making a
    warper (painting, np.copyto) must not leave the warper seeing features for one preset and
    none for another (API trial 1)."""
    from featurewarp_cli.engine.warper import FeatureWarper, load_warp

    mask = np.zeros((60, 80), bool)
    mask[20:40, 30:50] = True
    warper = FeatureWarper(80, 60, mask)
    first = warper.solve(load_warp("swirl")(80, 60, angle=90))
    mask[:] = False
    again = warper.solve(load_warp("stretch")(80, 60, sx=2))
    assert warper.mask is not mask and warper.mask.any()
    assert len(first.record.components) == len(again.record.components) == 1

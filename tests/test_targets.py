"""Per-quad linear algebra of paper section 2: Jacobians, closest rotations, scales."""

from __future__ import annotations

import math

import numpy as np
import pytest

from featurewarp_cli.engine import targets
from featurewarp_cli.engine.features import Features
from featurewarp_cli.engine.grid import Grid


def rotation(deg):
    a = math.radians(deg)
    return np.array([[math.cos(a), -math.sin(a)], [math.sin(a), math.cos(a)]])


def svd_rotation(t):
    """Reference closest rotation: U V^T with U's last column negated when det < 0."""
    u, _, vt = np.linalg.svd(t)
    flip = np.linalg.det(u @ vt) < 0
    u[flip, :, -1] *= -1
    return u @ vt


def one_component(matrices, extra=()):
    """Jacobians of K feature quads of one component, plus transition quads ``extra``."""
    t = np.concatenate([np.asarray(matrices, float), np.asarray(extra, float).reshape(-1, 2, 2)])
    k, e = len(matrices), len(t) - len(matrices)
    features = Features(np.r_[np.ones(k, bool), np.zeros(e, bool)], np.zeros(k + e, np.int64),
                        np.ones(k + e), 1)
    return t, features


def random_matrices(rng, n, det_sign):
    """n random 2x2 matrices with det of the given sign and clearly distinct singular values."""
    t = rng.normal(size=(4 * n, 2, 2))
    s = np.linalg.svd(t, compute_uv=False)
    ok = (np.sign(np.linalg.det(t)) == det_sign) & (s[:, 0] - s[:, 1] > 0.05)
    return t[ok][:n]


@pytest.mark.parametrize("det_sign", [1, -1])
def test_closest_rotations_equals_svd_reference(rng, det_sign):
    """closest_rotations is U V^T (sign-fixed for reflections) of numpy's SVD."""
    t = random_matrices(rng, 500, det_sign)
    assert len(t) == 500
    r = targets.closest_rotations(t)
    np.testing.assert_allclose(r, svd_rotation(t), atol=1e-10)
    # and it is a proper rotation
    np.testing.assert_allclose(np.linalg.det(r), 1.0, atol=1e-12)
    np.testing.assert_allclose(r @ np.swapaxes(r, 1, 2), np.broadcast_to(np.eye(2), r.shape), atol=1e-12)


def test_closest_rotations_is_not_the_papers_transpose():
    """The result is U V^T, not the paper's misprinted V U^T (its inverse)."""
    t = rotation(40)[None] @ np.diag([2.0, 0.5])[None]
    r = targets.closest_rotations(t)
    np.testing.assert_allclose(r[0], rotation(40), atol=1e-12)
    assert np.abs(r[0] - rotation(-40)).max() > 0.5


@pytest.mark.parametrize("deg", [0.0, 1e-7, 17.0, 90.0, -135.0, 179.999, 180.0, 270.0])
def test_closest_rotations_returns_a_rotation_itself(deg):
    """For a pure rotation W the closest rotation is W itself (DESIGN: R must equal W)."""
    w = rotation(deg)[None]
    np.testing.assert_allclose(targets.closest_rotations(w), w, rtol=0, atol=4e-16)


@pytest.mark.parametrize("scale", [0.2, 1.0, 3.5])
def test_closest_rotations_of_a_similarity_is_its_rotation(scale):
    """The closest rotation of s R is R for any positive scale s."""
    r = np.stack([rotation(d) for d in (-100, -5, 33, 160)])
    np.testing.assert_allclose(targets.closest_rotations(scale * r), r, atol=1e-14)


def test_singular_values_match_numpy(rng):
    """singular_values gives numpy's singular values, largest first, for any 2x2 matrix."""
    t = np.concatenate([rng.normal(size=(1000, 2, 2)), np.zeros((1, 2, 2)),
                        np.diag([3.0, -3.0])[None], np.array([[[1.0, 2.0], [2.0, 4.0]]])])
    np.testing.assert_allclose(targets.singular_values(t), np.linalg.svd(t, compute_uv=False),
                               rtol=1e-12, atol=1e-12)


@pytest.mark.parametrize("size,cell", [((50, 37), 4), ((160, 120), 7), ((33, 90), 5)])
def test_quad_jacobians_of_an_affine_warp_are_its_matrix(rng, size, cell):
    """Eq. (1) recovers the linear part of an affine warp exactly on every quad."""
    grid = Grid.for_image(*size, cell)
    a = rng.normal(size=(2, 2))
    b = rng.normal(size=2) * 50
    jac = targets.quad_jacobians(grid, grid.nodes() @ a.T + b)
    assert jac.shape == (grid.quad_shape[0] * grid.quad_shape[1], 2, 2)
    np.testing.assert_allclose(jac, np.broadcast_to(a, jac.shape), atol=1e-12)


def test_quad_jacobians_follow_a_nonlinear_warp_locally():
    """On a quadratic warp each quad's T is the warp's derivative at the quad centre."""
    grid = Grid.for_image(120, 90, 4)
    nodes = grid.nodes()
    warped = np.stack([nodes[:, 0] + 0.002 * nodes[:, 1] ** 2, nodes[:, 1] + 0.003 * nodes[:, 0] ** 2], 1)
    jac = targets.quad_jacobians(grid, warped)
    centres = nodes[grid.quads()].mean(axis=1)
    expected = np.zeros_like(jac)
    expected[:, 0, 0] = expected[:, 1, 1] = 1.0
    expected[:, 0, 1] = 0.004 * centres[:, 1]
    expected[:, 1, 0] = 0.006 * centres[:, 0]
    np.testing.assert_allclose(jac, expected, atol=1e-12)


@pytest.mark.parametrize("matrix,expected", [
    (np.diag([1.0, 2.0]), 1.0),                                   # one-axis stretch sy = 2
    (np.diag([2.0, 1.0]), 1.0),                                   # sx = 2
    (np.diag([0.5, 1.0]), math.sqrt(0.5)),                        # sx = 0.5: area follows
    (np.diag([1.0, 0.25]), 0.5),                                  # sy = 0.25
    (1.7 * np.eye(2), 1.7),                                       # uniform scale s
    (0.4 * np.eye(2), 0.4),
    (2.5 * rotation(70), 2.5),                                    # similarity
    (rotation(35) @ np.array([[1.0, 0.8], [0.0, 1.0]]), 1.0),     # rotation + shear, det 1
])
def test_intuitive_scales(matrix, expected):
    """The exact formulation's lambda: 1 for stretches, s for uniform scale, sqrt(det) when shrinking."""
    t, features = one_component([matrix] * 5)
    np.testing.assert_allclose(targets.intuitive_scales(t, features), [expected], rtol=1e-12)


def test_intuitive_scales_average_feature_quads_only():
    """lambda averages sqrt(det) over a component's feature quads; transition quads do not count."""
    t, features = one_component([0.5 * np.eye(2), 0.7 * np.eye(2)], extra=[10 * np.eye(2)] * 3)
    np.testing.assert_allclose(targets.intuitive_scales(t, features), [0.6], rtol=1e-12)


def test_paper_scales_are_mean_smaller_singular_value(rng):
    """The paper's lambda per component is the mean sigma_min over its feature quads."""
    t = rng.normal(size=(12, 2, 2))
    component = np.array([0, 0, 1, 1, 1, 0, 2, 2, 0, 1, -1, 2])
    is_feature = np.array([1, 1, 1, 0, 1, 1, 1, 1, 0, 1, 0, 1], bool)
    features = Features(is_feature, component, np.ones(12), 3)
    smin = np.linalg.svd(t, compute_uv=False)[:, 1]
    expected = [smin[(component == c) & is_feature].mean() for c in range(3)]
    np.testing.assert_allclose(targets.paper_scales(t, features), expected, rtol=1e-12)


def test_paper_scales_shrink_a_swirl_where_intuitive_keeps_area():
    """For a rotation + shear with det 1, paper lambda = sigma_min < 1, intuitive lambda = 1."""
    m = rotation(10) @ np.array([[1.0, 1.2], [0.0, 1.0]])
    t, features = one_component([m] * 3)
    paper = targets.paper_scales(t, features)[0]
    assert paper == pytest.approx(np.linalg.svd(m, compute_uv=False)[1], rel=1e-12)
    assert paper < 0.6
    assert targets.intuitive_scales(t, features)[0] == pytest.approx(1.0, rel=1e-12)


@pytest.mark.parametrize("formulation", ["exact", "paper"])
@pytest.mark.parametrize("mode", ["similarity", "rigid"])
def test_quad_targets_of_a_similarity_are_the_similarity(formulation, mode):
    """With T = s R everywhere, every constrained quad's target is s R (rigid: R)."""
    m = 1.3 * rotation(30)
    t, features = one_component([m] * 4, extra=[m] * 2)
    quad_maps, component_maps = targets.quad_targets(t, features, mode, formulation)
    expected = m if mode == "similarity" else rotation(30)
    np.testing.assert_allclose(quad_maps, np.broadcast_to(expected, quad_maps.shape), atol=1e-12)
    np.testing.assert_allclose(component_maps, [expected], atol=1e-12)

"""Local linear part of the warp per quad, and the shape-preserving targets (paper 2)."""

from __future__ import annotations

import numpy as np

from .features import Features
from .grid import Grid


def quad_jacobians(grid: Grid, warped: np.ndarray) -> np.ndarray:
    """Least-squares linear map of each quad's centred corners onto W's (Eq. 1).

    Parameters
    ----------
    grid : Grid
    warped : (N, 2) ndarray
        W at the grid nodes.

    Returns
    -------
    (K, 2, 2) ndarray
        T per quad, so that T @ (v - centroid) ~ W(v) - mean(W(corners)).
    """
    sx, sy = grid.spacing
    nodes = warped.reshape(grid.ny, grid.nx, 2)
    tl, tr, br, bl = nodes[:-1, :-1], nodes[:-1, 1:], nodes[1:, 1:], nodes[1:, :-1]
    # Source corners centred on the quad, the same for every quad of a regular grid:
    # u = (-hx, -hy), (hx, -hy), (hx, hy), (-hx, hy) for tl, tr, br, bl.
    # T = U' U^T (U U^T)^-1 with U U^T = diag(sx^2, sy^2); centring U' is not needed as sum(u) = 0.
    # Summed corner by corner on slices: the numbers of einsum("kcd,ce->kde") on the
    # gathered (K, 4, 2) corners, a dozen times faster.
    hx, hy = sx / 2.0, sy / 2.0
    t = np.empty(tl.shape[:2] + (2, 2))
    t[..., 0] = (((tl * -hx + tr * hx) + br * hx) + bl * -hx) / (sx * sx)
    t[..., 1] = (((tl * -hy + tr * -hy) + br * hy) + bl * hy) / (sy * sy)
    return t.reshape(-1, 2, 2)


def closest_rotations(t: np.ndarray) -> np.ndarray:
    """Closest proper rotation to each 2x2 matrix in the Frobenius norm.

    This is U V^T from the SVD T = U S V^T with the last column of U negated
    when det(T) < 0 (the paper's Eq. 2 prints V U^T, which is the inverse).
    In 2-D it has the closed form angle = atan2(T10 - T01, T00 + T11).

    Parameters
    ----------
    t : (K, 2, 2) ndarray

    Returns
    -------
    (K, 2, 2) ndarray
    """
    angle = np.arctan2(t[:, 1, 0] - t[:, 0, 1], t[:, 0, 0] + t[:, 1, 1])
    c, s = np.cos(angle), np.sin(angle)
    return np.stack([np.stack([c, -s], -1), np.stack([s, c], -1)], -2)


def singular_values(t: np.ndarray) -> np.ndarray:
    """Singular values (largest first) of each 2x2 matrix, in closed form: (K, 2)."""
    p = np.hypot(t[:, 0, 0] + t[:, 1, 1], t[:, 1, 0] - t[:, 0, 1])
    q = np.hypot(t[:, 0, 0] - t[:, 1, 1], t[:, 1, 0] + t[:, 0, 1])
    return np.stack([(p + q) / 2.0, np.abs(p - q) / 2.0], axis=1)


def component_mean(values: np.ndarray, features: Features) -> np.ndarray:
    """Mean of per-quad ``values`` over each component's feature quads.

    Parameters
    ----------
    values : (K, ...) ndarray
    features : Features

    Returns
    -------
    (n_components, ...) ndarray
    """
    own = features.is_feature
    labels = features.component[own]
    flat = values[own].reshape(labels.size, -1)
    counts = np.bincount(labels, minlength=features.n_components)
    sums = np.stack([np.bincount(labels, weights=flat[:, k], minlength=features.n_components)
                     for k in range(flat.shape[1])], axis=1)
    return (sums / np.maximum(counts, 1)[:, None]).reshape((features.n_components,) + values.shape[1:])


def paper_scales(t: np.ndarray, features: Features) -> np.ndarray:
    """The paper's scale per component: mean smaller singular value of its quads' T."""
    return component_mean(singular_values(t)[:, 1], features)


def intuitive_scales(t: np.ndarray, features: Features) -> np.ndarray:
    """Scale per component that matches intuition for every kind of warp.

    lambda = max(mean sigma_min, min(mean sqrt(det T), 1)): where the warp shrinks
    area, the feature's area follows it (sqrt det); where it enlarges, the
    feature grows only by the smaller principal scale, so a one-axis stretch
    leaves it at its size (the paper's intent) and a uniform scale s gives s;
    an area-preserving warp (swirl) keeps the feature's area, where the paper's
    mean sigma_min shrinks it.
    """
    sigma = singular_values(t)
    root_det = np.sqrt(np.clip(sigma[:, 0] * sigma[:, 1], 0.0, None))
    means = component_mean(np.stack([sigma[:, 1], root_det], axis=1), features)
    return np.maximum(means[:, 0], np.minimum(means[:, 1], 1.0))


def component_rotations(t: np.ndarray, features: Features) -> np.ndarray:
    """Best-fit rotation of the warp over each component: closest rotation to mean T."""
    return closest_rotations(component_mean(t, features))


def quad_targets(t: np.ndarray, features: Features, mode: str,
                 formulation: str = "exact") -> tuple[np.ndarray, np.ndarray]:
    """Target linear map per constrained quad, and the scale per component.

    Parameters
    ----------
    t : (K, 2, 2) ndarray
        Quad Jacobians of the warp.
    features : Features
    mode : {'rigid', 'similarity'}
    formulation : {'exact', 'paper'}
        paper: each quad's own rotation R_Q times the paper's lambda.
        exact: one similarity per component (its best-fit rotation times the
        intuitive scale), shared by its feature and transition quads.

    Returns
    -------
    quad_maps : (K, 2, 2) ndarray
        Meaningful where ``features.is_constrained``.
    component_maps : (n_components, 2, 2) ndarray
        The component's own similarity (for 'paper', lambda times its best-fit rotation).
    """
    n = features.n_components
    if mode == "rigid":
        scales = np.ones(n)
    elif formulation == "paper":
        scales = paper_scales(t, features)
    else:
        scales = intuitive_scales(t, features)
    component_maps = component_rotations(t, features) * scales[:, None, None]
    index = np.maximum(features.component, 0)
    if formulation == "paper":
        quad_maps = closest_rotations(t) * scales[index][:, None, None]
    else:
        quad_maps = component_maps[index]
    return quad_maps, component_maps

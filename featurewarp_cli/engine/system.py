"""The least-squares system of Eqs. (3)-(5): normal matrix and right-hand side.

Each quad contributes four edge equations ``w (v_b - v_a) = w t`` (edges taken
cyclically: top, right, bottom, left). The normal matrix A^T A is then a
weighted 5-point graph Laplacian whose edge weights are the sums of w^2 over
the (one or two) quads sharing the edge; it depends on the grid and the
weights only, never on the warp. It is a ``scipy.sparse`` matrix; its
factorization is :mod:`featurewarp_cli.engine.solver`'s.
"""

from __future__ import annotations

import numpy as np

from .grid import Grid


def normal_matrix(grid: Grid, weights: np.ndarray):
    """A^T A for quad weights ``weights`` ((K,) ndarray): an (N, N) scipy.sparse CSR matrix.

    Every grid edge is stored, whatever its weight, so the pattern is the
    grid's 5-point stencil (node ``j * nx + i`` coupled to its upper, left,
    right and lower neighbours), with each row's entries in column order.
    (SciPy is imported here, not with the module: a warp that factors
    nothing does not need it.)
    """
    import scipy.sparse as sp

    qy, qx = grid.quad_shape
    nx, ny = grid.nx, grid.ny
    w2 = (weights * weights).reshape(qy, qx)
    horizontal = np.zeros((ny, qx))               # edge (j, i) -- (j, i+1)
    horizontal[:-1] += w2
    horizontal[1:] += w2
    vertical = np.zeros((qy, nx))                 # edge (j, i) -- (j+1, i)
    vertical[:, :-1] += w2
    vertical[:, 1:] += w2
    diagonal = np.zeros((ny, nx))
    diagonal[:, :-1] += horizontal
    diagonal[:, 1:] += horizontal
    diagonal[:-1, :] += vertical
    diagonal[1:, :] += vertical

    # Each row's five entries in column order: upper, left, itself, right, lower neighbour.
    values = np.zeros((ny, nx, 5))
    exists = np.zeros((ny, nx, 5), bool)
    for k, (rows, cols, value) in enumerate(((slice(1, None), slice(None), -vertical),
                                             (slice(None), slice(1, None), -horizontal),
                                             (slice(None), slice(None), diagonal),
                                             (slice(None), slice(0, -1), -horizontal),
                                             (slice(0, -1), slice(None), -vertical))):
        values[rows, cols, k] = value
        exists[rows, cols, k] = True
    columns = np.arange(nx * ny).reshape(ny, nx, 1) + np.array([-nx, -1, 0, 1, nx])
    indptr = np.concatenate([[0], np.cumsum(exists.sum(axis=2).ravel())])
    return sp.csr_matrix((values[exists], columns[exists], indptr), shape=(nx * ny, nx * ny))


def node_stiffness(grid: Grid, weights: np.ndarray) -> np.ndarray:
    """Diagonal of the normal matrix: the summed squared weight of each node's edges, (N,)."""
    qy, qx = grid.quad_shape
    w2 = (weights * weights).reshape(qy, qx)
    diagonal = np.zeros((grid.ny, grid.nx))
    for rows, cols in ((slice(0, -1), slice(0, -1)), (slice(0, -1), slice(1, None)),
                       (slice(1, None), slice(0, -1)), (slice(1, None), slice(1, None))):
        diagonal[rows, cols] += 2.0 * w2          # each corner has two edges in the quad
    return diagonal.ravel()


def edge_vectors(grid: Grid, quad_maps: np.ndarray) -> np.ndarray:
    """Target vectors t of the four edges of each quad under per-quad linear maps.

    Parameters
    ----------
    grid : Grid
    quad_maps : (K, 2, 2) ndarray
        Linear map M_Q applied to each source edge (Eq. 3).

    Returns
    -------
    (K, 4, 2) ndarray
        Edges top, right, bottom, left.
    """
    sx, sy = grid.spacing
    col_x, col_y = quad_maps[:, :, 0], quad_maps[:, :, 1]
    return np.stack([sx * col_x, sy * col_y, -sx * col_x, -sy * col_y], axis=1)


def warp_edge_vectors(grid: Grid, warped: np.ndarray) -> np.ndarray:
    """Edge vectors of each quad under the warp itself (Eq. 4): (K, 4, 2), top, right, bottom, left
    (from corner k to corner k + 1 of tl, tr, br, bl)."""
    nodes = warped.reshape(grid.ny, grid.nx, 2)
    tl, tr, br, bl = nodes[:-1, :-1], nodes[:-1, 1:], nodes[1:, 1:], nodes[1:, :-1]
    return np.stack([tr - tl, br - tr, bl - br, tl - bl], axis=2).reshape(-1, 4, 2)


def right_hand_side(grid: Grid, weights: np.ndarray, edges: np.ndarray) -> np.ndarray:
    """A^T b for edge targets ``edges`` ((K, 4, 2) ndarray); returns (N, 2)."""
    qy, qx = grid.quad_shape
    we = ((weights * weights)[:, None, None] * edges).reshape(qy, qx, 4, 2)
    top, right, bottom, left = (we[:, :, k] for k in range(4))
    rhs = np.zeros((grid.ny, grid.nx, 2))
    # Edge k runs from corner k to corner k+1 (corners: tl, tr, br, bl): it adds
    # its target to its end and subtracts it from its start.
    rhs[:-1, :-1] += left - top
    rhs[:-1, 1:] += top - right
    rhs[1:, 1:] += right - bottom
    rhs[1:, :-1] += bottom - left
    return rhs.reshape(-1, 2)


def feature_nodes(grid: Grid, features) -> np.ndarray:
    """Component of each node that is a corner of a feature quad, else -1: (N,) int."""
    nodes = np.full(grid.n_nodes, -1)
    own = features.is_feature
    nodes[grid.quads()[own].ravel()] = np.repeat(features.component[own], 4)
    return nodes


def tie_features(grid: Grid, features, fixed: np.ndarray, released=()) -> np.ndarray:
    """Component each node is tied to as part of one rigid piece, or -1.

    The nodes of a component's feature quads move together (x = M_c X + t_c).
    Components that touch a fixed node, or are listed in ``released``, stay untied
    (they keep soft, weighted constraints instead).

    Parameters
    ----------
    grid : Grid
    features : features.Features
    fixed : (N,) bool ndarray
        Nodes with any coordinate held.
    released : sequence of int

    Returns
    -------
    (N,) int ndarray
    """
    tied = feature_nodes(grid, features)
    loose = np.union1d(np.unique(tied[fixed & (tied >= 0)]), np.asarray(released, dtype=np.int64))
    tied[np.isin(tied, loose)] = -1
    return tied


def sliding_sides(grid: Grid, warped: np.ndarray, tolerance: float = 1e-6) -> tuple[bool, ...]:
    """Sides (top, bottom, left, right) that W maps onto an axis-parallel straight line.

    Nodes on such a side may slide along that line without changing the canvas.
    When W leaves the whole border where it is (a swirl or bulge whose radius
    stays inside the image) nothing slides: it would gain nothing and cost a
    second factorization.
    """
    moved = warped.reshape(grid.ny, grid.nx, 2)
    border = grid.boundary()
    if np.abs(warped[border] - grid.nodes()[border]).max() <= tolerance:
        return (False,) * 4
    return (bool(np.ptp(moved[0, :, 1]) <= tolerance), bool(np.ptp(moved[-1, :, 1]) <= tolerance),
            bool(np.ptp(moved[:, 0, 0]) <= tolerance), bool(np.ptp(moved[:, -1, 0]) <= tolerance))


def border_conditions(grid: Grid, sides: tuple[bool, ...]) -> tuple[np.ndarray, np.ndarray]:
    """Which coordinates of each node are held at W: (fixed_x, fixed_y), each (N,) bool.

    All border nodes are held, except that on a sliding side (see
    :func:`sliding_sides`) the coordinate along the side is free; corners stay held.
    """
    fixed_x = grid.boundary().reshape(grid.ny, grid.nx)
    fixed_y = fixed_x.copy()
    top, bottom, left, right = sides
    inner_row, inner_col = slice(1, -1), slice(1, -1)
    if top:
        fixed_x[0, inner_col] = False
    if bottom:
        fixed_x[-1, inner_col] = False
    if left:
        fixed_y[inner_row, 0] = False
    if right:
        fixed_y[inner_row, -1] = False
    return fixed_x.ravel(), fixed_y.ravel()


def number_unknowns(fixed: np.ndarray, tied: np.ndarray) -> np.ndarray:
    """Unknown index per node: -1 when fixed, one shared index per tied component,
    otherwise its own (free nodes first, in node order, then the components)."""
    free = ~fixed & (tied < 0)
    unknown = np.full(fixed.size, -1)
    n_free = int(np.count_nonzero(free))
    unknown[free] = np.arange(n_free)
    components, inverse = np.unique(tied[tied >= 0], return_inverse=True)
    unknown[tied >= 0] = n_free + inverse
    return unknown

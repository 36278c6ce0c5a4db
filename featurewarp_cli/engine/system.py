"""The least-squares system of Eqs. (3)-(5): normal matrix and right-hand side.

Each quad contributes four edge equations ``w (v_b - v_a) = w t`` (edges taken
cyclically: top, right, bottom, left). The normal matrix A^T A is then a
weighted 5-point graph Laplacian whose edge weights are the sums of w^2 over
the (one or two) quads sharing the edge; it depends on the grid and the
weights only, never on the warp.
"""

from __future__ import annotations

import numpy as np

from .grid import Grid


class StencilMatrix:
    """A symmetric matrix with the pattern of a grid's 5-point stencil (node ``j * nx + i``
    coupled to its left, right, upper and lower neighbours), stored as its weights.

    Parameters
    ----------
    diagonal : (N,) ndarray
    right : (N - 1,) ndarray
        Entry (k, k + 1) = (k + 1, k); 0 where k ends a grid row (no coupling there).
    down : (N - nx,) ndarray
        Entry (k, k + nx) = (k + nx, k).
    nx : int
        Nodes per grid row.

    Attributes
    ----------
    shape : (int, int)
    nx, ny : int
    """

    def __init__(self, diagonal: np.ndarray, right: np.ndarray, down: np.ndarray, nx: int):
        self.diagonal, self.right, self.down = diagonal, right, down
        self.nx = int(nx)
        self.ny = diagonal.size // self.nx
        self.shape = (diagonal.size, diagonal.size)
        self._lower = None

    def dot(self, x: np.ndarray) -> np.ndarray:
        """The product with ``x`` ((N,) or (N, k) ndarray).

        Each row's terms are added in the order of its columns (upper, left,
        itself, right, lower neighbour), as a CSR matrix product adds them. The
        work runs on ``x.T`` (rows of N values: long inner loops); the result is
        the transpose of a C-ordered array.
        """
        xt = np.ascontiguousarray(np.asarray(x, dtype=np.float64).T)
        nx, right, down = self.nx, self.right, self.down
        y = np.zeros(xt.shape)
        y[..., nx:] -= down * xt[..., :-nx]
        y[..., 1:] -= right * xt[..., :-1]
        y += self.diagonal * xt
        y[..., :-1] -= right * xt[..., 1:]
        y[..., :-nx] -= down * xt[..., nx:]
        return y.T

    __matmul__ = dot

    def lower_triplets(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(rows, cols, vals) of the lower triangle (rows >= cols, int64 and float64), one entry
        per diagonal element and per grid edge, whatever its weight (the pattern is the grid's).
        Computed once (the x and y systems both read them)."""
        if self._lower is None:
            self._lower = self._lower_triplets()
        return self._lower

    def _lower_triplets(self):
        n, nx = self.shape[0], self.nx
        nodes = np.arange(n, dtype=np.int64)
        left = nodes[1:][nodes[1:] % nx != 0]              # nodes with a left neighbour
        rows = np.concatenate([nodes, left, nodes[nx:]])
        cols = np.concatenate([nodes, left - 1, nodes[:-nx]])
        vals = np.concatenate([self.diagonal, -self.right[left - 1], -self.down])
        return rows, cols, vals

    def submatrix(self, nodes: np.ndarray) -> "StencilWindow":
        """The rows and columns ``nodes`` (distinct node indices, usually sorted), as a
        :class:`StencilWindow`."""
        nodes = np.asarray(nodes, dtype=np.int64)
        n, nx, m = self.shape[0], self.nx, nodes.size
        local = np.full(n + 1, m, dtype=np.int64)           # m: not in the window
        local[nodes] = np.arange(m)
        i = nodes % nx
        # Neighbours of each node in column order: up, left, itself, right, down.
        exists = np.stack([nodes >= nx, i > 0, np.ones(m, bool), i < nx - 1, nodes < n - nx], axis=1)
        other = np.where(exists, nodes[:, None] + np.array([-nx, -1, 0, 1, nx]), n)
        weights = np.stack([-self.down[np.maximum(nodes - nx, 0)], -self.right[np.maximum(nodes - 1, 0)],
                            self.diagonal[nodes], -self.right[np.minimum(nodes, n - 2)],
                            -self.down[np.minimum(nodes, n - nx - 1)]], axis=1)
        neighbours = local[other]
        return StencilWindow(neighbours, np.where(neighbours < m, weights, 0.0))

    def to_scipy(self):
        """The matrix as a SciPy CSR matrix (imports SciPy; for tests and benchmarks)."""
        rows, cols, vals = self.lower_triplets()
        return symmetric_scipy(rows, cols, vals, self.shape[0])


class StencilWindow:
    """Some rows and the same columns of a :class:`StencilMatrix` (a symmetric matrix of
    at most five entries per row), as a table of each row's neighbours.

    Parameters
    ----------
    neighbours : (m, 5) int ndarray
        Column (local index) of the entries of each row: its upper, left, own, right
        and lower neighbour on the grid, or m where that one is not in the window.
    weights : (m, 5) ndarray
        The entries; 0 where there is no neighbour.

    Attributes
    ----------
    shape : (int, int)
    """

    def __init__(self, neighbours: np.ndarray, weights: np.ndarray):
        self.neighbours = neighbours
        self.weights = weights
        self.shape = (neighbours.shape[0], neighbours.shape[0])
        self._neighbours_t = np.ascontiguousarray(neighbours.T)
        self._weights_t = np.ascontiguousarray(weights.T)

    def dot(self, x: np.ndarray) -> np.ndarray:
        """The product with ``x`` ((m,) or (m, k) ndarray). Each row's terms are added in
        the order of their columns when the window's nodes are sorted, as in a CSR product
        (a missing neighbour adds 0). Computed on ``x.T``, like :meth:`StencilMatrix.dot`."""
        xt = np.asarray(x, dtype=np.float64).T
        m = self.shape[0]
        padded = np.zeros(xt.shape[:-1] + (m + 1,))          # column m: 0 for missing neighbours
        padded[..., :m] = xt
        y = np.zeros(xt.shape)
        for neighbour, weight in zip(self._neighbours_t, self._weights_t):
            y += weight * np.take(padded, neighbour, axis=-1)
        return y.T

    __matmul__ = dot

    def lower_triplets(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(rows, cols, vals) of the lower triangle (rows >= cols), row by row."""
        m = self.shape[0]
        rows = np.broadcast_to(np.arange(m)[:, None], self.neighbours.shape)
        low = (self.neighbours <= rows)
        return rows[low], self.neighbours[low], self.weights[low]

    def to_scipy(self):
        """The matrix as a SciPy CSR matrix (imports SciPy; for tests and benchmarks)."""
        rows, cols, vals = self.lower_triplets()
        return symmetric_scipy(rows, cols, vals, self.shape[0])


def symmetric_scipy(rows: np.ndarray, cols: np.ndarray, vals: np.ndarray, n: int):
    """The symmetric n x n matrix whose lower triangle has these triplets (rows >= cols;
    duplicates summed), as a SciPy CSR matrix (imports SciPy; for tests and benchmarks)."""
    import scipy.sparse as sp

    off = rows != cols
    return sp.csr_matrix((np.concatenate([vals, vals[off]]),
                          (np.concatenate([rows, cols[off]]), np.concatenate([cols, rows[off]]))),
                         shape=(n, n))


def normal_matrix(grid: Grid, weights: np.ndarray) -> StencilMatrix:
    """A^T A for quad weights ``weights`` ((K,) ndarray): an (N, N) :class:`StencilMatrix`."""
    qy, qx = grid.quad_shape
    w2 = (weights * weights).reshape(qy, qx)
    horizontal = np.zeros((grid.ny, qx))          # edge (j, i) -- (j, i+1)
    horizontal[:-1] += w2
    horizontal[1:] += w2
    vertical = np.zeros((qy, grid.nx))            # edge (j, i) -- (j+1, i)
    vertical[:, :-1] += w2
    vertical[:, 1:] += w2

    right = np.zeros((grid.ny, grid.nx))          # weight to the right neighbour
    right[:, :-1] = horizontal
    down = vertical.ravel()                       # weight to the node below
    diagonal = np.zeros((grid.ny, grid.nx))
    diagonal[:, :-1] += horizontal
    diagonal[:, 1:] += horizontal
    diagonal[:-1, :] += vertical
    diagonal[1:, :] += vertical
    return StencilMatrix(diagonal.ravel(), right.ravel()[:-1], down, grid.nx)


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
    """Edge vectors of each quad under the warp itself (Eq. 4): (K, 4, 2)."""
    corners = warped[grid.quads()]
    return np.roll(corners, -1, axis=1) - corners


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

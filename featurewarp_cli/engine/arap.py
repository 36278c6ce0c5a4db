"""As-rigid-as-possible deformation of the grid from positional handles (the paper's
interactive mode, section 3).

The method is the two-step one of Igarashi, Moscovich and Hughes (2005), "As-rigid-
as-possible shape manipulation", on the grid's triangles:

1. *similarity step*: each triangle keeps its shape up to a similarity. For every
   triangle and each of its vertices, the vertex is written in the frame of the
   opposite edge (``v_k = v_i + x (v_j - v_i) + y R90 (v_j - v_i)``, with x, y from the
   source); the squared error of these equations is a quadratic energy in the node
   positions, zero exactly for similarities. With the handles as heavily weighted
   penalty rows it is one sparse least-squares system in (x, y) together.
2. *rigid step*: each triangle's closest similarity to its step-1 image gives it a
   rotation; the triangle's edges are asked to be the source edges rotated so and
   scaled by the handles' overall scale ``s`` (the scale of the similarity that best
   fits the handles); one Laplacian system per axis.

Both matrices depend on the grid and on where the handles sit in the source, never on
where they are dragged: they are factored once per handle set, and moving a handle costs
back-substitutions and a per-triangle fit (what made the paper's editing interactive).
Igarashi's method was chosen over Sorkine and Alexa's local/global ARAP for that reason:
it is two linear solves with fixed matrices, no iteration to convergence, so an update
takes a bounded, small time. Handles that describe one similarity give exactly that
similarity: its energy is zero in both steps (step 2's triangles are asked to be the
source scaled by ``s``, the handles' own scale, instead of Igarashi's scale 1).

Handles are points anywhere in the image, tied to the grid by barycentric coordinates in
the triangle that holds them. A point handle of a Puppet-Warp kind holds a small disc
(``radius``) rather than a point: a pull on one point of a triangle mesh concentrates the
strain on the triangles around it (the displacement of a point force decays only as log r)
and folds them at drags of a few cells; a disc spreads it. The disc moves as the handle,
turned and scaled by the handles' overall similarity, so a similarity stays exact.

When the two-step result still folds (handles dragged across each other, or far towards a
pin), the map is found again by scalable locally injective mapping (SLIM, Rabinovich et al.
2017) started from an injective map (the handles' best similarity, or the caller's last
result): the symmetric Dirichlet energy, infinite at a flip, lowered by reweighted least
squares with a line search cut short before the first flip (:func:`injectivity.max_step`).
No triangle of the result folds; the handles are then held only as far as the image can
follow.
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp

from .grid import Grid, signed_areas
from .injectivity import max_step
from .solver import spd_solver

#: Weight of a handle's penalty row against one triangle's shape equations: the handles
#: hold to within a small fraction of a pixel while the system stays well conditioned.
HANDLE_WEIGHT = 1e4
#: Samples of a disc handle: its centre and two rings of this many points (at half and
#: full radius).
DISC_POINTS = 8
#: Iterations of the injective fallback at most, and the relative decrease of its energy
#: below which it stops.
INJECTIVE_STEPS = 100
SLIM_TOLERANCE = 1e-4


def embed(grid: Grid, points: np.ndarray) -> sp.csr_matrix:
    """Barycentric coordinates of ``points`` in the grid's triangles.

    Parameters
    ----------
    grid : Grid
    points : (K, 2) ndarray
        Source positions (pixel centres at integers), inside the pixel extent or on it
        (points outside are clamped to the nearest triangle's plane).

    Returns
    -------
    (K, N) scipy.sparse CSR matrix
        Row k holds the weights of the three nodes of the triangle of point k, so that
        ``E @ nodes`` gives the points back (and ``E @ W(nodes)`` maps them linearly).
    """
    points = np.asarray(points, dtype=np.float64).reshape(-1, 2)
    sx, sy = grid.spacing
    fx, fy = (points[:, 0] + 0.5) / sx, (points[:, 1] + 0.5) / sy
    i = np.clip(np.floor(fx), 0, grid.nx - 2).astype(np.int64)
    j = np.clip(np.floor(fy), 0, grid.ny - 2).astype(np.int64)
    u, v = fx - i, fy - j
    tl = j * grid.nx + i
    upper = u >= v                              # triangle (tl, tr, br), else (tl, br, bl)
    cols = np.stack([tl, np.where(upper, tl + 1, tl + 1 + grid.nx), np.where(upper, tl + 1 + grid.nx, tl + grid.nx)], 1)
    weights = np.stack([np.where(upper, 1 - u, 1 - v), np.where(upper, u - v, u), np.where(upper, v, v - u)], 1)
    rows = np.repeat(np.arange(len(points)), 3)
    return sp.csr_matrix((weights.ravel(), (rows, cols.ravel())), shape=(len(points), grid.n_nodes))


def _similarity_rows(nodes: np.ndarray, triangles: np.ndarray) -> sp.csr_matrix:
    """Igarashi's step-1 equations: (6M, 2N), unknowns (x of every node, then y)."""
    n = len(nodes)
    tri = np.concatenate([triangles, triangles[:, [1, 2, 0]], triangles[:, [2, 0, 1]]])
    i, j, k = tri[:, 0], tri[:, 1], tri[:, 2]
    d = nodes[j] - nodes[i]
    e = nodes[k] - nodes[i]
    length2 = np.sum(d * d, axis=1)
    x = np.sum(e * d, axis=1) / length2
    y = (e[:, 1] * d[:, 0] - e[:, 0] * d[:, 1]) / length2      # e . R90 d with R90 (a, b) = (-b, a)
    m = len(tri)
    one = np.ones(m)
    # rx: v_k.x - v_i.x - x (v_j.x - v_i.x) + y (v_j.y - v_i.y); ry likewise with R90.
    rx_cols = np.stack([k, i, j, n + j, n + i], 1)
    rx_vals = np.stack([one, x - 1, -x, y, -y], 1)
    ry_cols = np.stack([n + k, n + i, n + j, j, i], 1)
    ry_vals = np.stack([one, x - 1, -x, -y, y], 1)
    rows = np.repeat(np.arange(2 * m), 5)
    cols = np.concatenate([rx_cols, ry_cols]).ravel()
    vals = np.concatenate([rx_vals, ry_vals]).ravel()
    return sp.csr_matrix((vals, (rows, cols)), shape=(2 * m, 2 * n))


def _edge_rows(triangles: np.ndarray, n: int) -> sp.csr_matrix:
    """Edge differences of every triangle's three edges (3M, N): v_end - v_start."""
    start = triangles.ravel()
    end = triangles[:, [1, 2, 0]].ravel()
    rows = np.repeat(np.arange(start.size), 2)
    cols = np.stack([end, start], 1).ravel()
    vals = np.tile([1.0, -1.0], start.size)
    return sp.csr_matrix((vals, (rows, cols)), shape=(start.size, n))


def similarity_fit(sources: np.ndarray, targets: np.ndarray) -> tuple[float, float]:
    """(a, b) of the similarity x -> [[a, -b], [b, a]] x + t that best fits ``sources`` onto
    ``targets`` in the least-squares sense (its scale is hypot(a, b))."""
    p = sources - sources.mean(axis=0)
    q = targets - targets.mean(axis=0)
    spread = float(np.sum(p * p))
    if spread == 0.0:
        return 1.0, 0.0
    return (float(np.sum(p * q)) / spread, float(np.sum(p[:, 0] * q[:, 1] - p[:, 1] * q[:, 0])) / spread)


def _disc_offsets(radius: np.ndarray) -> np.ndarray:
    """(K, 1 + 2 DISC_POINTS, 2) sample offsets of each handle's disc (all zero for radius 0)."""
    angle = np.arange(DISC_POINTS) * (2.0 * np.pi / DISC_POINTS)
    ring = np.stack([np.cos(angle), np.sin(angle)], axis=1)
    unit = np.concatenate([np.zeros((1, 2)), 0.5 * ring, ring])
    return radius[:, None, None] * unit[None]


class RigidDeformer:
    """As-rigid-as-possible map of a grid from handles, factored once per handle set.

    Parameters
    ----------
    grid : Grid
        The grid to deform (usually coarser than the feature-aware solve's).
    sources : (K, 2) ndarray
        Where the handles sit in the source image; at least two distinct points.
    radius : (K,) ndarray or float
        Radius in pixels of the disc each handle holds (0: a point; curve and border
        samples are points).
    weight : float
        Weight of the handles' penalty rows (:data:`HANDLE_WEIGHT`).

    Examples
    --------
    >>> import numpy as np
    >>> grid = Grid.for_image(64, 48, 8)
    >>> rigid = RigidDeformer(grid, np.array([[0.0, 0.0], [63.0, 47.0]]))
    >>> nodes = rigid.deform(np.array([[10.0, 5.0], [73.0, 52.0]]))     # a translation
    >>> bool(np.allclose(nodes, grid.nodes() + [10, 5]))
    True
    """

    def __init__(self, grid: Grid, sources: np.ndarray, radius=0.0, weight: float = HANDLE_WEIGHT):
        sources = np.asarray(sources, dtype=np.float64).reshape(-1, 2)
        if len(np.unique(np.round(sources, 6), axis=0)) < 2:
            raise ValueError("at least two distinct handles (or pins) are needed: one alone leaves the "
                             "rotation and scale free")
        self.grid = grid
        self.sources = sources
        self.offsets = _disc_offsets(np.broadcast_to(np.asarray(radius, dtype=np.float64), len(sources)))
        self.weight = float(weight)
        self.nodes = grid.nodes()
        self.triangles = grid.triangles()
        self.source_areas = signed_areas(self.nodes, self.triangles)
        samples = (sources[:, None, :] + self.offsets).reshape(-1, 2)
        self.embedding = embed(grid, samples)
        penalty = (self.embedding.T @ self.embedding) * (self.weight / self.offsets.shape[1])
        shape = _similarity_rows(self.nodes, self.triangles)
        self._step1 = spd_solver((shape.T @ shape + sp.block_diag([penalty, penalty])).tocsc())
        self._edges = _edge_rows(self.triangles, grid.n_nodes)
        self._step2 = spd_solver((self._edges.T @ self._edges + penalty).tocsc())
        self._source_edges = np.asarray(self._edges @ self.nodes).reshape(-1, 3, 2)
        corners = self.nodes[self.triangles]
        self._centred_source = corners - corners.mean(axis=1, keepdims=True)
        #: Local/global steps the last :meth:`deform` took to stay injective (0: none needed).
        self.injective_steps = 0

    def deform(self, targets: np.ndarray, start: np.ndarray | None = None, steps: int | None = None) -> np.ndarray:
        """Node positions (N, 2) that carry the handles to ``targets`` (K, 2) as rigidly as
        possible, without a fold.

        ``start``: an injective map (N, 2) close to the answer (the last one, while a handle
        is dragged) for the injective fallback; default: the handles' best similarity.
        ``steps``: the fallback's iterations at most (default :data:`INJECTIVE_STEPS`)."""
        targets = np.asarray(targets, dtype=np.float64).reshape(self.sources.shape)
        a, b = similarity_fit(self.sources, targets)
        turn = np.array([[a, -b], [b, a]])
        samples = (targets[:, None, :] + self.offsets @ turn.T).reshape(-1, 2)
        pulled = (self.embedding.T @ samples) * (self.weight / self.offsets.shape[1])
        first = self._step1(np.concatenate([pulled[:, 0], pulled[:, 1]]))
        n = self.grid.n_nodes
        x = self._rigid_step(np.stack([first[:n], first[n:]], axis=1), np.hypot(a, b), pulled)
        self.injective_steps = 0
        if np.all(signed_areas(x, self.triangles) > 0):
            return x
        if start is None or not np.all(signed_areas(start, self.triangles) > 0):
            centre_s, centre_t = self.sources.mean(axis=0), targets.mean(axis=0)
            start = (self.nodes - centre_s) @ turn.T + centre_t
            if not (a * a + b * b > 0):
                start = self.nodes + (centre_t - centre_s)
        return self._injective(start, np.hypot(a, b) or 1.0, samples, steps or INJECTIVE_STEPS)

    def centres(self, nodes: np.ndarray) -> np.ndarray:
        """Where the handles' centres are under the node positions ``nodes``: (K, 2)."""
        centre = self.embedding[:: self.offsets.shape[1]]
        return np.asarray(centre @ nodes)

    def _rigid_step(self, positions: np.ndarray, scale: float, pulled: np.ndarray) -> np.ndarray:
        """Step 2: the triangles rotated as in ``positions``, scaled by ``scale``, joined."""
        angle = self._rotations(positions)
        c, s = np.cos(angle)[:, None], np.sin(angle)[:, None]
        src = self._source_edges
        wanted = scale * np.stack([c * src[..., 0] - s * src[..., 1], s * src[..., 0] + c * src[..., 1]], axis=-1)
        return np.asarray(self._step2(self._edges.T @ wanted.reshape(-1, 2) + pulled))

    def _injective(self, x: np.ndarray, scale: float, samples: np.ndarray, steps: int) -> np.ndarray:
        """Scalable locally injective mapping (Rabinovich et al. 2017) from the injective ``x``:
        the symmetric Dirichlet energy of each triangle against its source scaled by ``scale``
        (infinite at a flip) plus the handles' penalty, lowered by reweighted least squares
        with a line search that stops short of the first flip."""
        rest = self.nodes * scale
        grads, areas = _basis_gradients(rest, self.triangles)
        root = np.sqrt(self.weight / self.offsets.shape[1])
        penalty_rows, targets = (self.embedding * root).tocsr(), samples * root
        energy = _slim_energy(x, self.triangles, grads, areas, penalty_rows, targets)
        for step in range(1, steps + 1):
            proposal = _slim_step(x, self.triangles, grads, areas, penalty_rows, targets)
            t = min(1.0, 0.9 * max_step(x, proposal, self.triangles))
            while t > 1e-6:
                trial = x + t * (proposal - x)
                trial_energy = _slim_energy(trial, self.triangles, grads, areas, penalty_rows, targets)
                if trial_energy <= energy:
                    break
                t *= 0.5
            self.injective_steps = step
            if t <= 1e-6 or energy - trial_energy <= SLIM_TOLERANCE * energy:
                if t > 1e-6:
                    x = trial
                break
            x, energy = trial, trial_energy
        return x

    def _rotations(self, positions: np.ndarray) -> np.ndarray:
        """Angle of each triangle's closest similarity from the source to ``positions``."""
        p = self._centred_source
        q = positions[self.triangles]
        q = q - q.mean(axis=1, keepdims=True)
        dot = np.sum(p * q, axis=(1, 2))
        cross = np.sum(p[..., 0] * q[..., 1] - p[..., 1] * q[..., 0], axis=1)
        return np.arctan2(cross, dot)


def _basis_gradients(rest: np.ndarray, triangles: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Gradients (M, 3, 2) of each triangle's barycentric basis functions on ``rest``, and
    the triangles' areas (M,): the Jacobian of a map is sum_k q_k g_k^T."""
    p = rest[triangles]
    e1, e2 = p[:, 1] - p[:, 0], p[:, 2] - p[:, 0]
    det = e1[:, 0] * e2[:, 1] - e1[:, 1] * e2[:, 0]
    inverse = np.stack([np.stack([e2[:, 1], -e2[:, 0]], -1), np.stack([-e1[:, 1], e1[:, 0]], -1)], 1) / det[:, None, None]
    g1, g2 = inverse[:, 0], inverse[:, 1]          # rows of [e1 e2]^-1: gradients of basis 1 and 2
    return np.stack([-g1 - g2, g1, g2], axis=1), 0.5 * det


def _jacobians(x: np.ndarray, triangles: np.ndarray, grads: np.ndarray) -> np.ndarray:
    """(M, 2, 2) Jacobian of the piecewise-linear map with node images ``x``."""
    return np.einsum("mki,mkj->mij", x[triangles], grads)


def _slim_energy(x, triangles, grads, areas, penalty_rows, targets) -> float:
    """Symmetric Dirichlet energy plus the handles' penalty |P x - targets|^2 (inf where a
    triangle flips)."""
    jac = _jacobians(x, triangles, grads)
    det = jac[:, 0, 0] * jac[:, 1, 1] - jac[:, 0, 1] * jac[:, 1, 0]
    if np.any(det <= 0):
        return np.inf
    frob = np.sum(jac * jac, axis=(1, 2))
    residual = penalty_rows @ x - targets
    return float(np.sum(areas * (frob + frob / (det * det))) + np.sum(residual * residual))


def _slim_weights(jac: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """SLIM's per-triangle weight W = U diag(w(sigma)) U^T and target W R for Jacobians ``jac``
    (M, 2, 2) with a positive determinant, from the closed-form 2x2 SVD J = U(phi) S U(theta)
    (the closest rotation R is the rotation by phi + theta)."""
    e = (jac[:, 0, 0] + jac[:, 1, 1]) / 2
    f = (jac[:, 0, 0] - jac[:, 1, 1]) / 2
    g = (jac[:, 1, 0] + jac[:, 0, 1]) / 2
    h = (jac[:, 1, 0] - jac[:, 0, 1]) / 2
    q, r = np.hypot(e, h), np.hypot(f, g)
    sigma = np.maximum(np.stack([q + r, q - r], axis=1), 1e-8)
    turn, spread = np.arctan2(h, e), np.arctan2(g, f)
    phi = (turn + spread) / 2
    w = np.sqrt((sigma + 1) * (sigma * sigma + 1) / sigma ** 3)        # symmetric Dirichlet's reweighting
    c, s = np.cos(phi), np.sin(phi)
    weight = np.empty_like(jac)
    weight[:, 0, 0] = w[:, 0] * c * c + w[:, 1] * s * s
    weight[:, 1, 1] = w[:, 0] * s * s + w[:, 1] * c * c
    weight[:, 0, 1] = weight[:, 1, 0] = (w[:, 0] - w[:, 1]) * c * s
    rc, rs = np.cos(turn), np.sin(turn)
    rotation = np.stack([np.stack([rc, -rs], -1), np.stack([rs, rc], -1)], -2)
    return weight, weight @ rotation


def _slim_step(x, triangles, grads, areas, penalty_rows, targets) -> np.ndarray:
    """The reweighted least-squares proposal of one SLIM iteration."""
    weight, target = _slim_weights(_jacobians(x, triangles, grads))
    m, n = len(triangles), len(x)
    # rows (triangle, column c, output i): sum_k g_k[c] (W[i,0] x_k + W[i,1] y_k) = (W R)[i, c]
    root = np.sqrt(areas)
    coef = np.einsum("mkc,mij->mcikj", grads, weight) * root[:, None, None, None, None]   # (M, 2, 2, 3, 2)
    rows = np.broadcast_to(np.arange(4 * m).reshape(m, 2, 2, 1, 1), coef.shape)
    cols = np.broadcast_to(triangles[:, None, None, :, None] + n * np.arange(2)[None, None, None, None, :], coef.shape)
    shape_rows = sp.csr_matrix((coef.ravel(), (rows.ravel(), cols.ravel())), shape=(4 * m, 2 * n))
    rhs_shape = (np.transpose(target, (0, 2, 1)) * root[:, None, None]).ravel()
    pen = sp.block_diag([penalty_rows, penalty_rows]).tocsr()
    rhs_pen = np.concatenate([targets[:, 0], targets[:, 1]])
    normal = (shape_rows.T @ shape_rows + pen.T @ pen).tocsc()
    solution = spd_solver(normal)(shape_rows.T @ rhs_shape + pen.T @ rhs_pen)
    return np.stack([solution[:n], solution[n:]], axis=1)

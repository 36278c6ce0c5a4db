"""As-rigid-as-possible deformation of the grid from positional handles (the paper's
interactive mode, section 3).

The map is the minimum of one energy (:mod:`featurewarp_cli.engine.rigid_energy`):
converged as-rigid-as-possible (Sorkine and Alexa 2007) with an area barrier that keeps
every triangle the right way round, the handles as heavily weighted penalty rows. The
triangles' rest size is 1 (a squash does not shrink the direction it leaves alone), or the
handles' own scale where one similarity explains the handles (:func:`rest_scale`), so
handles that describe a similarity give exactly that similarity.

Its Newton minimiser starts from an injective map near the answer: the caller's last
result while a handle is dragged, else Igarashi, Moscovich and Hughes' (2005) similarity
step (each triangle keeps its shape up to a similarity: for each triangle and vertex, the
vertex written in the frame of the opposite edge, ``v_k = v_i + x (v_j - v_i) + y R90 (v_j -
v_i)``; one sparse least-squares system, factored once per handle set) followed by a few
local/global iterations (one back-substitution each), the last of them that folds nothing.

Handles are points anywhere in the image, tied to the grid by barycentric coordinates in
the triangle that holds them. A point handle of a Puppet-Warp kind holds a small disc
(``radius``) rather than a point: a pull on one point of a triangle mesh concentrates the
strain on the triangles around it (the displacement of a point force decays only as log r)
and folds them at drags of a few cells; a disc spreads it. The disc moves as the handle,
turned and scaled by the handles' overall similarity, so a similarity stays exact. Where
the handles ask for a fold (dragged across each other, or far towards a pin), the barrier
holds the triangles and the handles are held only as far as the image can follow.
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp

from .grid import Grid, signed_areas
from . import rigid_energy
from .solver import spd_solver

#: Weight of a handle's penalty row against one triangle's shape equations: the handles
#: hold to within a small fraction of a pixel while the system stays well conditioned.
HANDLE_WEIGHT = 1e4
#: Samples of a disc handle: its centre and two rings of this many points (at half and
#: full radius).
DISC_POINTS = 8
#: Local/global iterations (Sorkine and Alexa 2007) that make the Newton minimiser's start.
GUESS_STEPS = 10
#: How far from one similarity the handles may be (their fit's residual against their
#: spread) before the triangles' rest size is 1 instead of the handles' scale.
SIMILARITY_RESIDUAL = 0.01


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


def rest_scale(sources: np.ndarray, targets: np.ndarray) -> float:
    """The size the rigid map asks of every triangle: the handles' scale ``s`` where a
    similarity explains them, 1 where it does not, and ``s ** c`` between.

    ``c = (1 - rho / SIMILARITY_RESIDUAL) ** 2`` (0 beyond), with ``rho`` the residual of the
    handles' best similarity against the targets' spread: handles that scale the image
    uniformly scale it exactly, while a squash does not shrink the direction it leaves alone
    (a rest size of ``s`` would: a half-width squash fits ``s`` = 0.63). It is a continuous
    function of the handles, so no drag flips it."""
    a, b = similarity_fit(sources, targets)
    scale = float(np.hypot(a, b))
    spread = float(np.sum((targets - targets.mean(axis=0)) ** 2))
    if not (scale > 0 and spread > 0):
        return 1.0
    turn = np.array([[a, -b], [b, a]])
    shift = targets.mean(axis=0) - sources.mean(axis=0) @ turn.T
    residual = float(np.sum((sources @ turn.T + shift - targets) ** 2)) / spread
    weight = max(0.0, 1.0 - residual / SIMILARITY_RESIDUAL) ** 2
    return scale ** weight


def disc_turn(a: float, b: float, scale: float) -> np.ndarray:
    """The 2x2 map a handle's disc moves by: the handles' best rotation (from their similarity
    fit (a, b)) at the triangles' rest size ``scale`` (:func:`rest_scale`), so that the disc is
    as large as the triangles around it are asked to be."""
    norm = float(np.hypot(a, b))
    if not norm > 0:
        return scale * np.eye(2)
    return (scale / norm) * np.array([[a, -b], [b, a]])


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
        #: Newton steps the last :meth:`deform` took, and whether it converged.
        self.newton_steps, self.converged = 0, True
        self._rigid_energy = None

    def deform(self, targets: np.ndarray, start: np.ndarray | None = None, steps: int | None = None) -> np.ndarray:
        """Node positions (N, 2) that carry the handles to ``targets`` (K, 2) as rigidly as
        possible, without a fold: the minimum of :mod:`rigid_energy`'s energy.

        ``start``: an injective map (N, 2) close to the answer (the last one, while a handle
        is dragged) to start from instead of the similarity step. ``steps``: Newton steps at
        most (default :data:`rigid_energy.MAX_STEPS`)."""
        targets = np.asarray(targets, dtype=np.float64).reshape(self.sources.shape)
        a, b = similarity_fit(self.sources, targets)
        turn = np.array([[a, -b], [b, a]])
        scale = rest_scale(self.sources, targets)
        samples = (targets[:, None, :] + self.offsets @ disc_turn(a, b, scale).T).reshape(-1, 2)
        if start is None or not np.all(signed_areas(start, self.triangles) > 0):
            start = self._first_guess(samples, turn, targets, scale)
        energy = self._energy(scale)
        root = np.sqrt(self.weight / self.offsets.shape[1])
        x, self.newton_steps, self.converged = rigid_energy.minimise(energy, start, samples * root,
                                                                      steps or rigid_energy.MAX_STEPS)
        return x

    def _energy(self, scale: float) -> rigid_energy.RigidEnergy:
        """The energy for triangles of rest size ``scale`` (built once per handle set)."""
        if self._rigid_energy is None:
            root = np.sqrt(self.weight / self.offsets.shape[1])
            self._rigid_energy = rigid_energy.RigidEnergy(self.nodes, self.triangles, self.embedding * root)
        self._rigid_energy.rescale(scale)
        return self._rigid_energy

    def _first_guess(self, samples: np.ndarray, turn: np.ndarray, targets: np.ndarray, scale: float) -> np.ndarray:
        """An injective start near the answer: Igarashi's similarity step, then local/global
        iterations (:data:`GUESS_STEPS`), the last of these that folds nothing; the handles'
        best similarity where all fold."""
        pulled = (self.embedding.T @ samples) * (self.weight / self.offsets.shape[1])
        first = self._step1(np.concatenate([pulled[:, 0], pulled[:, 1]]))
        n = self.grid.n_nodes
        x = np.stack([first[:n], first[n:]], axis=1)
        best = x if np.all(signed_areas(x, self.triangles) > 0) else None
        for _ in range(GUESS_STEPS):
            x = np.asarray(self._step2(self._edges.T @ self._wanted(x, scale).reshape(-1, 2) + pulled))
            if np.all(signed_areas(x, self.triangles) > 0):
                best = x
        if best is not None:
            return best
        centre_s, centre_t = self.sources.mean(axis=0), targets.mean(axis=0)
        if not (turn[0, 0] ** 2 + turn[1, 0] ** 2 > 0):
            return self.nodes + (centre_t - centre_s)
        return (self.nodes - centre_s) @ turn.T + centre_t

    def _wanted(self, positions: np.ndarray, scale: float) -> np.ndarray:
        """(M, 3, 2) source edges of each triangle turned by its closest rotation to ``positions``
        and scaled by ``scale``."""
        angle = self._rotations(positions)
        c, s = np.cos(angle)[:, None], np.sin(angle)[:, None]
        src = self._source_edges
        return scale * np.stack([c * src[..., 0] - s * src[..., 1], s * src[..., 0] + c * src[..., 1]], axis=-1)

    def centres(self, nodes: np.ndarray) -> np.ndarray:
        """Where the handles' centres are under the node positions ``nodes``: (K, 2)."""
        centre = self.embedding[:: self.offsets.shape[1]]
        return np.asarray(centre @ nodes)

    def _rotations(self, positions: np.ndarray) -> np.ndarray:
        """Angle of each triangle's closest similarity from the source to ``positions``."""
        p = self._centred_source
        q = positions[self.triangles]
        q = q - q.mean(axis=1, keepdims=True)
        dot = np.sum(p * q, axis=(1, 2))
        cross = np.sum(p[..., 0] * q[..., 1] - p[..., 1] * q[..., 0], axis=1)
        return np.arctan2(cross, dot)

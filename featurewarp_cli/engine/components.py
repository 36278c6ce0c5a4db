"""How each feature component may move: a similarity whose scale and rotation are solved.

In the exact formulation every node of a component's feature quads moves by one
similarity ``x = A_c X + t_c`` with ``A_c = [[a, -b], [b, a]]``. The translation
``t_c`` is a shared unknown of the linear system (or, where the component is cut
by the frame, fixed by the border condition); ``(a, b)`` -- scale and rotation --
are unknowns of the same least squares, pulled towards the preset's ``lambda R``
by a prior (Wang et al. 2008, "Optimized scale-and-stretch", does this per quad).

Border conditions
-----------------
A node that the border holds in x (or y) gives its component one linear
equation in ``(a, b, t)``. The first such node of a component fixes ``t_x`` in
terms of ``(a, b)``; every further one is an equation on ``(a, b)`` alone:
``a (X_i - X_0) - b (Y_i - Y_0) = q_i - q_0`` (for y:
``b (X_i - X_0) + a (Y_i - Y_0) = q_i - q_0``). So a component cut by a side that
slides keeps b = 0 (no rotation) and slides along the side with its cut edge on
it; one cut by two opposite sides takes the scale those sides impose; one held
by pins that no similarity satisfies (an arc's curved border) is left untied,
with soft constraints only. What remains of ``(a, b)`` is an affine set
``p0 + N eta`` with 0, 1 or 2 directions.

Solving for eta
---------------
Node positions are linear in eta: ``x(eta) = x0 + Phi eta``, where ``x0`` is the
least-squares solution with every component at ``p0`` and column ``Phi_j`` the
solution of the homogeneous problem for a unit step of eta_j. The data energy is
then a quadratic ``|r0 + R eta|^2`` whose Hessian ``R^T R`` depends on the grid,
the weights and the ties only (not on W): it is computed once (one batched solve
of all columns) and reused for every warp. With the prior this is a small dense
system in eta; one more solve places the nodes.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

#: Pins that a similarity fits with a larger RMS residual (px) leave a component untied.
PIN_TOLERANCE = 0.01
#: Components whose scale and rotation are unknowns (similarity mode): the largest this many;
#: the others keep the preset's lambda R. Each costs two back-substitutions per axis when the
#: scale problem is set up, so a mask of 2 500 specks took over 120 s at 1 MP; a speck's own
#: scale changes the picture little.
MAX_FREE_SCALES = 64
#: Columns of Phi solved at once.
_BATCH = 16
#: The node responses to each eta (used by quick solves) are kept up to this many numbers per axis.
_KEPT_RESPONSES = 2_500_000


@dataclass
class Ties:
    """The parametrization of the tied components for one warp.

    Attributes
    ----------
    node_component : (N,) int ndarray
        Component of each node of a feature quad, -1 elsewhere (tied or not).
    tied : (n_components,) bool ndarray
        Components that move as one similarity (the others keep soft constraints).
    pin : (n_components, 2) int ndarray
        Per axis, the node whose border condition fixes the translation, or -1
        when the translation along that axis is a free shared unknown.
    base : (n_components, 2) ndarray
        (a, b) at eta = 0.
    basis : (n_components, 2, 2) ndarray
        Directions of (a, b) that stay free (columns; zero columns unused).
    free : (n_components,) int ndarray
        How many directions are free (0, 1 or 2).
    unpinned : (n_components,) bool ndarray
        Components held by pins that no similarity satisfies (an arc's curved sides) whose
        nodes were let go of their border conditions, so that they keep their shape.
    grown : (n_components,) bool ndarray or None
        Components scaled past the edges that cut them (``FeatureWarper(grow_past_edge=True)``,
        :mod:`featurewarp_cli.engine.grow`): their nodes are let go of the border and their
        pins hold the translation where the grown similarity puts them.
    """

    node_component: np.ndarray
    tied: np.ndarray
    pin: np.ndarray
    base: np.ndarray
    basis: np.ndarray
    free: np.ndarray
    unpinned: np.ndarray
    grown: np.ndarray | None = None

    def decisions(self) -> tuple[np.ndarray, np.ndarray]:
        """(consistent, unpinned): what :func:`parametrize` decided from W, to keep (``decided``)."""
        return self.tied & ~self.unpinned, self.unpinned.copy()

    def let_go(self, axis: int) -> np.ndarray:
        """(N,) bool: nodes whose border condition along ``axis`` no longer holds: those of
        unpinned components (their translation along it is free) and of grown ones (placed
        past their cut edges)."""
        comp = self.node_component
        on = comp >= 0
        out = np.zeros(on.shape, bool)
        c = comp[on]
        out[on] = self.tied[c] & ((self.pin[c, axis] < 0) | (self.grown is not None and self.grown[c]))
        return out

    def unknown_ties(self, axis: int) -> np.ndarray:
        """(N,) component whose shared translation unknown a node takes along ``axis``, or -1."""
        comp = self.node_component
        on = comp >= 0
        share = np.zeros(on.shape, bool)
        share[on] = self.tied[comp[on]] & (self.pin[comp[on], axis] < 0)
        return np.where(share, comp, -1)

    def held(self, axis: int) -> np.ndarray:
        """(N,) bool: nodes of tied components whose translation along ``axis`` the border fixes."""
        comp = self.node_component
        on = comp >= 0
        held = np.zeros(on.shape, bool)
        held[on] = self.tied[comp[on]] & (self.pin[comp[on], axis] >= 0)
        return held

    def placed(self, axis: int) -> np.ndarray:
        """(N,) bool: nodes whose coordinate along ``axis`` the component's similarity sets
        (up to the shared translation, where it is free)."""
        comp = self.node_component
        on = comp >= 0
        placed = np.zeros(on.shape, bool)
        placed[on] = self.tied[comp[on]]
        return placed

    def project(self, ab: np.ndarray) -> np.ndarray:
        """The nearest admissible (a, b) to each of ``ab`` ((C, 2)): base + N N^T (ab - base)."""
        return self.base + np.einsum("cij,ckj,ck->ci", self.basis, self.basis, ab - self.base)

    def columns(self) -> tuple[np.ndarray, np.ndarray]:
        """(component, direction) of each entry of eta."""
        comp, k = np.nonzero(np.arange(2)[None, :] < np.where(self.tied, self.free, 0)[:, None])
        return comp, k

    def border_fixed(self, fixed_x: np.ndarray, fixed_y: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The border conditions in force: the grid's (``fixed_x``, ``fixed_y``), less those of
        unpinned components' nodes."""
        return fixed_x & ~self.let_go(0), fixed_y & ~self.let_go(1)

    def window_ties(self) -> np.ndarray:
        """Component whose shared translation a node takes in both axes, or -1 (for window passes)."""
        x, y = self.unknown_ties(0), self.unknown_ties(1)
        return np.where(x == y, x, -1)

    def window_fixed(self, fixed_x: np.ndarray, fixed_y: np.ndarray) -> np.ndarray:
        """Nodes a window pass may not move: held in either axis, or tied in one axis only."""
        x, y = self.unknown_ties(0), self.unknown_ties(1)
        held_x, held_y = self.border_fixed(fixed_x, fixed_y)
        return held_x | held_y | self.held(0) | self.held(1) | (x != y)

    def key(self) -> bytes:
        """What the Hessian of eta depends on besides the grid and weights."""
        arrays = (self.tied, self.pin, self.basis, self.unpinned) + (() if self.grown is None else (self.grown,))
        return b"".join(np.ascontiguousarray(a).tobytes() for a in arrays)


def as_ab(maps: np.ndarray) -> np.ndarray:
    """(a, b) of the similarity closest to each 2x2 map: (C, 2)."""
    return np.stack([(maps[:, 0, 0] + maps[:, 1, 1]) / 2.0, (maps[:, 1, 0] - maps[:, 0, 1]) / 2.0], axis=1)


def as_maps(ab: np.ndarray) -> np.ndarray:
    """The matrices [[a, -b], [b, a]]: (..., 2, 2)."""
    a, b = ab[..., 0], ab[..., 1]
    return np.stack([np.stack([a, -b], -1), np.stack([b, a], -1)], -2)


def _pin_rows(nodes, fixed, target, node_component, n, axis):
    """Per component: the first node held along ``axis`` and the normal equations
    (2x2 matrix, right-hand side, sum of squared right-hand sides, row count) of its
    further held nodes' equations on (a, b)."""
    held = np.flatnonzero(fixed & (node_component >= 0))
    comp = node_component[held]
    first = np.full(n, -1)
    first[comp[::-1]] = held[::-1]                       # the lowest-numbered held node
    ref = first[comp]
    dx, dy = (nodes[held] - nodes[ref]).T
    rows = np.stack([dx, -dy], 1) if axis == 0 else np.stack([dy, dx], 1)
    rhs = target[held, axis] - target[ref, axis]
    gram = np.zeros((n, 2, 2))
    for i in range(2):
        for j in range(2):
            gram[:, i, j] = np.bincount(comp, rows[:, i] * rows[:, j], minlength=n)
    moment = np.stack([np.bincount(comp, rows[:, i] * rhs, minlength=n) for i in range(2)], 1)
    return first, gram, moment, np.bincount(comp, rhs * rhs, minlength=n), np.bincount(comp, minlength=n)


def parametrize(nodes, fixed_x, fixed_y, target, node_component, n_components, prior, solve_scale,
                unpin: bool = False, decided=None):
    """The :class:`Ties` of the components under this warp's border conditions.

    Parameters
    ----------
    nodes : (N, 2) ndarray
        Source positions.
    fixed_x, fixed_y : (N,) bool ndarray
        Coordinates the border holds.
    target : (N, 2) ndarray
        Where the border holds them (W at the nodes).
    node_component : (N,) int ndarray
        Component of each feature-quad node, -1 elsewhere.
    n_components : int
    prior : (n_components, 2) ndarray
        The preset's (a, b) per component (lambda R).
    solve_scale : bool
        Similarity mode: (a, b) are unknowns. False (rigid): (a, b) are the prior's, turned
        to the rotation nearest it that the pins allow (a feature cut by a border that W
        leaves in place keeps that border's rotation), at the prior's size.
    unpin : bool
        A component whose pins no similarity satisfies is let go of them and tied like an
        interior one (its cut edge leaves W's border a little); False: it is left untied,
        with soft constraints, and the border stays exactly at W.
    decided : tuple of two (n_components,) bool ndarray, optional
        (consistent, unpinned) to take instead of deciding them from W: a drag's update keeps
        its last solve's (:meth:`Ties.decisions`), so its systems are not factored anew when
        a component's pins turn satisfiable or not mid-drag (a coin near the border on the
        coins photo: a 170 ms update).
    """
    n = n_components
    first_x, gx, mx, sx, cx = _pin_rows(nodes, fixed_x, target, node_component, n, 0)
    first_y, gy, my, sy, cy = _pin_rows(nodes, fixed_y, target, node_component, n, 1)
    gram, moment, squares, count = gx + gy, mx + my, sx + sy, np.maximum(cx + cy, 1)
    values, vectors = np.linalg.eigh(gram)                  # ascending
    scale = np.maximum(values[:, 1:], 1e-12)
    stiff = values > 1e-9 * scale                           # constrained directions
    coords = np.einsum("cij,ci->cj", vectors, moment)
    inverse = np.where(stiff, 1.0 / np.where(stiff, values, 1.0), 0.0)
    determined = np.einsum("cij,cj->ci", vectors, inverse * coords)
    loose = vectors * ~stiff[:, None, :]                     # columns spanning the free directions
    if solve_scale:
        base = determined + np.einsum("cij,ckj,ck->ci", loose, loose, prior - determined)
        free = np.count_nonzero(~stiff, axis=1)
        basis = np.where(stiff[:, None, :], 0.0, vectors)
        order = np.argsort(stiff, axis=1, kind="stable")     # free directions first
        basis = np.take_along_axis(basis, order[:, None, :], axis=2)
    else:        # rigid: the rotation the pins allow nearest the prior's, at the prior's size
        nearest = determined + np.einsum("cij,ckj,ck->ci", loose, loose, prior - determined)
        size, wanted = np.hypot(*nearest.T), np.hypot(*prior.T)
        base = np.where((size > 0)[:, None], nearest * (wanted / np.where(size > 0, size, 1.0))[:, None], prior)
        free, basis = np.zeros(n, int), np.zeros((n, 2, 2))
    residual = squares - 2.0 * (base * moment).sum(1) + np.einsum("ci,cij,cj->c", base, gram, base)
    consistent = np.sqrt(np.maximum(residual, 0.0) / count) <= PIN_TOLERANCE
    pin = np.stack([first_x, first_y], 1)
    unpinned = ~consistent & unpin
    if decided is not None:
        consistent, unpinned = (np.array(a, bool) for a in decided)
    if unpinned.any():
        comp = node_component
        let_go = (comp >= 0) & unpinned[np.maximum(comp, 0)]
        if not ((fixed_x & ~let_go).any() and (fixed_y & ~let_go).any()):
            unpinned[:] = False           # nothing would hold the grid in place: stay untied
    if unpinned.any():
        pin[unpinned] = -1
        base[unpinned] = prior[unpinned]
        if solve_scale:
            free[unpinned] = 2
            basis[unpinned] = np.eye(2)
    fixed_scale = ~largest(node_component, n, MAX_FREE_SCALES)
    free[fixed_scale], basis[fixed_scale] = 0, 0.0          # they keep the preset's lambda R
    return Ties(node_component, consistent | unpinned, pin, base, basis, free, unpinned)


def largest(node_component: np.ndarray, n: int, count: int) -> np.ndarray:
    """(n,) bool: the ``count`` components with the most nodes (ties: the lower index)."""
    sizes = np.bincount(node_component[node_component >= 0], minlength=n)
    keep = np.zeros(n, bool)
    keep[np.lexsort((np.arange(n), -sizes))[:count]] = True
    return keep


def placement(ties: Ties, nodes: np.ndarray, pins: np.ndarray, ab: np.ndarray) -> np.ndarray:
    """Offsets of the tied components' nodes for similarities ``ab`` ((C, 2, ...) ndarray).

    Along an axis with a free translation the offset is ``A_c X`` (the shared unknown
    adds t); along one the border fixes, it is the whole position
    ``A_c (X - X_pin) + q_pin`` (``pins``: (N, 2) positions q, 0 for a homogeneous step).

    Returns
    -------
    (N, 2, ...) ndarray
        Zero on nodes that are not tied.
    """
    comp = ties.node_component
    on = np.flatnonzero((comp >= 0) & ties.tied[np.maximum(comp, 0)])
    c = comp[on]
    out = np.zeros((nodes.shape[0], 2) + ab.shape[2:])
    a, b = ab[c, 0], ab[c, 1]
    extra = (slice(None),) + (None,) * (ab.ndim - 2)
    for axis in range(2):
        pin = ties.pin[c, axis]
        anchored = pin >= 0
        origin = np.where(anchored[:, None], nodes[np.maximum(pin, 0)], 0.0)
        x, y = (nodes[on] - origin).T
        if axis == 0:
            value = a * x[extra] - b * y[extra]
        else:
            value = b * x[extra] + a * y[extra]
        value = value + np.where(anchored, pins[np.maximum(pin, 0), axis], 0.0)[extra]
        out[on, axis] = value
    return out


def prior_weights(features, spacing, scale_prior: float) -> np.ndarray:
    """Weight of each component's prior on (a, b): (C,).

    A component of n feature quads holding (a, b) with its own shape equations at
    weight w_F spends ``w_F^2 n 2 (sx^2 + sy^2) |delta (a, b)|^2`` per change of
    (a, b); the prior costs ``scale_prior^2`` times that.
    """
    sx, sy = spacing
    own = features.is_feature
    w2 = np.bincount(features.component[own], features.weight[own] ** 2, minlength=features.n_components)
    return scale_prior ** 2 * w2 * 2.0 * (sx * sx + sy * sy)


def _column_table(ties: Ties):
    """Per component and direction, the column of eta (or -1): (C, 2) int."""
    comp, k = ties.columns()
    table = np.full((ties.tied.size, 2), -1)
    table[comp, k] = np.arange(comp.size)
    return table


def _directions(ties: Ties, comp: np.ndarray, k: np.ndarray) -> np.ndarray:
    """(a, b) direction of eta's column (comp, k): (n, 2)."""
    return ties.basis[comp, :, k]


def step_fields(ties: Ties, grid, features, nodes: np.ndarray):
    """G and B of every column of eta, as sparse (2N, J) matrices (rows: x block, then y block).

    G_j: the offsets a unit step of eta_j gives the tied nodes (the homogeneous
    :func:`placement`); B_j = A^T W^2 h_j: the right-hand side of the edge targets
    ``dM_j e`` it gives its component's constrained quads.
    """
    import scipy.sparse as sp

    n_nodes = nodes.shape[0]
    table = _column_table(ties)
    n_cols = int(table.max()) + 1 if table.size else 0
    comp = ties.node_component
    # G: each tied node, for each free direction of its component.
    node, k = np.nonzero((comp >= 0)[:, None] & (table[np.maximum(comp, 0)] >= 0))
    c = comp[node]
    col = table[c, k]
    da, db = _directions(ties, c, k).T
    rows, vals = [], []
    for axis in range(2):
        pin = ties.pin[c, axis]
        origin = np.where((pin >= 0)[:, None], nodes[np.maximum(pin, 0)], 0.0)
        x, y = (nodes[node] - origin).T
        rows.append(axis * n_nodes + node)
        vals.append(da * x - db * y if axis == 0 else db * x + da * y)
    g = sp.csc_matrix((np.concatenate(vals), (np.concatenate(rows), np.tile(col, 2))), shape=(2 * n_nodes, n_cols))
    # B: each corner of each constrained quad of a tied component, for each free direction.
    sx, sy = grid.spacing
    corner_vectors = np.array([[-sx, -sy], [sx, -sy], [sx, sy], [-sx, sy]])
    quad_comp = features.component
    constrained = (quad_comp >= 0) & ties.tied[np.maximum(quad_comp, 0)]
    quad, k = np.nonzero(constrained[:, None] & (table[np.maximum(quad_comp, 0)] >= 0))
    c = quad_comp[quad]
    col = table[c, k]
    da, db = _directions(ties, c, k).T
    w2 = features.weight[quad] ** 2
    corners = grid.quads()[quad]                               # (n, 4)
    vx, vy = corner_vectors[:, 0][None, :], corner_vectors[:, 1][None, :]
    bx = w2[:, None] * (da[:, None] * vx - db[:, None] * vy)
    by = w2[:, None] * (db[:, None] * vx + da[:, None] * vy)
    cols = np.repeat(col, 4)
    b = sp.csc_matrix((np.concatenate([bx.ravel(), by.ravel()]),
                       (np.concatenate([corners.ravel(), n_nodes + corners.ravel()]), np.tile(cols, 2))),
                      shape=(2 * n_nodes, n_cols))
    return g, b


def target_moments(ties: Ties, features, spacing) -> np.ndarray:
    """Per component, sum over its constrained quads of w^2 * 2 (sx^2 + sy^2): (C,).

    ``<h_j, h_k>`` of two columns of one component is this times the dot product
    of their (a, b) directions (a similarity's image of an edge has the edge's
    length times |(a, b)|)."""
    sx, sy = spacing
    on = features.component >= 0
    return np.bincount(features.component[on], features.weight[on] ** 2,
                       minlength=ties.tied.size) * 2.0 * (sx * sx + sy * sy)


class ScaleSolver:
    """The small dense problem in eta: Hessian of the data energy, built once.

    Parameters
    ----------
    ties : Ties
    grid : Grid
    features : Features
    matrix : sparse matrix
        The normal matrix L (N, N), SciPy sparse.
    systems : AxisSystems
        The factored reduced systems for x and y under these ties.
    """

    def __init__(self, ties: Ties, grid, features, matrix, systems):
        n_nodes = grid.n_nodes
        self.ties = ties
        self.comp, self.k = ties.columns()
        self.n_columns = n = self.comp.size
        g, b = step_fields(ties, grid, features, grid.nodes())
        lg = [matrix @ g[axis * n_nodes:(axis + 1) * n_nodes] for axis in range(2)]
        self.d = [(lg[axis] - b[axis * n_nodes:(axis + 1) * n_nodes]).tocsc() for axis in range(2)]
        self.g, self.b = g, b
        hessian = np.zeros((n, n))
        keep = n_nodes * n <= _KEPT_RESPONSES
        self.responses = [np.empty((n_nodes, n)) for _ in range(2)] if keep else None
        for start in range(0, n, _BATCH):
            stop = min(n, start + _BATCH)
            for axis, system in enumerate((systems.x, systems.y)):
                rows = slice(axis * n_nodes, (axis + 1) * n_nodes)
                phi = system.solve(b[rows, start:stop], g[rows, start:stop])
                hessian[start:stop] += (self.d[axis].T @ phi).T
                if keep:
                    self.responses[axis][:, start:stop] = phi
        hessian -= (b.T @ g).toarray()
        moments = target_moments(ties, features, grid.spacing)
        directions = _directions(ties, self.comp, self.k)
        same = self.comp[:, None] == self.comp[None, :]
        hessian += np.where(same, moments[self.comp][:, None] * (directions @ directions.T), 0.0)
        self.hessian = 0.5 * (hessian + hessian.T)
        self.directions = directions

    def gradient(self, x0: np.ndarray, rhs0: np.ndarray, edges0: np.ndarray, features, spacing) -> np.ndarray:
        """Half the data energy's gradient in eta at eta = 0: (J,).

        ``x0``: the solution at eta = 0 (N, 2); ``rhs0``: its A^T W^2 d (N, 2);
        ``edges0``: its edge targets d (K, 4, 2); ``spacing``: the grid's cell (sx, sy).
        """
        grad = self.d[0].T @ x0[:, 0] + self.d[1].T @ x0[:, 1] - self.g.T @ rhs0.T.ravel()
        # <d0, h_j>: per quad, sum_e d0(e).e and d0(e).(J e) (J: a quarter turn).
        sx, sy = spacing
        unit_edges = np.array([[sx, 0.0], [0.0, sy], [-sx, 0.0], [0.0, -sy]])
        turned = np.stack([-unit_edges[:, 1], unit_edges[:, 0]], axis=1)
        on = features.component >= 0
        w2 = features.weight[on] ** 2
        along = w2 * np.einsum("kec,ec->k", edges0[on], unit_edges)
        across = w2 * np.einsum("kec,ec->k", edges0[on], turned)
        n = self.ties.tied.size
        sums = np.stack([np.bincount(features.component[on], along, minlength=n),
                         np.bincount(features.component[on], across, minlength=n)], axis=1)
        return grad + (sums[self.comp] * self.directions).sum(axis=1)

    def solve(self, base: np.ndarray, gradient: np.ndarray, prior: np.ndarray, weights: np.ndarray) -> np.ndarray:
        """(a, b) per component after the step in eta that minimises data energy plus prior.

        Parameters
        ----------
        base : (C, 2) ndarray
            (a, b) at eta = 0 (this warp's :attr:`Ties.base`).
        gradient : (J,) ndarray
            From :meth:`gradient`.
        prior : (C, 2) ndarray
            The preset's (a, b) per component.
        weights : (C,) ndarray
            The prior's weight per component (:func:`prior_weights`).

        Returns
        -------
        (C, 2) ndarray
        """
        ab = base.copy()
        if not self.n_columns:
            return ab
        same = self.comp[:, None] == self.comp[None, :]
        lhs = self.hessian + np.where(same, weights[self.comp][:, None] * (self.directions @ self.directions.T), 0.0)
        pull = weights[self.comp] * ((base - prior)[self.comp] * self.directions).sum(axis=1)
        lhs[np.diag_indices_from(lhs)] += 1e-12 * max(1.0, float(np.abs(np.diag(lhs)).max()))
        eta = np.linalg.solve(lhs, -(gradient + pull))
        np.add.at(ab, self.comp, eta[:, None] * self.directions)
        self.eta = eta
        return ab

    def moved(self, x0: np.ndarray) -> np.ndarray | None:
        """The nodes after the last :meth:`solve`'s step from the solution ``x0`` at eta = 0,
        without a solve (x is affine in eta), or None when the responses were too many to keep."""
        if self.responses is None or not self.n_columns:
            return None
        return x0 + np.stack([self.responses[axis] @ self.eta for axis in range(2)], axis=1)

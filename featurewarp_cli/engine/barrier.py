"""The area barrier and the Newton solver that converges the fold guard's results.

Where the least-squares solution x* of a solve folds or crushes triangles, the guard's result
is a local minimum of one energy, the solve's least-squares energy plus a barrier on the
triangles' areas::

    Phi(x) = 1/2 (x - x*)' H (x - x*)  +  sum_t kappa_t b(a_t(x) / f_t)

- ``H``: the solve's normal matrix (the paper's terms, the ties, the border rules), x* its
  minimiser, so the first term is the least-squares energy up to a constant;
- ``a_t``: the signed area of triangle t; ``f_t = SAFE_FRACTION`` times its area under W;
- ``b``: the clamped log barrier of Incremental Potential Contact (Li et al. 2020, eq. 6),
  ``b(r) = -(r - 1)^2 ln r`` for r < 1 and 0 above: exactly zero where a triangle keeps its
  safe fraction (twice differentiable there), unbounded as its area goes to zero;
- ``kappa_t = STIFFNESS`` times the least-squares stiffness at t's corners times
  ``f_t^2 / (2 |grad a_t|^2)`` under W: the barrier's curvature against the least-squares
  energy's is ``STIFFNESS b''(r) / 2`` at any cell size; a function of the grid, the weights
  and W alone.

Where x* keeps every triangle above its safe fraction, Phi's minimum is x* itself (where no
triangle is below its floor at x either and the straight step to x* folds none, the solver
takes that step and stops: further steps would only chase rounding). The solver
(:func:`converge`) takes Newton steps from an injective start, each no longer than the first
fold along it allows (:func:`injectivity.max_step`), and stops when the Newton decrement is
below ``TOLERANCE`` times Phi: the result no longer depends on the start or on the path, so a
one-ulp change of the input moves it by rounding only. The Newton systems are solved by
conjugate gradients preconditioned with the factorization the solve already has (one
back-substitution per iteration) and a small factorization of the barrier's active nodes (a
symmetric two-level preconditioner); where the barrier touches few nodes, exactly, by the
Woodbury identity on those nodes (back-substitutions of unit forces, kept for the run, and a
dense system of their size), with the exact Hessian wherever that system is positive definite.
Far from the minimum each triangle's barrier Hessian is bounded by a positive semi-definite
one (the area Hessian's negative part dropped; partly kept, :data:`_PARTIAL`, after a step the
bound made too short); once a full step is taken with a decrement below ``_EXACT_BELOW`` of
Phi, the exact Hessian (quadratic convergence), back to the bound wherever the exact system is
not positive definite. A full step of the bound by conjugate gradients is doubled while the
energy falls (:func:`_extended`): the bound over-estimates the curvature along the valleys.

Where the start folds (the least-squares solution in the guard's window around its folds), the
same solver minimises Phi with b continued below a ratio by its second-order Taylor polynomial
there (``below``; finite for folded triangles, convex in the ratio: the quadratic extrapolation
of the log in Ben-Tal and Zibulevsky's penalty/barrier methods, SIAM J. Optim. 7, 1997): one
energy converged from the folded start, no first fold-free iterate. Where its minimum keeps
every triangle at that ratio or above, Phi and the continued energy agree around it, so it is
a minimum of Phi itself.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from . import injectivity
from .grid import signed_areas
from .inverse_rows import MAX_NODES as _DIRECT_NODES, InverseRows, cholesky_solve

#: Fraction of its area under W below which the barrier pushes a triangle open (f_t above).
#: Lower lets features push the background thinner before it resists.
SAFE_FRACTION = 0.05
#: The barrier's weight against the least-squares energy (kappa_t above), the same at every
#: cell size. At 300 the thinnest triangle of the hard swirls and bulges keeps 40-70 % of its
#: safe fraction (at 1000, 60-83 %, with up to twice the Newton steps; at 100, 20-54 %); lower
#: lets triangles be crushed towards zero (creases).
STIFFNESS = 300.0
#: Converged when the Newton decrement is below this fraction of Phi. Looser is faster and
#: lets a one-ulp change of the input move the result by more.
TOLERANCE = 1e-12
#: Newton steps at most (the report says when a solve stopped there). A swirl's centre that
#: tied features ring untwists slowly (the astronaut's head, patch and shuttle under swirl 180 at
#: 1 MP, cell 4: 109 + 62 steps; 201 + 61 without :data:`_PARTIAL`); stopped at 100 or 400, one
#: ulp moved such results up to 0.09 px (short of a minimum, the path decides). Most take < 100.
MAX_STEPS = 600
#: Exact barrier Hessians (not projected) once a full step was taken and the decrement fell
#: below this fraction of Phi: quadratic convergence near the minimum.
_EXACT_BELOW = 1e-5
#: Newton systems whose barrier touches at most _DIRECT_NODES nodes (:mod:`inverse_rows`),
#: whose dense work ((2 nodes)^3) is at most _DIRECT_WORK times the nodes of the grid or window
#: and whose unit-force back-substitutions (one a node) take at most _DIRECT_SOLVES
#: node-columns, are solved exactly (Woodbury, :func:`_direct_direction`); beyond, conjugate
#: gradients cost less.
_DIRECT_WORK, _DIRECT_SOLVES = 2000, 2e7
#: How far along a bound step's ray :func:`_extended` looks for the first fold (in steps).
_FAR = 1024.0
#: Once :func:`_extended` lengthened a step (the bound over-estimates the curvature), the CG
#: directions far from the minimum keep this fraction of the area Hessian's part the bound drops
#: while their system stays positive definite. 1 MP swirl 180, cell 4: 262 Newton steps, 6 470
#: back-substitutions with the bound; 171, 4 002 at 0.9 (0.7: 15 % fewer; 1, exact: 20 %).
_PARTIAL = 0.9
#: Conjugate-gradient tolerance (on r.z, relative) and iterations at most, far from and near the
#: minimum. Near it (the exact Hessian), a system that needs more is nearly singular or indefinite
#: in a direction CG has not met yet: the bound instead (12 MP fish, helmet: 96 solves on one).
_CG_FAR, _CG_NEAR = (1e-2, 100), (1e-6, 20)
#: Second derivatives of a triangle's signed area in its corners' coordinates
#: (x0, y0, x1, y1, x2, y2): constant, indefinite.
_AREA_HESSIAN = np.zeros((6, 6))
for _i in range(3):
    for _sign, _j in ((0.5, (_i + 1) % 3), (-0.5, (_i + 2) % 3)):
        _AREA_HESSIAN[2 * _i, 2 * _j + 1] += _sign
        _AREA_HESSIAN[2 * _j + 1, 2 * _i] += _sign


_values, _vectors = np.linalg.eigh(_AREA_HESSIAN)
#: -(its negative part): the area Hessian's term in b's Hessian is b' times it, b' < 0, so
#: b' * _AREA_HESSIAN's positive semi-definite part is -b' * this (a constant).
_AREA_HESSIAN_NEGATIVE = (_vectors * np.maximum(-_values, 0.0)) @ _vectors.T
#: Its positive part: _AREA_HESSIAN = _AREA_HESSIAN_POSITIVE - _AREA_HESSIAN_NEGATIVE.
_AREA_HESSIAN_POSITIVE = (_vectors * np.maximum(_values, 0.0)) @ _vectors.T


@dataclass
class Convergence:
    """How :func:`converge` ended: Newton ``steps`` taken and whether it ``converged``."""

    steps: int = 0
    converged: bool = True


def clamped_log(ratio: np.ndarray, safe: float = 1.0, below: float = 0.0) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """IPC's clamped log barrier b(r) = -(r - s)^2 ln(r / s) (0 for r >= s, ``s = safe``) and
    its first two derivatives, elementwise. ``ratio`` must be positive, except with ``below``
    > 0: below that ratio b is continued by its second-order Taylor polynomial there (finite for
    any ratio, a folded triangle's too: :func:`converge`). The rigid map's barrier
    (:mod:`rigid_energy`, s = its SAFE_AREA) is the same function.

    >>> [float(v[0]) for v in clamped_log(np.array([1.0]))]
    [0.0, 0.0, 0.0]
    """
    ratio = np.asarray(ratio, dtype=np.float64)
    if below > 0:
        value, first, second = clamped_log(np.maximum(ratio, below), safe)
        gap = np.minimum(ratio - below, 0.0)
        return value + (first + 0.5 * second * gap) * gap, first + second * gap, second
    value, first, second = (np.zeros_like(ratio) for _ in range(3))
    on = ratio < safe
    r = ratio[on]
    log, gap = np.log(r / safe), r - safe
    value[on] = -gap * gap * log
    first[on] = -2.0 * gap * log - gap * gap / r
    second[on] = -2.0 * log - 4.0 * gap / r + gap * gap / (r * r)
    return value, first, second


def weights(warped: np.ndarray, triangles: np.ndarray, stiffness: np.ndarray, floor: np.ndarray) -> np.ndarray:
    """kappa_t per triangle: :data:`STIFFNESS` times the least-squares stiffness at its corners
    (``stiffness``: the normal matrix's diagonal per node) times f_t^2 / (2 |grad a_t|^2) under
    W, so that the barrier's Hessian against the least-squares one, STIFFNESS b''(r) / 2, is
    the same at every cell size and for every triangle."""
    return STIFFNESS * injectivity.penalty_stiffness(warped, triangles, stiffness) * floor * floor


def hessians(points, triangles, ratio, floor, kappa, exact: float, below: float = 0.0) -> np.ndarray:
    """(K, 6, 6) Hessians of the barrier terms of ``triangles`` (corner coordinates interleaved):
    exact (``exact`` 1 or True), the bound (0 or False: the area Hessian's term projected to
    positive semi-definite), or the part the bound drops kept by the fraction ``exact``; the
    barrier continued below ``below`` (:func:`clamped_log`), whose folded triangles get no
    area-Hessian term but in the exact Hessians (Gauss-Newton: the bound's grows with the fold's
    depth, and took the hard 12 MP swirl's window 28 steps instead of 17)."""
    _, first, second = clamped_log(ratio, below=below)
    grads = injectivity.area_gradients(points, triangles).reshape(-1, 6)
    area = -_AREA_HESSIAN if exact == 1 else _AREA_HESSIAN_NEGATIVE - float(exact) * _AREA_HESSIAN_POSITIVE
    area_term = (-kappa * first / floor)[:, None, None] * area
    if below and exact != 1:
        area_term[ratio <= 0] = 0.0
    return (kappa * second / floor ** 2)[:, None, None] * grads[:, :, None] * grads[:, None, :] + area_term


def _dot(matrix, points: np.ndarray) -> np.ndarray:
    """``matrix.dot(points)`` for a CSR ``matrix`` and (N, k) ``points``, one column at a time:
    SciPy's product with several vectors at once took 1.6 times as long (0.71 against 0.43 ms
    on the 12 MP grid, the Newton steps' main product); each entry is the same sum in the same
    order, so the same bits."""
    if getattr(matrix, "format", None) != "csr" or points.ndim != 2 or points.dtype != np.float64:
        return matrix.dot(points)
    out = np.empty(points.shape)
    for k in range(points.shape[1]):
        out[:, k] = matrix @ np.ascontiguousarray(points[:, k])
    return out


def _local_solver(between, unknowns: np.ndarray, triangles: np.ndarray, blocks: np.ndarray):
    """``r -> z``: the Newton system restricted to the solve's unknowns that the corners of
    ``triangles`` (the barrier's active ones) take, everything else held, solved exactly (one
    small factorization). ``unknowns`` ((2, N) int, -1 held) is the solve's numbering per axis:
    a tied feature with a corner among them enters with its shared translation (all its nodes
    move with it), so a feature pressed against crushed triangles is preconditioned by the
    barrier's stiffness too, not by the least-squares energy alone (which is 1e11 times softer
    there: CG then needed its full 100 iterations and still pointed uphill). ``between(axis,
    ids)`` gives the least-squares part, the lower triangle of the reduced matrix between those
    unknowns (:attr:`InverseRows.between`); only lower triangles are assembled and factored
    (whole symmetric matrices, then their lower triangles, took 40 % longer). The matrix
    is a principal submatrix of the reduced Newton
    system: where it is not positive definite, neither is the whole."""
    import scipy.sparse as sp                 # SciPy: imported by the solves that need it

    from .solver import spd_solver

    n = unknowns.shape[1]
    on = np.zeros(n, bool)
    on[triangles.ravel()] = True
    column, size = np.full((n, 2), -1), 0     # the local unknown of each node's x and y
    rows, cols, data, same = [], [], [], np.array_equal(unknowns[0], unknowns[1])
    for axis, unknown in enumerate(unknowns):
        ids = np.unique(unknown[on & (unknown >= 0)])
        lookup = np.full(int(unknown.max()) + 2, -1)
        lookup[ids] = size + np.arange(ids.size)
        column[:, axis] = np.where(unknown >= 0, lookup[unknown], -1)
        if ids.size and not (axis and same):  # one system for both axes: the same block
            block = between(axis, ids)
        if ids.size:
            rows.append(block.row + size)
            cols.append(block.col + size)
            data.append(block.data)
        size += ids.size
    if size == 0:
        return lambda r: np.zeros_like(r)
    mapped = [np.flatnonzero(column[:, axis] >= 0) for axis in range(2)]
    dof = np.take(column, triangles, axis=0).reshape(-1, 6)
    dof_rows, dof_cols = np.broadcast_to(dof[:, :, None], blocks.shape), np.broadcast_to(dof[:, None, :], blocks.shape)
    keep = (dof_cols >= 0) & (dof_rows >= dof_cols)          # the lower triangle (a tied pair's both)
    lower = sp.csc_matrix((np.concatenate(data + [blocks[keep]]),
                           (np.concatenate(rows + [dof_rows[keep]]), np.concatenate(cols + [dof_cols[keep]]))),
                          shape=(size, size))
    solve = spd_solver(lower, lower=True)

    at = [column[mapped[axis], axis] for axis in range(2)]     # the local unknown of each mapped node

    def local(r):
        rhs = np.bincount(at[0], r[mapped[0], 0], minlength=size) + np.bincount(at[1], r[mapped[1], 1], minlength=size)
        moved = np.asarray(solve(rhs)).reshape(-1)
        z = np.zeros_like(r)
        for axis in range(2):
            z[mapped[axis], axis] = moved[at[axis]]
        return z
    return local


def summed_between(normal, unknowns: np.ndarray):
    """``between(axis, ids)`` for :func:`_local_solver` where no factored system has it: the lower
    triangle of P' H P between the unknowns ``ids`` (sorted, unique) of ``unknowns[axis]``,
    ``normal``'s rows summed over their nodes."""
    import scipy.sparse as sp                 # SciPy: imported by the solves that need it

    def between(axis, ids):
        unknown = unknowns[axis]
        nodes = np.flatnonzero(np.isin(unknown, ids))
        block = normal[nodes][:, nodes].tocoo()
        at = np.searchsorted(ids, unknown[nodes])
        return sp.tril(sp.csc_matrix((block.data, (at[block.row], at[block.col])), shape=(ids.size, ids.size)),
                       format="coo")
    return between


def _newton_direction(move, normal, unknowns, between, points, triangles, blocks, gradient, near: bool,
                      indefinite: bool = False):
    """Conjugate gradients on (H + barrier Hessian) d = -gradient, preconditioned by a local
    solve, a back-substitution of the factored H and the local solve again; (d, ok), ok False
    where the system or the preconditioner shows a direction of non-positive curvature, or
    ``near`` and CG did not converge in :data:`_CG_NEAR`'s iterations. (The local solve fails
    only where the whole system is indefinite too: its matrix is a principal submatrix.)
    ``blocks`` may be indefinite where ``near`` or ``indefinite`` (the exact or the partial
    Hessians): a preconditioner that is not positive definite is a failure too.

    ``move``: the solve's linear part (:func:`converge`'s ``linear``): every preconditioned
    residual, and so the direction, is exactly on the solve's positions. ``unknowns`` and
    ``between``: the solve's numbering per axis and its reduced matrix (:func:`_local_solver`)."""
    n = points.shape[0]
    corners = triangles.ravel()

    def product(d):
        out = _dot(normal, d)
        part = np.einsum("kij,kj->ki", blocks, np.take(d, triangles, axis=0).reshape(-1, 6)).reshape(-1, 2)
        for k in range(2):
            out[:, k] += np.bincount(corners, part[:, k], minlength=n)
        return out

    from . import cholmod                     # scikit-sparse: imported by the solves that need it

    try:
        local = _local_solver(between, unknowns, triangles, blocks)
    except cholmod.NotPositiveDefinite:
        return None, False

    def precondition(r):
        z = local(r)
        z = z + move(r - product(z))
        return z + local(r - product(z))

    residual = -gradient
    z = precondition(residual)
    direction, step = np.zeros_like(points), z.copy()
    rz = first = float((residual * z).sum())
    if first <= 0:                            # the bound's preconditioner is positive definite:
        return (None, False) if (near or indefinite) and first < 0 else (direction, True)   # a stationary point

    tolerance, steps = _CG_NEAR if near else _CG_FAR
    for _ in range(steps):
        product_step = product(step)
        curvature = float((step * product_step).sum())
        if not curvature > 0:
            return None, False
        alpha = rz / curvature
        direction += alpha * step
        residual -= alpha * product_step
        z = precondition(residual)
        rz_next = float((residual * z).sum())
        if rz_next < 0 and (near or indefinite):
            return None, False
        if rz_next <= tolerance * first:
            return direction, True
        step, rz = z + (rz_next / rz) * step, rz_next
    return (None, False) if near else (direction, True)


def _direct_direction(rows: InverseRows, move, points, triangles, blocks, gradient):
    """The Newton direction -(H + B)^-1 g exactly, by the Woodbury identity on the barrier's
    active nodes, or None where H + B is not positive definite.

    With S = H^-1 (back-substitutions of the factored system, admissible positions only), P
    the active nodes' coordinates, B = P D P' and G = P' S P = C C' (:meth:`InverseRows.factor`;
    G is singular where nodes are held or share a feature's unknown):
    (H + B)^-1 = S - S P (D - D C M^-1 C' D) P' S with M = I + C' D C, which is positive
    definite exactly when H + B is. Two back-substitutions and dense work of the active
    nodes' size; S's entries grow with the active set (:class:`InverseRows`).

    Where a triangle is nearly crushed, D is many orders above H (1e11 on the coins under
    swirl 90 at 256 px) and the identity subtracts nearly equal terms: the direction's residual
    is up to 1e-2 of the gradient there, an inexact Newton direction, and it can even point
    uphill (a one-ulp nudge of that swirl stopped on such a direction as if converged, 3.9 px
    from the un-nudged result); :func:`step_direction` then takes conjugate gradients instead."""
    import scipy.sparse as sp                 # SciPy: imported by the solves that need it

    nodes, local = np.unique(triangles, return_inverse=True)
    u = nodes.size
    dof = (2 * local.reshape(-1, 3)[:, :, None] + np.arange(2)).reshape(-1, 6)
    coupling = sp.csr_matrix((blocks.ravel(), (np.repeat(dof, 6, axis=1).ravel(), np.tile(dof, 6).ravel())),
                             shape=(2 * u, 2 * u))                  # D: 6 x 6 blocks, summed
    factor = rows.factor(nodes)                                     # (2u, r): G = C C'
    reduced = (coupling @ factor).T                                 # C' D (D symmetric)
    small = np.eye(factor.shape[1]) + reduced @ factor              # M
    try:
        lower = np.linalg.cholesky(small)                           # positive definite, or H + B is not
    except np.linalg.LinAlgError:
        return None
    moved = move(gradient)                                          # S g
    v = moved[nodes].reshape(-1)
    inner = cholesky_solve(lower, reduced @ v)                      # M^-1 C' D v
    force = np.zeros_like(points)
    force[nodes] = (coupling @ v - reduced.T @ inner).reshape(u, 2)
    return move(force) - moved


def converge(solve, normal, movable: np.ndarray, x: np.ndarray, triangles: np.ndarray, floor: np.ndarray,
             kappa: np.ndarray, areas=None, max_steps: int | None = None,
             inverse=None, linear=None, tolerance=TOLERANCE, below=0.0) -> tuple[np.ndarray, Convergence]:
    """Minimise Phi (module docstring) from the injective positions ``x``: (x, :class:`Convergence`).
    With ``below`` > 0, Phi with b continued below that ratio (:func:`clamped_log`), from any
    ``x``, no step bounded by a fold: a minimum that keeps every triangle at ``below`` or above
    is a minimum of Phi too (the two energies agree around it).

    Parameters
    ----------
    solve : callable
        ``solve(force)`` -> (N, 2) minimiser of the least-squares energy minus ``force . x``
        over the admissible positions (a back-substitution of the factored system).
    normal : scipy.sparse matrix
        The least-squares energy's Hessian per axis (N x N; exact on the rows ``solve`` moves).
    movable : (N,) bool ndarray
        Nodes ``solve`` moves one by one (not held, not tied; used without ``inverse``).
    x, triangles, floor, kappa : (N, 2), (M, 3), (M,), (M,) ndarray
        Start (no triangle folded, unless ``below``), the triangles, f_t and kappa_t (:func:`weights`).
    areas, max_steps, tolerance, below : callable, int, float, float, optional
        ``areas(points)`` -> signed area per triangle (default :func:`grid.signed_areas`); Newton
        steps at most (default :data:`MAX_STEPS`; a preview: a few); looser where a run goes on; ``below``.
    inverse : InverseRows, optional
        ``solve``'s linear part between nodes, as far as earlier runs on the same system filled
        it: with it, a Newton system whose barrier touches few nodes is solved exactly.
    linear : callable, optional
        ``linear(force)`` -> S force, exactly 0 on held coordinates and one value per unknown.
        The default, ``solve(force) - solve(0)``, subtracts positions: 1e-14 apart on a tied
        feature, times reaction forces of 1e4, spoiled CG (the coins under swirl 90 at 256 px
        "converged" 0.044 px off the solve's positions).
    """
    areas = areas or (lambda points: signed_areas(points, triangles))
    max_steps = MAX_STEPS if max_steps is None else max_steps
    optimum = solve(np.zeros_like(x))
    move = linear or (lambda force: solve(force) - optimum)

    def energy(points):
        current = areas(points)
        if current.min() <= 0 and not below:
            return np.inf
        offset = points - optimum
        return 0.5 * float((_dot(normal, offset) * offset).sum()) + float(
            (kappa * clamped_log(current / floor, below=below)[0]).sum())

    near, bound, partial, value, rows = False, False, False, energy(x), inverse
    for step in range(max_steps):
        ratio = areas(x) / floor
        active = np.flatnonzero(ratio < 1.0)
        tris, scale = triangles[active], kappa[active] / floor[active]
        slopes = scale * clamped_log(ratio[active], below=below)[1]
        gradient = _dot(normal, x - optimum) + injectivity.penalty_force(x, tris, slopes)
        direction, ok, direct = step_direction(rows, move, normal, movable, x, tris, ratio[active], floor[active],
                                               kappa[active], gradient, near, not bound, partial and not near, below)
        decrement = -float((gradient * direction).sum()) if ok else 0.0
        if not ok or (partial and not near and not decrement > 0):     # not positive definite
            if not (near or partial):
                return x, Convergence(step, False)     # even with the bound: stay
            near = partial = False
            continue
        if decrement <= tolerance * value or decrement < 1e-18:     # uphill beyond rounding: not a minimum
            return x, Convergence(step, decrement >= -TOLERANCE * value)    # a looser run's: the same
        if active.size == 0 and _reaches_optimum(areas, x, optimum, floor):
            return optimum, Convergence(step + 1, True)
        length = 1.0 if below else min(1.0, 1.8 * injectivity.max_step_of(areas, x, x + 2.0 * direction))
        trial = energy(x + length * direction)
        while length > 1e-12 and not trial <= value - 1e-4 * length * decrement:
            length *= 0.5
            trial = energy(x + length * direction)
        if length <= 1e-12:
            if (near and not direct) or (direct and not bound) or (partial and not direct):   # the bound
                near, bound, partial = False, True, False
                continue
            return x, Convergence(step, False)     # no descent along the bound's direction: stay
        if length == 1.0 and not near and not direct:
            length, trial = _extended(energy, areas if not below else None, x, direction, trial)
        partial = partial or length > 1.0          # the bound over-estimated the curvature: see _PARTIAL
        near, bound = length >= 1.0 and decrement < _EXACT_BELOW * value, False
        x, value = x + length * direction, trial
    return x, Convergence(max_steps, False)


def _extended(energy, areas, x: np.ndarray, direction: np.ndarray, value: float) -> tuple[float, float]:
    """(length, energy) of the step along ``direction`` from ``x``: a full step (energy ``value``)
    doubled while that lowers the energy, up to 0.9 of the way to the first fold along the ray
    (``areas`` None: the continued barrier, no fold to stop at) and at most 0.9 :data:`_FAR`.

    The bound's Hessian over-estimates the curvature where the barrier's area term has a
    negative part, so its full steps fall short along the valleys of the energy (the
    astronaut's fish at 12 MP with the head + helmet mask converged at 0.8-0.9 a step; the
    1 MP swirl 180 with her head, patch and shuttle at cell 4 took 388 steps, 203 with this)."""
    reach = 0.9 * _FAR * (injectivity.max_step_of(areas, x, x + _FAR * direction) if areas else 1.0)
    length = 1.0
    while 2.0 * length <= reach:
        longer = energy(x + 2.0 * length * direction)
        if not longer < value:
            break
        length, value = 2.0 * length, longer
    return length, value


def _reaches_optimum(areas, x: np.ndarray, optimum: np.ndarray, floor: np.ndarray) -> bool:
    """Whether x* keeps every triangle at its floor or above and the straight step from ``x``
    (no triangle below its floor) to it folds none: there Phi is the least-squares quadratic,
    x* its minimum, and further Newton steps would only chase the solves' rounding."""
    return bool(np.all(areas(optimum) >= floor)) and injectivity.max_step_of(areas, x, optimum) >= 1.0


def step_direction(rows, move, normal, movable, x, triangles, ratio, floor, kappa, gradient, near,
               exact_first=True, partial=False, below=0.0):
    """(direction, ok, direct): the Newton direction by :func:`_direct_direction` where ``rows``
    is given and the barrier touches few nodes (the exact Hessian where the system is positive
    definite with it and ``exact_first``, else the bound), else by :func:`_newton_direction`
    (the exact Hessian when ``near``, else the partial one with ``partial``, else the bound;
    also where rounding keeps :meth:`InverseRows.factor` from factoring, or the direct
    direction from pointing downhill)."""
    nodes, n = np.unique(triangles), x.shape[0]
    if (rows is not None and nodes.size <= _DIRECT_NODES and (2 * nodes.size) ** 3 <= _DIRECT_WORK * n
            and nodes.size * n <= _DIRECT_SOLVES and _factors(rows, nodes)):
        for exact in ((True, False) if exact_first else (False,)):
            direction = _direct_direction(rows, move, x, triangles,
                                          hessians(x, triangles, ratio, floor, kappa, exact=exact, below=below),
                                          gradient)
            if direction is None:                 # not positive definite with these blocks
                continue
            if -float((gradient * direction).sum()) > 0:
                return direction, True, True
            break                                 # uphill (see _direct_direction): CG below
        else:
            return None, False, True
    blocks = hessians(x, triangles, ratio, floor, kappa, exact=1.0 if near else _PARTIAL if partial else 0.0,
                      below=below)
    unknowns = rows.unknowns if rows is not None else np.stack([np.where(movable, np.arange(n), -1)] * 2)
    between = rows.between if rows is not None and rows.between is not None else summed_between(normal, unknowns)
    return (*_newton_direction(move, normal, unknowns, between, x, triangles, blocks, gradient, near, partial), False)


def _factors(rows: InverseRows, nodes: np.ndarray) -> bool:
    """Whether :meth:`InverseRows.factor` factors G for ``nodes`` (sorted, unique; kept)."""
    try:
        rows.factor(nodes)
    except np.linalg.LinAlgError:
        return False
    return True

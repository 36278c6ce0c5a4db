"""The rigid map's injective minimiser: as-rigid-as-possible energy plus an area barrier,
lowered by Newton steps that cannot fold.

The energy of node positions ``x`` (N, 2) of a triangle grid, its rest shape the source
grid scaled by ``s`` (:func:`arap.rest_scale`), is::

    E(x) = sum_t A_t (|F_t - R_t|^2 + BARRIER_WEIGHT * b(det F_t)) + w |P x - h|^2

with ``F_t`` the Jacobian of triangle t against its rest shape, ``R_t`` its closest rotation
(Sorkine and Alexa 2007, "As-rigid-as-possible surface modeling", in the per-element form
of Liu et al. 2008), ``A_t`` its rest area, ``P x - h`` the handles' penalty rows and ``b``
the clamped log barrier of incremental potential contact (Li et al. 2020, Eq. 6) on the
area ratio ``r = det F``: ``-(r - SAFE_AREA)^2 log(r / SAFE_AREA)`` below ``SAFE_AREA``,
exactly zero above it and infinite at ``r = 0``. Where converged ARAP folds no triangle
below that fraction of its rest area, the minimum is converged ARAP; elsewhere the barrier
keeps every triangle the right way round.

The minimiser is projected Newton (Teran et al. 2005): each triangle's Hessian in ``F``
is made positive semi-definite (ARAP's has the closed form of Smith, Goes and Kim 2019,
"Analytic eigensystems for isotropic distortion energies": 2 I minus the twist direction;
the barrier's is projected numerically), the whole system is factored with the symbolic
analysis made once, and the step is cut to 0.9 of the largest one that folds nothing
(:func:`injectivity.max_step`) and backtracked (Armijo). Every iterate is injective. It
stops when the Newton decrement falls below :data:`TOLERANCE` of the energy.
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp

from . import cholmod
from .barrier import clamped_log
from .injectivity import max_step
from .targets import closest_rotations

#: A triangle may shrink to this fraction of its rest area before the barrier acts.
SAFE_AREA = 0.5
#: The barrier's weight against the rigidity energy, per unit of rest area.
BARRIER_WEIGHT = 100.0
#: Stop when the Newton decrement (g.H^-1 g, twice the model's predicted decrease) is below
#: this fraction of the energy.
TOLERANCE = 1e-7
#: Also converged when the Newton step moves no node by more than this (px): where the
#: handles are one similarity the energy is 0 up to rounding and no relative test applies.
STEP_FLOOR = 1e-9
#: Newton steps at most.
MAX_STEPS = 200
_ARMIJO = 1e-4
_FLIP_MARGIN = 0.9
_LONGEST = 16.0


class RigidEnergy:
    """E(x) on one grid and handle set (see the module's notes); factored pattern kept.

    Parameters
    ----------
    rest : (N, 2) ndarray
        The rest shape's nodes (the source grid scaled by the rest scale).
    triangles : (M, 3) int ndarray
    penalty : (K, N) sparse matrix
        The handles' rows ``P`` (already scaled by the square root of their weight).
    """

    def __init__(self, rest: np.ndarray, triangles: np.ndarray, penalty):
        self.triangles = triangles
        self.n = len(rest)
        p = rest[triangles]
        e1, e2 = p[:, 1] - p[:, 0], p[:, 2] - p[:, 0]
        det = e1[:, 0] * e2[:, 1] - e1[:, 1] * e2[:, 0]
        inverse = np.stack([np.stack([e2[:, 1], -e2[:, 0]], -1), np.stack([-e1[:, 1], e1[:, 0]], -1)], 1)
        inverse = inverse / det[:, None, None]
        g1, g2 = inverse[:, 0], inverse[:, 1]
        self.grads = np.stack([-g1 - g2, g1, g2], axis=1)         # (M, 3, 2): F = sum_k x_k g_k^T
        self.areas = 0.5 * det
        m = len(triangles)
        # dF/dx as (M, 4, 6): F flattened [F00, F01, F10, F11], x as [x0, y0, x1, y1, x2, y2].
        self.dfdx = np.zeros((m, 4, 6))
        for k in range(3):
            for i in range(2):
                for j in range(2):
                    self.dfdx[:, 2 * i + j, 2 * k + i] = self.grads[:, k, j]
        self.dfdx_t = np.ascontiguousarray(self.dfdx.transpose(0, 2, 1))
        self._unit = (self.grads, self.areas, self.dfdx, self.dfdx_t)
        self.scale = 1.0
        self.dofs = (2 * triangles[:, :, None] + np.arange(2)).reshape(m, 6)
        self.penalty = sp.csr_matrix(penalty)
        gram = (self.penalty.T @ self.penalty).tocoo()
        rows = np.concatenate([np.repeat(self.dofs, 6, axis=1).ravel(), 2 * gram.row, 2 * gram.row + 1])
        cols = np.concatenate([np.tile(self.dofs, (1, 6)).ravel(), 2 * gram.col, 2 * gram.col + 1])
        self._penalty_values = np.tile(2.0 * gram.data, 2)
        # The lower triangle's pattern, fixed (CSC order), and where each entry adds into it.
        size = 2 * self.n
        self._lower = rows >= cols
        keys, self._slot = np.unique(cols[self._lower] * size + rows[self._lower], return_inverse=True)
        self._indices = (keys % size).astype(np.int32)
        self._indptr = np.searchsorted(keys // size, np.arange(size + 1)).astype(np.int32)
        self._analysis = None

    def rescale(self, scale: float) -> None:
        """Make the rest shape the given one scaled by ``scale`` (the pattern and its analysis stay)."""
        if scale != self.scale:
            grads, areas, dfdx, dfdx_t = self._unit
            self.grads, self.dfdx, self.dfdx_t = grads / scale, dfdx / scale, dfdx_t / scale
            self.areas, self.scale = areas * scale * scale, scale

    def jacobians(self, x: np.ndarray) -> np.ndarray:
        """(M, 2, 2) Jacobians of the map with node images ``x``."""
        return np.matmul(x[self.triangles].transpose(0, 2, 1), self.grads)

    def value(self, x: np.ndarray, targets: np.ndarray) -> float:
        """E(x) (inf where a triangle folds)."""
        f = self.jacobians(x)
        det = f[:, 0, 0] * f[:, 1, 1] - f[:, 0, 1] * f[:, 1, 0]
        if not np.all(det > 0):
            return np.inf
        rotation = closest_rotations(f)
        held = self.penalty @ x - targets
        return float(np.sum(self.areas * (np.sum((f - rotation) ** 2, axis=(1, 2))
                                          + BARRIER_WEIGHT * clamped_log(det, SAFE_AREA)[0])) + np.sum(held * held))

    def newton_step(self, x: np.ndarray, targets: np.ndarray) -> tuple[np.ndarray, float]:
        """The projected Newton step at the injective ``x``.

        Returns
        -------
        step : (N, 2) ndarray
            ``-H^-1 g`` with H the sum of the triangles' Hessians made positive
            semi-definite and the penalty's.
        decrement : float
            ``-g.step`` (twice the decrease the quadratic model predicts)."""
        f = self.jacobians(x)
        flat = f.reshape(-1, 4)
        det = flat[:, 0] * flat[:, 3] - flat[:, 1] * flat[:, 2]
        cofactor = np.stack([flat[:, 3], -flat[:, 2], -flat[:, 1], flat[:, 0]], axis=1)
        rotation = closest_rotations(f).reshape(-1, 4)
        _, slope, curve = clamped_log(det, SAFE_AREA)
        grad_f = 2.0 * (flat - rotation) + BARRIER_WEIGHT * slope[:, None] * cofactor
        hess_f = _arap_hessians(flat, rotation)
        active = np.flatnonzero(slope != 0)
        if active.size:
            hess_f[active] += _psd(BARRIER_WEIGHT * (curve[active, None, None] * cofactor[active, :, None]
                                                     * cofactor[active, None, :]
                                                     + slope[active, None, None] * _DET_HESSIAN))
        grad = np.matmul(self.dfdx_t, (grad_f * self.areas[:, None])[:, :, None])[:, :, 0]
        gradient = np.bincount(self.dofs.ravel(), grad.ravel(), minlength=2 * self.n)
        gradient += 2.0 * np.asarray(self.penalty.T @ (self.penalty @ x - targets)).ravel()
        local = np.matmul(np.matmul(self.dfdx_t, hess_f * self.areas[:, None, None]), self.dfdx)
        values = np.concatenate([local.ravel(), self._penalty_values])[self._lower]
        lower = sp.csc_matrix((np.bincount(self._slot, values, minlength=self._indices.size),
                               self._indices, self._indptr), shape=(2 * self.n,) * 2)
        try:
            step = -self._solve(lower, gradient)
        except cholmod.NotPositiveDefinite:      # rounding next to a degenerate triangle: no step
            return np.zeros((self.n, 2)), float("nan")
        return step.reshape(-1, 2), float(-gradient @ step)

    def _solve(self, lower, gradient: np.ndarray) -> np.ndarray:
        """Solve with the symmetric matrix whose lower triangle is ``lower`` (its pattern fixed)."""
        if not cholmod.AVAILABLE:
            from scipy.sparse.linalg import spsolve

            full = lower + sp.tril(lower, -1).T
            return spsolve(full.tocsc(), gradient)
        if self._analysis is None:
            self._analysis = cholmod.analyze(lower, supernodal=True)
        factor = cholmod.factorize(self._analysis, lower)
        return cholmod.solve(factor, gradient)


def minimise(energy: RigidEnergy, x: np.ndarray, targets: np.ndarray,
             steps: int = MAX_STEPS) -> tuple[np.ndarray, int, bool]:
    """Lower ``energy`` from the injective ``x``.

    Parameters
    ----------
    energy : RigidEnergy
    x : (N, 2) ndarray
        Start; every triangle positively oriented.
    targets : (K, 2) ndarray
        The handles' penalty targets ``h`` (scaled as the penalty rows).
    steps : int
        Newton steps at most.

    Returns
    -------
    x : (N, 2) ndarray
        Every triangle positively oriented.
    steps : int
        Newton steps taken.
    converged : bool
        The Newton decrement ``g.H^-1 g`` fell below :data:`TOLERANCE` times the energy, or
        the step below :data:`STEP_FLOOR` (False: the step cap was reached, or no step
        lowered the energy)."""
    value = energy.value(x, targets)
    for step in range(1, steps + 1):
        direction, decrement = energy.newton_step(x, targets)
        if not np.isfinite(decrement):
            return x, step - 1, False
        if decrement <= TOLERANCE * value or np.abs(direction).max() <= STEP_FLOOR:
            return x, step - 1, True
        bound = max_step(x, x + direction, energy.triangles)       # 1.0: the whole step folds nothing
        alpha = 1.0 if bound >= 1.0 else _FLIP_MARGIN * bound
        while alpha > 1e-12:
            trial = x + alpha * direction
            trial_value = energy.value(trial, targets)
            if trial_value <= value - _ARMIJO * alpha * decrement:
                break
            alpha *= 0.5
        else:
            return x, step, False
        if alpha == 1.0:
            trial, trial_value = _extend(energy, x, direction, targets, trial, trial_value)
        x, value = trial, trial_value
    return x, steps, False


def _extend(energy: RigidEnergy, x, direction, targets, trial, trial_value):
    """Past a full Newton step that folded nothing: double the step while the energy keeps
    falling (up to :data:`_LONGEST` steps; the model can overrate the curvature of a slide)."""
    length = 1.0
    while length < _LONGEST:
        longer = 2.0 * length
        if max_step(x, x + longer * direction, energy.triangles) < 1.0:
            break
        candidate = x + longer * direction
        value = energy.value(candidate, targets)
        if not value < trial_value:
            break
        trial, trial_value, length = candidate, value, longer
    return trial, trial_value


#: Hessian of det F in the flattened F = [F00, F01, F10, F11].
_DET_HESSIAN = np.array([[0.0, 0, 0, 1], [0, 0, -1, 0], [0, -1, 0, 0], [1, 0, 0, 0]])


def _arap_hessians(flat: np.ndarray, rotation: np.ndarray) -> np.ndarray:
    """(M, 4, 4) Hessians of |F - R(F)|^2, projected: 2 (I - min(1, 2 / (s1 + s2)) t t^T),
    with t the twist direction R [[0, -1], [1, 0]] / sqrt(2) and s1 + s2 the sum of the signed
    singular values (Smith, Goes and Kim 2019)."""
    trace_sum = np.hypot(flat[:, 0] + flat[:, 3], flat[:, 2] - flat[:, 1])      # s1 + s2
    r = rotation
    twist = np.stack([r[:, 1], -r[:, 0], r[:, 3], -r[:, 2]], axis=1) / np.sqrt(2.0)
    weight = np.minimum(1.0, 2.0 / np.maximum(trace_sum, 1e-300))
    return 2.0 * (np.eye(4)[None] - weight[:, None, None] * twist[:, :, None] * twist[:, None, :])


def _psd(matrices: np.ndarray) -> np.ndarray:
    """Each symmetric matrix with its negative eigenvalues set to zero."""
    values, vectors = np.linalg.eigh(matrices)
    return np.einsum("mij,mj,mkj->mik", vectors, np.maximum(values, 0.0), vectors)

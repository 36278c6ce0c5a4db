"""The path of barrier minima from W: an injective start that is a continuous function of the inputs.

Blend the least-squares targets from W's own (``s = 0``) to the solve's (``s = 1``): the edge
targets' right-hand side, and the positions the solve holds or ties (a tied feature's shape,
a held coordinate) from W's to the solve's. At ``s = 0`` the least-squares solution is W
itself (its right-hand side is ``L W``), which has no fold; it is affine in ``s``, so the
barrier energy's minima form a path from W. Followed by a predictor along the path's tangent
(``(H + B)^-1 H`` times the least-squares line's, B the barrier's Hessian bound, taken where the
last step's tangent takes the triangles: :func:`_resisting`), up to where a triangle keeps half
of its area (of its floor where it is above it: a root, not a count), and a corrector
(:func:`barrier.converge` at the new ``s``), it ends at a minimum of the energy at ``s = 1``
without untangling, windows or fold counts (Allgower and Georg, *Introduction to Numerical
Continuation Methods*, 2003, ch. 2: predictor-corrector path following).

Where the guard's window cannot open the folds, it starts the barrier here instead of
untangling the whole grid: the untangling's first fold-free iterate, or whether it found one
within its steps, turned a one-ulp change of W into 1.2 px (the astronaut at 320 px under a
rigid ``swirl --angle 230``) and 7-137 px (the 1 MP photo under ``swirl --angle 229.99999``).
"""

from __future__ import annotations

import numpy as np

from . import barrier, injectivity

#: Where the path's minimum (converged to :data:`barrier.TOLERANCE` before it is judged) leaves
#: a triangle thinner than this share of its floor, the tied features do not fit (the minima
#: crush the ground between them as ``s`` nears a limit below 1): the path stops and the guard
#: releases them. Judged on loosely converged points, the outcome alternated over a band of
#: 4096 ulps of a swirl's angle; on converged minima, as the ground thins along the path, it
#: is a function of the minimum at s = 1. The kept minima of the photos and the hard
#: swirls keep 25-70 % (:data:`barrier.STIFFNESS`); lower follows a blocked path longer.
BLOCKED_SHARE = 0.2
#: The corrector's tolerance (the Newton decrement against the energy, as
#: :data:`barrier.TOLERANCE`) before ``s = 1``; the last point is converged to
#: :data:`barrier.TOLERANCE`. Looser is faster and follows the path less closely (at 0.1 the
#: 1 MP photo's ``squeeze`` crushed a triangle on the way and released its features).
PATH_TOLERANCE = 1e-3
#: Predictor-corrector steps at most, a guard against a path whose minimum ends without a
#: crushed triangle (treated as blocked). The photos' and hard cases' paths take 7-69.
MAX_STEPS = 200


def path_from_warp(problem, floor: np.ndarray, record) -> tuple[np.ndarray, bool]:
    """Follow the path of the barrier energy's minima from W (``s = 0``) to the solve (``s = 1``).

    Parameters
    ----------
    problem : guard.Problem
        The solve's systems, constants and grid.
    floor : (M,) ndarray
        Each triangle's floor (:data:`barrier.SAFE_FRACTION` of its area under W).
    record : guard.GuardRecord
        Gets the Newton steps of every corrector, ``path_steps``, and ``converged`` of the
        run at ``s = 1`` (left as it was where the path is blocked: the release's runs decide).

    Returns
    -------
    x : (N, 2) ndarray
        The minimum at ``s = 1``, or the last minimum reached (a triangle below
        :data:`BLOCKED_SHARE` of its floor there, or none where the predictor could not move).
    reached : bool
        Whether the path got to ``s = 1``: the tied features fit.
    """
    warped, systems = problem.warped, problem.systems
    rhs_warp = _stacked(problem.normal, warped)
    along = systems.solve(problem.rhs, problem.offset) - warped      # d(least-squares solution)/ds
    areas = lambda points: injectivity.grid_areas(problem.grid, points)    # noqa: E731
    x, s, converged = warped.copy(), 0.0, record.converged
    held = np.stack([systems.x.unknown < 0, systems.y.unknown < 0], axis=1)
    kappa = barrier.weights(warped, problem.triangles, problem.stiffness, floor)
    current, ahead = areas(x), None
    for step in range(MAX_STEPS):
        tangent = _tangent(problem, systems, x, _resisting(current, ahead, floor), floor, kappa, along)
        share = injectivity.max_step(x, x + (1.0 - s) * tangent, problem.triangles,
                                     injectivity.CRUSHED_SHARE * np.minimum(floor, current))
        if not share > 0:
            break
        s_next = 1.0 if share >= 1.0 else s + share * (1.0 - s)
        look = share * (1.0 - s_next) * tangent          # the same share of what is left, from the next point
        x = x + (s_next - s) * tangent
        s = s_next
        rhs = (1.0 - s) * rhs_warp + s * problem.rhs
        offset = (1.0 - s) * warped + s * problem.offset
        x = np.where(held, offset, x)            # exactly where the solve holds them, no drift
        x, how = converge_grid(problem, systems, rhs, offset, problem.tied, x, floor, record, kappa=kappa,
                               tolerance=barrier.TOLERANCE if s == 1.0 else PATH_TOLERANCE)
        record.path_steps, current = step + 1, areas(x)
        if s < 1.0 and (current < BLOCKED_SHARE * floor).any():        # decided on the converged minimum
            x, how = converge_grid(problem, systems, rhs, offset, problem.tied, x, floor, record, kappa=kappa)
            current = areas(x)
        if (current < BLOCKED_SHARE * floor).any():
            break                                # the features do not fit
        if s == 1.0:
            record.converged = converged and how.converged
            return x, True
        ahead = areas(x + look)                  # from the point the next step starts at
    record.converged = converged                 # the release's runs are the result's
    return x, False


def _stacked(normal, points: np.ndarray) -> np.ndarray:
    """``L points`` per axis: the right-hand side whose least-squares solution is ``points``."""
    return np.stack([normal.dot(points[:, 0]), normal.dot(points[:, 1])], axis=1)


def _resisting(current: np.ndarray, ahead: np.ndarray | None, floor: np.ndarray) -> np.ndarray:
    """The area ratios (to the floor) at which the predictor takes the barrier's curvature: the
    triangles' own at the minimum (``current``), or lower where the last step's tangent, looked
    along from here by the same share of what is left of the path, takes them lower (``ahead``;
    not below :data:`injectivity.CRUSHED_SHARE`, the predictor's own limit).

    A triangle that the least-squares direction is crushing resists only once it is below its
    floor; predicted without that, the next triangle of a crease's front ended every step (1 MP
    ``squeeze`` with her own mask: 18 steps, the limiting triangle each time the next one down
    one column of quads). With the curvature it is about to have: 9 steps, the same minimum (the
    same pixels); the 12 MP hard swirl and bulge on the whole grid 41 -> 20 and 56 -> 24."""
    ratio = current / floor
    if ahead is None:
        return ratio
    return np.minimum(ratio, np.maximum(ahead / floor, injectivity.CRUSHED_SHARE))


def _tangent(problem, systems, x, ratio, floor, kappa, along):
    """The predictor's direction at a minimum ``x``: the path's tangent d(minimum)/ds there
    where ``ratio`` is the triangles' own.

    At a minimum, (H + B) dx/ds = H along (H the least-squares Hessian, B the barrier's, its
    positive semi-definite bound), so dx/ds = along - (H + B)^-1 B along: one Newton
    direction (:func:`barrier.step_direction`) with ``B along`` as the gradient. ``ratio``:
    the area ratios B is taken at (:func:`_resisting`: lower than the triangles' own where
    the last step heads them below, so a triangle still above its floor may resist);
    ``along``: the least-squares solution's d/ds. Returns (N, 2); ``along`` where no ratio is
    below 1 or the system is not positive definite.
    """
    active = np.flatnonzero(ratio < 1.0)
    if active.size == 0:
        return along
    tris = problem.triangles[active]
    blocks = barrier.hessians(x, tris, ratio[active], floor[active], kappa[active], exact=False)
    part = np.einsum("kij,kj->ki", blocks, along[tris].reshape(-1, 6)).reshape(-1, 2)
    pushed = np.stack([np.bincount(tris.ravel(), part[:, k], minlength=x.shape[0]) for k in range(2)], axis=1)
    direction, ok, _ = barrier.step_direction(problem.inverse(systems), problem.linear(systems), problem.normal,
                                              ~problem.fixed & (problem.tied < 0), x, tris, ratio[active],
                                              floor[active], kappa[active], pushed, False, exact_first=False)
    return along + direction if ok else along


def converge_grid(problem, systems, rhs, offset, tied, x, floor, record, max_steps=None,
                  tolerance=barrier.TOLERANCE, kappa=None):
    """Converge the barrier energy on the whole grid from ``x`` (no folds).

    Parameters
    ----------
    problem : guard.Problem
    systems, rhs, offset, tied
        The least-squares system and constants whose energy is minimised, and the component
        each node is tied to (or -1).
    x, floor : (N, 2), (M,) ndarray
    record : guard.GuardRecord
        Gets the run's Newton steps and convergence (:meth:`GuardRecord.count`).
    max_steps, tolerance : int, float, optional
        As :func:`barrier.converge` (a preview's few steps; a path's looser tolerance).
    kappa : (M,) ndarray, optional
        :func:`barrier.weights` for ``floor``, where the caller has it.

    Returns
    -------
    x : (N, 2) ndarray
    how : barrier.Convergence
    """
    if kappa is None:
        kappa = barrier.weights(problem.warped, problem.triangles, problem.stiffness, floor)
    x, how = barrier.converge(problem.solver(systems, rhs, offset), problem.normal, ~problem.fixed & (tied < 0), x,
                              problem.triangles, floor, kappa,
                              areas=lambda points: injectivity.grid_areas(problem.grid, points),
                              max_steps=max_steps, inverse=problem.inverse(systems),
                              linear=problem.linear(systems), tolerance=tolerance)
    record.count(how)
    return x, how

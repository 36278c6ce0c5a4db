"""The searches over the features' similarities that least squares alone gets wrong.

The least-squares optimum of :mod:`featurewarp_cli.engine.components` balances the
features' shape equations against the background's. Three things it does not see:

- a grown feature may crush the background beside it (:func:`fitting_scales` backs off
  towards the preset's lambda R until nothing is crushed);
- a feature that cannot keep its shape at its size may keep it smaller
  (:func:`shrink_to_fit`, after the fold-over guard had to relax it);
- where features fill most of a row or column, least squares prefers to pile the whole
  change of length into the thin strip of background left there (the stretch of a thin
  strip costs little because it has few quads); :func:`spread_stretch` grows
  the features uniformly until the largest stretch of a background triangle matches the
  largest compression, as the scale-and-stretch idea of Wang et al. 2008 asks.

Each searches a segment of (a, b) values, along which the solution is affine: the first
point where a triangle reaches its floor is the first root of quadratics
(:func:`injectivity.max_step`), the spread's balance a converged root of a continuous
function. Neither is a bisection to a threshold, so a one-ulp change of the inputs moves the
result by rounding only.
"""

from __future__ import annotations

import numpy as np

from .grid import signed_areas
from .barrier import SAFE_FRACTION
from .injectivity import CRUSHED_SHARE, max_step
from .roots import bracketed_root

def _between(start_result, end_result, t: float):
    """The solution at ``start + t (end - start)`` from the solutions at both ends.

    The least-squares solution and its constants (right-hand side, offsets, edge targets)
    are affine in (a, b) for fixed ties, so points of a segment cost no solve."""
    return tuple(a + t * (b - a) for a, b in zip(start_result, end_result))


def _furthest_fitting(start: np.ndarray, end: np.ndarray, start_result, end_result, floor: np.ndarray,
                      triangles):
    """The furthest point of the segment start -> end up to which the solution keeps every
    triangle's area at or above ``floor``, given that ``start``'s (``start_result``) does: the
    first root of the areas' quadratics (:func:`injectivity.max_step`).

    Returns (ab, solution)."""
    t = max_step(start_result[0], end_result[0], triangles, floor)
    return start + t * (end - start), _between(start_result, end_result, t)


def fitting_scales(solve, prior: np.ndarray, optimum: np.ndarray, triangles, warped):
    """The features' similarities: the least-squares ``optimum`` unless its solution crushes a
    triangle that the ``prior``'s solution does not; then the furthest point from the prior
    towards the optimum that crushes none.

    A triangle counts as crushed below its floor (:data:`barrier.SAFE_FRACTION` of its area
    under W), or below its area in the prior's solution where that is smaller already (folds there are the fold-over
    guard's to open, as for any solution). So solving for scale and rotation never leaves the
    background worse off than the preset's own lambda R would: a feature that cannot grow as
    far as least squares would like stays a similarity, only less grown.

    Returns (ab, solve(ab))."""
    best = solve(optimum)
    if np.allclose(prior, optimum):
        return optimum, best
    start = solve(prior)
    floor = np.minimum(SAFE_FRACTION * signed_areas(warped, triangles), signed_areas(start[0], triangles))
    if np.all(signed_areas(best[0], triangles) >= floor):
        return optimum, best
    return _furthest_fitting(prior, optimum, start, best, floor, triangles)


def shrink_to_fit(solve, low: np.ndarray, high: np.ndarray, high_result, triangles, warped):
    """The largest similarities between ``low`` and ``high`` ((C, 2) each; ``high_result`` is
    ``solve(high)``) whose solution crushes no triangle below :data:`barrier.SAFE_FRACTION` of its
    area under W, or None when even ``low`` does. For features that cannot keep
    their shape at the size least squares picked (densely packed coins squeezed to 0.6 of
    their width): smaller but exact.

    Returns (ab, solve(ab)) or None."""
    floor = SAFE_FRACTION * signed_areas(warped, triangles)
    start = solve(low)
    if not np.all(signed_areas(start[0], triangles) >= floor):
        return None
    return _furthest_fitting(low, high, start, high_result, floor, triangles)


#: Background area ratios (canvas / W) up to SPREAD_ABOVE are left as least squares put
#: them; beyond, :func:`spread_stretch` searches the features' scale.
SPREAD_ABOVE = 4.0
#: How far :func:`spread_stretch` may grow the features: up to this factor.
SPREAD_RANGE = 2.0
#: Fraction of background triangles at each end that the spread's balance leaves out.
SPREAD_OUTLIERS = 0.002


def _log_extremes(target: np.ndarray, reference: np.ndarray, triangles: np.ndarray) -> tuple[float, float]:
    """log of the largest and of the smallest area ratio (canvas / W) of ``triangles``, each
    leaving out the :data:`SPREAD_OUTLIERS` most extreme (single triangles wedged in a
    notch of the mask are squeezed whatever the scale; the spread is about regions)."""
    ratio = np.log(np.maximum(signed_areas(target, triangles) / reference, 1e-12))
    low, high = np.quantile(ratio, [SPREAD_OUTLIERS, 1.0 - SPREAD_OUTLIERS])
    return float(high), float(low)


def spread_stretch(solve, ab: np.ndarray, result, scalable: np.ndarray, triangles: np.ndarray,
                   warped: np.ndarray, background: np.ndarray):
    """Grow the features uniformly so the background's stretch is spread.

    When the largest background area ratio against W exceeds :data:`SPREAD_ABOVE` and
    outweighs the largest compression, the ``scalable`` components' (a, b) are multiplied
    by one factor m in [1, SPREAD_RANGE]: the point where the largest stretch equals the
    largest compression (log max + log min changes sign), or where it has come down to
    SPREAD_ABOVE if that comes first, so that a stretch just above SPREAD_ABOVE grows the
    features just a little (no jump where a one-ulp change crosses it); a root found to
    convergence (:func:`roots.bracketed_root`, the ITP method), unless a triangle reaches its floor
    before (:data:`injectivity.CRUSHED_SHARE` of its floor, or of its area in ``result``
    where that is smaller already; the first root of quadratics, :func:`injectivity.max_step`).
    Shrinking is not searched here: squeezed features are :func:`shrink_to_fit`'s.

    Growing a feature stretches the strip over it sideways too, so the area ratio there
    falls more slowly than the strip's height: a subject that fills the height and most of
    the width cannot bring it down much (see README, "Known limits").

    Parameters
    ----------
    solve : callable
        (C, 2) (a, b) -> (nodes, ...), the least-squares solution at those similarities.
    ab, result : (C, 2) ndarray and tuple
        The similarities found so far and ``solve(ab)``.
    scalable : (C,) bool ndarray
        Components whose similarity is an unknown (tied, with a free scale).
    triangles : (M, 3) int ndarray
    warped : (N, 2) ndarray
        The nodes under W.
    background : (M,) bool ndarray
        Background triangles.

    Returns
    -------
    (ab, solve(ab))
    """
    tris = triangles[background]
    reference = signed_areas(warped, tris)
    keep = reference > 1e-12
    tris, reference = tris[keep], reference[keep]
    if not tris.size or not scalable.any():
        return ab, result
    high, low = _log_extremes(result[0], reference, tris)
    if high <= np.log(SPREAD_ABOVE) or high + low <= 0:
        return ab, result
    areas = signed_areas(result[0], triangles)
    floor = CRUSHED_SHARE * np.minimum(SAFE_FRACTION * signed_areas(warped, triangles), areas)
    if not np.all(areas >= floor):            # folded: the guard's to open
        return ab, result
    grown = solve(np.where(scalable[:, None], ab * SPREAD_RANGE, ab))
    reach = max_step(result[0], grown[0], triangles, floor)       # the solution is affine in m

    def balance(t):                           # both > 0 at t = 0; the first to reach 0 stops the growth
        high, low = _log_extremes(result[0] + t * (grown[0] - result[0]), reference, tris)
        return min(high + low, high - np.log(SPREAD_ABOVE))

    if reach > 0 and balance(reach) <= 0:
        reach = bracketed_root(balance, 0.0, reach, xtol=1e-12)
    return np.where(scalable[:, None], ab * (1.0 + reach * (SPREAD_RANGE - 1.0)), ab), _between(result, grown, reach)

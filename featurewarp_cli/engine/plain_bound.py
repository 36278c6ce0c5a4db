"""Never worse than plain: where a component comes out more distorted than under the warp W
itself, the guard's result is moved towards W as little as makes it no worse.

``state`` below is the warper's grid state: ``nodes``, ``triangles``, ``grid``, ``features``
and ``tri_component`` (the component of each triangle of a feature quad, -1 elsewhere).
"""

from __future__ import annotations

import cv2
import numpy as np

from . import barrier, quality
from .grid import signed_areas
from .guard import Problem, blend_search

#: Cells over which the move towards W tapers off around offending triangles, and the
#: bisection steps of that move (:func:`no_worse_than_plain`).
TAPER_CELLS = 3
PLAIN_BISECTIONS = 6


def _anisotropy(state, points: np.ndarray) -> np.ndarray:
    """Anisotropy of every triangle of a feature quad under ``points`` (inf elsewhere unused): (M,)."""
    on = state.tri_component >= 0
    out = np.ones(state.triangles.shape[0])
    out[on] = quality.triangle_anisotropy(state.nodes, points, state.triangles[on])
    return out


def middle_nodes(nodes: np.ndarray, node_component: np.ndarray, n: int) -> np.ndarray:
    """(N,) bool: the feature nodes within half their component's radius of its centre (where a
    photo's keypoints gather), for :func:`no_worse_than_plain`. Depends on the grid and mask only."""
    on = np.flatnonzero(node_component >= 0)
    comp = node_component[on]
    centre = np.stack([np.bincount(comp, nodes[on, k], minlength=n) for k in range(2)], 1).astype(float)
    centre /= np.maximum(np.bincount(comp, minlength=n), 1)[:, None]
    distance = np.hypot(*(nodes[on] - centre[comp]).T)
    radius = np.zeros(n)
    np.maximum.at(radius, comp, distance)
    middle = np.zeros(node_component.shape, bool)
    middle[on] = distance <= 0.5 * radius[comp]
    return middle


def _fit_per_component(state, points: np.ndarray) -> np.ndarray:
    """Anisotropy of each component's best-fitting affine map under ``points`` (what keypoints
    measure), over all its nodes and over its middle (``state.node_middle``,
    :func:`middle_nodes`: a rim kept at the middle's cost is worse for keypoints): (2, C)."""
    n = state.features.n_components
    fits = [quality.affine_fits(state.nodes[on], points[on], state.node_component[on], n)
            for on in (state.node_component >= 0, state.node_middle)]
    return np.stack([np.nan_to_num(quality.map_anisotropy(np.nan_to_num(f)), nan=1.0, posinf=1e9) for f in fits])


def _worst_per_component(state, anisotropy: np.ndarray) -> np.ndarray:
    """Worst of ``anisotropy`` over each component's triangles: (C,)."""
    on = state.tri_component >= 0
    worst = np.zeros(state.features.n_components)
    np.maximum.at(worst, state.tri_component[on], anisotropy[on])
    return worst


def _taper(state, quads: np.ndarray) -> np.ndarray:
    """(N, 1) weights: 1 on the corners of ``quads`` (grown by one cell), tapering to 0 over
    :data:`TAPER_CELLS` cells."""
    grid = state.grid
    nodes = np.zeros(grid.n_nodes)
    nodes[grid.quads()[quads].ravel()] = 1.0
    size = 2 * TAPER_CELLS + 1
    grown = cv2.dilate(nodes.reshape(grid.ny, grid.nx), np.ones((3, 3)))
    return np.maximum(grown, cv2.GaussianBlur(grown, (size, size), 0)).ravel()[:, None]


def no_worse_than_plain(state, x: np.ndarray, warped: np.ndarray, record, problem: Problem | None = None) -> np.ndarray:
    """``x``, or ``x`` moved towards W where components came out more anisotropic than under
    W, as little as makes every component no worse than W, without folds. A component is
    worse when its worst triangle is, or its best-fitting affine map (its overall
    proportions) is.

    Tried in turn, each with its blend bisected: the move ``(1 - t) w (W - x)`` with ``w``
    1 around the offending triangles, tapering to 0 over :data:`TAPER_CELLS` cells (then
    around the offending components); a new solve (``problem``) with only the offending
    components untied and their targets blended towards W's, so the other features stay
    as they are, finished by the tapered move where needed; last, every node moved evenly
    towards W."""
    if np.any(signed_areas(warped, state.triangles) <= 0):
        return x
    plain = (_worst_per_component(state, _anisotropy(state, warped)) * (1.0 + 1e-9) + 1e-9,
             _fit_per_component(state, warped) * (1.0 + 1e-9) + 1e-9)

    def ok(points):
        return (bool(np.all(_worst_per_component(state, _anisotropy(state, points)) <= plain[0]))
                and bool(np.all(_fit_per_component(state, points) <= plain[1]))
                and not np.any(signed_areas(points, state.triangles) <= 0))

    if ok(x):
        return x
    offending = np.unique(state.tri_component[_worse(state, x, plain)])
    fixed = _tapered_fix(state, x, warped, plain, ok)
    if fixed is not None:
        x, record.plain_blend = fixed
        record.degraded_components = [int(c) for c in offending if c >= 0]
        return x
    if problem is not None:
        floor = barrier.SAFE_FRACTION * signed_areas(warped, state.triangles)
        found = blend_search(problem, offending, floor, record,
                             accept=lambda p: ok(p) or _tapered_fix(state, p, warped, plain, ok) is not None)
        if found is not None:
            best, blend = found
            best, taper = (best, 1.0) if ok(best) else _tapered_fix(state, best, warped, plain, ok)
            record.degraded_components = [int(c) for c in offending]
            record.plain_blend = blend * taper
            return best
    if ok(warped):
        x, record.plain_blend = _bisect_move(lambda t: warped + t * (x - warped), ok)
        return x
    record.plain_blend = 0.0
    return warped


def _worse(state, points: np.ndarray, plain: tuple) -> np.ndarray:
    """Feature triangles more anisotropic under ``points`` than their component's worst under W,
    and every triangle of a component whose affine fit is (``plain``: both figures under W)."""
    component = np.maximum(state.tri_component, 0)
    fit_worse = np.any(_fit_per_component(state, points) > plain[1], axis=0)
    return (state.tri_component >= 0) & ((_anisotropy(state, points) > plain[0][component]) | fit_worse[component])


def _tapered_fix(state, points: np.ndarray, warped: np.ndarray, plain: tuple, ok):
    """``points`` moved towards W around the offending triangles (then components), tapered,
    as little as passes ``ok``: (positions, t) as :func:`_bisect_move`, or None where even
    the whole move does not pass."""
    worse = _worse(state, points, plain)
    n_quads = state.features.weight.size
    local = np.zeros(n_quads, bool)
    local[np.flatnonzero(worse) % n_quads] = True
    offending = np.unique(state.tri_component[worse])
    bad = np.isin(state.features.component, offending) & state.features.is_constrained
    others = (state.node_component >= 0) & ~np.isin(state.node_component, offending)
    for region in (local, bad):
        weight = _taper(state, region)
        weight[others] = 0.0                # the move leaves the other features as they are

        def move(t, weight=weight):
            return points + (1.0 - t) * weight * (warped - points)

        if ok(move(0.0)):
            return _bisect_move(move, ok)
    return None


def _bisect_move(move, ok) -> tuple[np.ndarray, float]:
    """(``move(t)``, t) at the largest t in [0, 1] (bisection) that passes ``ok``, given t = 0 does."""
    lo, hi, best = 0.0, 1.0, move(0.0)
    for _ in range(PLAIN_BISECTIONS):
        mid = 0.5 * (lo + hi)
        points = move(mid)
        if ok(points):
            lo, best = mid, points
        else:
            hi = mid
    return best, lo

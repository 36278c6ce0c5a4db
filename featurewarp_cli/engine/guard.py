"""The fold-over guard's policy: untangle near the folds, then globally, then relax features.

The primitives (step limits, areas, the penalty descent, windows) are in
:mod:`featurewarp_cli.engine.injectivity`; this module decides how to use them for
one solve. A :class:`Problem` is everything the guard needs to re-solve: the
factored systems, the right-hand side, the offsets and a way to rebuild them for
other edge targets or ties.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field

import cv2
import numpy as np

from . import injectivity, quality, system
from .grid import signed_areas

#: Bisection steps on how far released features go from the warp's shape to their own.
BLEND_BISECTIONS = 8
UNTANGLED_BISECTIONS = 3
#: Fraction of its area under the warp that the guard asks each triangle to keep.
UNTANGLE_FLOOR = 0.05
#: The guard first untangles a window around the folds, reaching these many times the
#: largest fold's extent beyond it (at least WINDOW_MIN_MARGIN quads), in at most
#: WINDOW_ITERATIONS steps each (a hopeless window stops early); where both fail, the whole
#: grid. 12 MP swirl 180, head + helmet mask: the first window stalls at 60 steps (5 900
#: folds down to 2 200), the wider one opens the rest in 27, slivers are lifted in a small
#: window (:func:`_settled`): 0.45 s on 160 000 nodes, where the global pass took 3.4 s.
WINDOW_MARGINS = (0.5, 1.0)
WINDOW_MIN_MARGIN = 8
WINDOW_ITERATIONS = 150
#: Cells over which the move towards W tapers off around offending triangles, and the
#: bisection steps of that move (:func:`no_worse_than_plain`).
TAPER_CELLS = 3
PLAIN_BISECTIONS = 6
#: Slivers the small settling window leaves at or above this fraction of their floor are
#: kept (it lifts them to half; 2 of 1 500 stall at 0.496 on the 12 MP hard swirl); thinner
#: ones send the wide window back to lift them as before.
SETTLED = 0.45
#: Windows larger than this fraction of the grid are left to the global pass.
WINDOW_MAX_FRACTION = 0.5


@dataclass
class GuardRecord:
    """What the guard did (for the report).

    Attributes
    ----------
    flipped_before : int
        Folded triangles of the least-squares solution.
    untangle_iterations : int
    window_quads : int
        Quads the last successful window could reshape (0: no window pass).
    release_rounds : int
        0: features kept their targets; 1 or 2: some were relaxed towards W.
    released_components : list of int
    feature_blend : float
        1: released features at their own shape; 0: at the warp's.
    fallback : bool
        Nothing injective was found; the result is a step from W towards the solution.
    plain_blend : float
        1: the solution as found; below 1: moved this far from W towards it, so that no
        component is more distorted than under W (the targets of ``degraded_components``
        where that list is not empty, times the share of a tapered move after it; else the
        nodes near the offending triangles, or all).
    degraded_components : list of int
    drag_step, preview_eased : float, bool
        Below 1: a drag's update (``FeatureWarper.solve(drag=True)``), or a preview whose windows
        could not open its folds (``preview_eased``), eased: the nodes around the folds moved this
        far from W towards the least-squares solution, all the way ``DRAG_REACH`` cells out.
    """

    flipped_before: int = 0
    untangle_iterations: int = 0
    window_quads: int = 0
    release_rounds: int = 0
    released_components: list = field(default_factory=list)
    feature_blend: float = 1.0
    fallback: bool = False
    plain_blend: float = 1.0
    degraded_components: list = field(default_factory=list)
    drag_step: float = 1.0
    preview_eased: bool = False


@dataclass
class Problem:
    """One linear least-squares problem of the warper, ready to re-solve.

    Attributes
    ----------
    grid, features, triangles, warped, normal, stiffness, fixed
        The grid's state (``fixed``: nodes held in both axes for window passes).
    tied : (N,) int ndarray
        Component whose shared translation a node takes in both axes, or -1.
    systems : AxisSystems
    rhs, offset : (N, 2) ndarray
    edges, warp_edges : (K, 4, 2) ndarray
        The targets solved for, and W's own.
    rebuild : callable
        ``rebuild(edges, released)`` -> (systems, rhs, offset, tied) for other edge
        targets with the components ``released`` untied.
    timings : dict
    preview : bool
        An interactive update (``FeatureWarper.solve(quick=True)``): windows only, and
        :func:`guard` returns None where they fail (see :func:`_untangled`, :func:`_settled`).
    """

    grid: object
    features: object
    triangles: np.ndarray
    warped: np.ndarray
    normal: object
    stiffness: np.ndarray
    fixed: np.ndarray
    tied: np.ndarray
    systems: object
    rhs: np.ndarray
    offset: np.ndarray
    edges: np.ndarray
    warp_edges: np.ndarray
    rebuild: object
    timings: dict
    preview: bool = False

    def solver(self, systems, rhs, offset):
        """``solve(force)``: positions for these constants plus a force per node."""
        def solve(force=None):
            t0 = time.perf_counter()
            result = systems.solve(rhs if force is None else rhs + force, offset)
            self.timings["solve"] = self.timings.get("solve", 0.0) + time.perf_counter() - t0
            return result
        return solve


def guard(problem: Problem, x: np.ndarray, record: GuardRecord) -> np.ndarray | None:
    """Positions with no folded triangle, as close to ``x`` (the least-squares solution) as found;
    None for a preview whose folds the windows do not open (the caller eases it instead)."""
    tris = problem.triangles
    record.flipped_before = int(np.count_nonzero(injectivity.flipped(x, tris)))
    if record.flipped_before == 0:
        return x
    warp_areas = signed_areas(problem.warped, tris)
    if warp_areas.min() <= 0:
        return x                          # the grid cannot follow the warp: nothing injective to keep
    floor = UNTANGLE_FLOOR * warp_areas
    x, ok = _untangled(problem, problem.systems, problem.rhs, problem.offset, problem.tied, x, floor, record)
    if ok:
        return x
    return None if problem.preview else _release(problem, x, floor, record)


def _untangled(problem, systems, rhs, offset, tied, start, floor, record):
    """Untangle in a window around the folds (wider windows next, each from where the last one
    left off), else on the whole grid; a preview stops after a window that gave up, or after
    the windows; (x, no folds left)."""
    tris = problem.triangles
    folds = int(np.count_nonzero(injectivity.flipped(start, tris)))
    for margin in WINDOW_MARGINS:
        x, iterations, window_quads = _untangle_window(problem, rhs, offset, tied, start, floor, margin,
                                                       settle=False)
        record.untangle_iterations += iterations
        if x is None:
            break
        left = int(np.count_nonzero(injectivity.flipped(x, tris)))
        if left == 0:
            record.window_quads = window_quads
            return _settled(problem, rhs, offset, tied, start, x, floor, margin, record), True
        if left < folds:
            start, folds = x, left
        if problem.preview and iterations < WINDOW_ITERATIONS:      # it gave up: a preview eases instead
            break
    if problem.preview:
        return start, False
    grid = problem.grid
    x, iterations = injectivity.untangle(problem.solver(systems, rhs, offset), problem.normal.dot, start, tris,
                                         floor, problem.stiffness,
                                         areas=lambda points: injectivity.grid_areas(grid, points))
    record.untangle_iterations += iterations
    return x, not injectivity.flipped(x, tris).any()


def _settled(problem, rhs, offset, tied, start, x, floor, margin, record):
    """``x`` (no folds, unfolded by the window ``margin`` from ``start``) with its crushed
    triangles (below half their floor) lifted.

    The wide window stops as soon as nothing is folded, since lifting a few dozen slivers
    there took as many steps as opening thousands of folds (12 MP swirl 180: 20 of 50 steps
    on 86 000 nodes). So first a small window around them, features held, by steps that
    never make the thinnest triangle thinner. Where slivers below :data:`SETTLED` of their
    floor are left (wedged against a feature), the wide window runs again from ``start``
    until they are lifted too (a fresh pass from ``x`` folds again or stalls); not in a preview."""
    thinnest = lambda points: float((injectivity.grid_areas(problem.grid, points) / floor).min())  # noqa: E731
    if thinnest(x) >= 0.5:
        return x
    settled, iterations, _ = _untangle_window(problem, rhs, offset, tied, x, floor, WINDOW_MARGINS[0],
                                              carry_features=False, keep_thinnest=True)
    record.untangle_iterations += iterations
    if settled is not None and not injectivity.flipped(settled, problem.triangles).any():
        x = settled
    worst = thinnest(x)
    if worst >= SETTLED or problem.preview:
        return x
    again, iterations, _ = _untangle_window(problem, rhs, offset, tied, start, floor, margin)
    record.untangle_iterations += iterations
    if again is not None and not injectivity.flipped(again, problem.triangles).any() and thinnest(again) > worst:
        return again
    return x


def _release(problem: Problem, x, floor, record: GuardRecord):
    """Untie the features near the folds (then all) and blend their targets towards W's."""
    features, tris = problem.features, problem.triangles
    released = np.unique(features.component[injectivity.trouble_quads(problem.grid, x, tris)
                                            & features.is_constrained])
    for round_ in (1, 2):
        record.release_rounds = round_
        if round_ == 2:
            released = np.arange(features.n_components)
        found = blend_search(problem, released, floor, record)
        if found is None:
            continue                      # folds come from features not released yet
        best, record.feature_blend = found
        record.released_components = [int(c) for c in released]
        return best
    record.fallback = True
    warped = problem.warped
    return warped + injectivity.max_step(warped, x, tris) * 0.95 * (x - warped)


def blend_search(problem: Problem, released: np.ndarray, floor, record: GuardRecord, accept=None):
    """Untie the components ``released`` and solve with their targets blended ``s`` of their own
    and ``1 - s`` of W's: the largest s (bisection) whose solution, untangled where needed,
    has no fold and passes ``accept`` (positions -> bool; default: anything).

    Returns (positions, s), or None when even s = 0 (W's targets) does not pass."""
    tris = problem.triangles
    blend = np.isin(problem.features.component, released) & problem.features.is_constrained
    accept = accept or (lambda points: True)

    def constants(s):
        edges = np.where(blend[:, None, None], s * problem.edges + (1.0 - s) * problem.warp_edges, problem.edges)
        return problem.rebuild(edges, released)

    def solve_at(s):
        systems, rhs, offset, _ = constants(s)
        return problem.solver(systems, rhs, offset)()

    lo, hi = 0.0, 1.0
    best = solve_at(0.0)
    if injectivity.flipped(best, tris).any():
        systems, rhs, offset, tied = constants(0.0)
        best, ok = _untangled(problem, systems, rhs, offset, tied, best, floor, record)
        if not ok or not accept(best):
            return None
        return _untangled_blend(problem, constants, solve_at, floor, record, accept, 0.0, best)
    if not accept(best):
        return None
    for _ in range(BLEND_BISECTIONS):        # cheap: plain solves
        mid = 0.5 * (lo + hi)
        x = solve_at(mid)
        if injectivity.flipped(x, tris).any() or not accept(x):
            hi = mid
        else:
            lo, best = mid, x
    return _untangled_blend(problem, constants, solve_at, floor, record, accept, lo, best)


def _untangled_blend(problem, constants, solve_at, floor, record, accept, lo, best):
    """Bisect the blend beyond ``lo`` (whose positions are ``best``), untangling each trial."""
    hi = 1.0
    for _ in range(UNTANGLED_BISECTIONS):
        mid = 0.5 * (lo + hi)
        systems, rhs, offset, tied = constants(mid)
        x, ok = _untangled(problem, systems, rhs, offset, tied, solve_at(mid), floor, record)
        if ok and accept(x):
            lo, best = mid, x
        else:
            hi = mid
    return best, lo


def _untangle_window(problem: Problem, rhs, offset, tied, x, floor, margin_factor: float, settle: bool = True,
                     carry_features: bool = True, keep_thinnest: bool = False):
    """:func:`injectivity.untangle` on a window around the folded or crushed triangles.

    A fold is a local defect, so the guard first works on the nodes within
    ``margin_factor`` times the largest fold's extent of the folded and
    crushed triangles, everything else held where it is, except that a tied
    feature reaching into the window keeps its shared unknown (it may shift as a
    whole). The window's system is the normal matrix's rows for its unknowns.

    Returns
    -------
    x : (N, 2) ndarray or None
        New positions; None when the window would be about as large as the grid.
    iterations : int
    quads : int
        Quads whose shape the window may change.
    """
    grid, weights = problem.grid, problem.features.weight
    n_quads = weights.size
    crushed = np.flatnonzero(injectivity.grid_areas(grid, x) < 0.5 * floor) % n_quads
    quads = np.zeros(n_quads, bool)
    quads[crushed] = True
    margin = max(WINDOW_MIN_MARGIN, int(margin_factor * injectivity.extent(grid, crushed)))
    _, near, inner = injectivity.window(grid, quads, margin)
    moving = inner & ~problem.fixed & (tied < 0)
    if carry_features:
        moving |= np.isin(tied, np.unique(tied[near & (tied >= 0)])) & (tied >= 0)
    corners = grid.quads()
    touched = moving[corners].any(axis=1)
    ties = tied[corners]
    rigid = (ties[:, 0] >= 0) & (ties == ties[:, :1]).all(axis=1)    # inside one tied feature
    changing = np.flatnonzero(touched & ~rigid)
    if changing.size == 0 or changing.size > WINDOW_MAX_FRACTION * n_quads:
        return None, 0, 0                 # nothing the window could move, or not worth a window
    in_system = np.zeros(grid.n_nodes, bool)
    in_system[corners[touched].ravel()] = True
    nodes = np.flatnonzero(in_system)
    local_moving = moving[nodes]
    unknown = system.number_unknowns(~local_moving, np.where(local_moving, tied[nodes], -1))
    from .solver import ReducedSystem

    matrix = problem.normal[nodes][:, nodes]
    reduced = ReducedSystem(matrix, unknown)
    held = np.where(local_moving[:, None], offset[nodes], x[nodes])
    local_rhs = rhs[nodes]
    timings = problem.timings

    def solve(force):
        t0 = time.perf_counter()
        result = reduced.solve(local_rhs + force, held)
        timings["solve"] = timings.get("solve", 0.0) + time.perf_counter() - t0
        return result

    local = np.full(grid.n_nodes, -1)
    local[nodes] = np.arange(nodes.size)
    quad_corners = local[corners[changing]]
    triangles = np.concatenate([quad_corners[:, [0, 1, 2]], quad_corners[:, [0, 2, 3]]])
    window_floor = np.concatenate([floor[changing], floor[changing + n_quads]])
    moved, iterations = injectivity.untangle(solve, matrix.dot, x[nodes], triangles, window_floor,
                                             problem.stiffness[nodes], max_iterations=WINDOW_ITERATIONS,
                                             settle=settle, keep_thinnest=keep_thinnest)
    x = x.copy()
    x[nodes] = moved
    return x, iterations, int(changing.size)


# --- never worse than plain -----------------------------------------------------------------
# ``state`` below is the warper's grid state: ``nodes``, ``triangles``, ``grid``, ``features``
# and ``tri_component`` (the component of each triangle of a feature quad, -1 elsewhere).


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
        floor = UNTANGLE_FLOOR * signed_areas(warped, state.triangles)
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

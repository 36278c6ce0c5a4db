"""The fold-over guard's policy: a window's minimum around the folds, else the path from W, then relax features.

The primitives (step limits, areas, windows) are in :mod:`injectivity`, the
energy every result is converged to in :mod:`barrier`, the never-worse-than-plain step after
the guard in :mod:`plain_bound`. A :class:`Problem` is what the guard needs to re-solve.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from . import barrier, injectivity
from .grid import signed_areas
from .path import BLOCKED_SHARE, converge_grid as _converge_grid, path_from_warp
from .window import PREVIEW_STEPS, WINDOW_STEPS, timed as _timed, window_around as _window  # noqa: F401 (the report's)

#: Where the least-squares solution folds, the guard converges the energy in a window around
#: the crushed triangles, reaching WINDOW_MARGIN times their largest cluster's extent beyond
#: them (at least WINDOW_MIN_MARGIN quads) and the ground around the tied features it reaches
#: (:mod:`window`: WINDOW_STEPS, WINDOW_MAX_FRACTION). Wider is slower a step and holds less of
#: the grid at the least-squares solution.
WINDOW_MARGIN = 0.5
WINDOW_MIN_MARGIN = 8
#: The shares of the floor below which the window's runs continue the barrier, in turn
#: (:func:`_open_window`): the softest first (fewer Newton steps: the 12 MP hard bulge 30
#: against 86 at 0.2, both to 1e-12), a stiffer one from its minimum where that still folds (the astronaut's
#: head by the top edge under ``fish`` at 256 px: 0.125; the close-up under ``flag`` at 192
#: px: 0.03; quarters of CRUSHED_SHARE). Each lower share is closer to the barrier itself.
CONTINUED_BELOW = tuple(injectivity.CRUSHED_SHARE / 4 ** k for k in range(3))
#: Even steps of the blend from where the least-squares solution stops passing the margin up
#: to the released features' own targets (:func:`blend_search`); more follow the path of
#: minima more closely (the stop is interpolated between two of them) at more Newton steps.
BLEND_STEPS = 8
#: A step of that blend not converged in these many Newton steps ends the path at the point
#: before it (its iterate is not used). Lower is faster where the next minimum is far and
#: crushed (the image pressed to 1 px: 530 steps, 35 s at 1 MP, then failing anyway) and ends
#: more paths early; the steps on the photos and the other extremes converge in 4-35.
TRIAL_STEPS = 100


@dataclass
class GuardRecord:
    """What the guard did (for the report).

    Attributes
    ----------
    flipped_before : int
        Folded triangles of the least-squares solution.
    untangle_iterations : int
        Newton steps of the window's run from the folded least-squares solution (:func:`_open_window`).
    window_quads : int
        Quads the window could reshape where it opened the folds (0: no window, or it did not).
    path_steps : int
        Predictor-corrector steps of the path from W (:mod:`path`; 0: the window sufficed).
    release_rounds : int
        0: features kept their targets; 1 or 2: some were relaxed towards W.
    released_components : list of int
    feature_blend, release_cut : float, bool
        1: released features at their own shape, 0: at W's; cut short by a step (TRIAL_STEPS).
    fallback : bool
        Nothing injective was found; the result is a step from W towards the solution.
    plain_blend : float
        1: the solution as found; below 1: moved this far from W towards it, so that no
        component is more distorted than under W (the targets of ``degraded_components``
        where that list is not empty, times the share of a tapered move after it; else the
        nodes near the offending triangles, or all).
    degraded_components : list of int
    newton_steps, converged : int, bool
        Newton steps of :func:`barrier.converge` (all its runs), and whether the runs behind
        the result (not the release's trials it did not keep) met its tolerance.
    drag_step, preview_eased : float, bool
        Below 1: a drag's update (``FeatureWarper.solve(drag=True)``), or a preview whose window
        could not open its folds (``preview_eased``), eased: the nodes around the folds moved this
        far from W towards the least-squares solution, all the way ``DRAG_REACH`` cells out.
    """

    flipped_before: int = 0
    untangle_iterations: int = 0
    window_quads: int = 0
    release_rounds: int = 0
    released_components: list = field(default_factory=list)
    feature_blend: float = 1.0
    release_cut: bool = False
    fallback: bool = False
    plain_blend: float = 1.0
    degraded_components: list = field(default_factory=list)
    newton_steps: int = 0
    converged: bool = True
    drag_step: float = 1.0
    preview_eased: bool = False
    path_steps: int = 0

    def count(self, how: barrier.Convergence) -> None:
        """Add one :func:`barrier.converge` run's Newton steps and convergence."""
        self.newton_steps, self.converged = self.newton_steps + how.steps, self.converged and how.converged


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
    inverses : dict
        :meth:`inverse`'s, by system.
    margin : callable or None
        ``margin(positions)`` <= 0 where a release's blend is acceptable: no component worse
        than under W, or fixable by a tapered move (:func:`blend_search`,
        :func:`plain_bound.release_margin`).
    preview : bool
        An interactive update (``FeatureWarper.solve(quick=True)``): the window only, and
        :func:`guard` returns None where it fails (see :func:`_unfolded`).
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
    margin: object = None
    inverses: dict = field(default_factory=dict)

    def inverse(self, systems):
        """:class:`barrier.InverseRows` of ``systems``' inverse (:meth:`AxisSystems.entries`), for
        :func:`barrier.converge`: one per system, so the runs of a release's path share its
        back-substitutions."""
        if id(systems) not in self.inverses:
            unknowns = np.stack([systems.x.unknown, systems.y.unknown])
            self.inverses[id(systems)] = (systems, barrier.InverseRows(_timed(self.timings, systems.entries),
                                                                       unknowns, systems.normal_between))
        return self.inverses[id(systems)][1]

    def solver(self, systems, rhs, offset):
        """``solve(force)``: positions for these constants plus a force per node."""
        return _timed(self.timings, lambda force=None: systems.solve(rhs if force is None else rhs + force, offset))

    def linear(self, systems):
        """``move(force)``: the solve's linear part, the positions' change under a force per node
        (exactly 0 where held, one value per tied unknown; :func:`barrier.converge`)."""
        return _timed(self.timings, systems.move)


def guard(problem: Problem, x: np.ndarray, record: GuardRecord, before_release=None) -> np.ndarray | None:
    """Positions with no folded triangle, as close to ``x`` (the least-squares solution) as found;
    None for a preview whose folds the window does not open (the caller eases it instead), and
    where the features do not fit and ``before_release()`` (asked then, once) returns True: the
    caller has another solution to guard (smaller similarities), and no feature is released."""
    tris = problem.triangles
    record.flipped_before = int(np.count_nonzero(injectivity.flipped(x, tris)))
    warp_areas = signed_areas(problem.warped, tris)
    if warp_areas.min() <= 0:
        return x                          # the grid cannot follow the warp: nothing injective to keep
    floor = barrier.SAFE_FRACTION * warp_areas
    # Folded, or crushed below the continuation's share: the window's continued energy, smooth
    # across a zero area (the barrier itself is too steep to start from there: a triangle left at
    # 4e-12 of its floor stopped its Newton steps, and one ulp flipped the route at the fold).
    if not (signed_areas(x, tris) < injectivity.CRUSHED_SHARE * floor).any():
        (x, windowed), ok = _converged(problem, x, floor, record), True
        if windowed is None:
            return x                      # no triangle below its floor: x is the energy's minimum
    else:
        x, ok = _unfolded(problem, x, floor, record)
        windowed = bool(record.window_quads)
    if ok and ((problem.preview and windowed) or record.path_steps):
        return x                          # a preview's window minimum (bounded time); the path's end: the grid's
    if ok:
        # A window's minimum holds the rest at the least-squares solution (up to 27 px from the
        # energy's minimum at 12 MP): it only starts the whole grid's, whose run says converged.
        record.converged = True
        return _converge_grid(problem, problem.systems, problem.rhs, problem.offset, problem.tied, x, floor, record,
                              PREVIEW_STEPS if problem.preview else None)[0]
    if problem.preview or (before_release is not None and before_release()):
        return None
    return _release(problem, x, floor, record)


def _unfolded(problem, start, floor, record):
    """The energy's minimum (outside a preview: a point the whole grid's run converges from) in a
    window around the folds (:func:`_open_window`), else the path of
    minima from W (:func:`path.path_from_warp`); (x, the features fit), (None, False) for a
    preview whose window does not open its folds (the caller eases it). No untangling: not the
    first fold-free iterate of a descent, whose choice, or whether it found one before fold
    counts gave up, turned one ulp into 1.2-137 px on the whole grid."""
    x, steps, quads = _open_window(problem, start, floor, record)
    record.untangle_iterations += steps
    if x is not None:
        record.window_quads = quads
        return x, True
    if problem.preview:
        return None, False                # guard() returns None: the caller eases the preview
    return path_from_warp(problem, floor, record)


def _converged(problem, x, floor, record):
    """(positions, windowed): ``x`` (no folds) as it is where no triangle is below its floor
    (windowed None: x is the energy's minimum); else moved towards the barrier energy's minimum
    in a window around its crushed triangles (to :attr:`window.Window.tolerance`; windowed True),
    or not at all where that window would not be much smaller than the grid (False);
    :func:`guard` converges the whole grid."""
    crushed = injectivity.grid_areas(problem.grid, x) < floor
    if not crushed.any():
        return x, None
    window = _window(problem, x, crushed, WINDOW_MIN_MARGIN)
    if window is None:
        return x, False
    x = x.copy()
    x[window.nodes] = window.converge(x, floor, record)
    return x, True


def _release(problem: Problem, x, floor, record: GuardRecord):
    """Untie the features near where the path from W stopped (``x``: its triangles below
    ``BLOCKED_SHARE`` of their floor; then all) and blend their targets towards W's."""
    features, tris = problem.features, problem.triangles
    blocked = injectivity.grid_areas(problem.grid, x) < BLOCKED_SHARE * floor
    released = np.unique(features.component[injectivity.trouble_quads(problem.grid, blocked)
                                            & features.is_constrained])
    for round_ in (1, 2) if released.size else (2,):      # nothing blocked: all at once
        record.release_rounds = round_
        if round_ == 2:
            released = np.arange(features.n_components)
        found = blend_search(problem, released, floor, record)
        if found is None:
            continue                      # folds come from features not released yet
        best, record.feature_blend = found
        record.released_components = [int(c) for c in released]
        return best
    from .plain_bound import furthest_move      # it imports this module
    record.fallback = True                # no blend passes: from W towards x, up to half a floor
    warped = problem.warped
    return furthest_move(lambda t: warped + t * (x - warped), lambda points: -1.0, tris, floor)[0]


def blend_search(problem: Problem, released: np.ndarray, floor, record: GuardRecord, margin=None, origin=None,
                 steps: int = BLEND_STEPS, thinnest: float = injectivity.CRUSHED_SHARE):
    """Untie the components ``released`` and converge the barrier's energy with their targets
    blended ``s`` of their own and ``1 - s`` of W's, for the largest s whose minimum passes
    ``margin`` (positions -> float, <= 0 passes; default ``problem.margin``, else anything),
    combined with a triangle thinner than ``thinnest`` of its floor (:data:`injectivity.CRUSHED_SHARE`) failing.

    A path of minima, each converged from the one before, so every point is injective:
    - the least-squares solution is affine in s (the targets enter the right-hand side only):
      followed up to the first root of the areas' quadratics at half the floor, or of the
      margin (:func:`plain_bound.furthest_move`); where it fails the margin at s = 0, the path
      starts at the minimum for s = 0 converged from ``origin`` (positions with no fold that
      tie ``released`` and keep the coordinates the untied system holds);
    - from there, ``steps`` even steps of s up to 1, each converged from the last point (one
      not converged in :data:`TRIAL_STEPS` Newton steps ends the path at that point). Where
      one fails ``margin``, the furthest point between it and the last point that passed,
      converged at its blend (:func:`settle`). Without steps, the start likewise.
    Each point is a continuous function of the inputs: roots, and a converged minimum that, where
    it fails the margin, gives way to the chord; whether a step converges in TRIAL_STEPS is not.

    Returns (positions, s), or None when the start at s = 0 (W's targets) fails ``margin``
    (it folds, or is too thin, with no ``origin``, or the minimum from ``origin`` fails too)."""
    from .plain_bound import furthest_move, thinnest_margin      # it imports this module

    blend = np.isin(problem.features.component, released) & problem.features.is_constrained
    margin = thinnest_margin(problem, floor, margin or problem.margin or (lambda points: -1.0), thinnest)
    kappa = barrier.weights(problem.warped, problem.triangles, problem.stiffness, floor)    # once, not a run

    def constants(s):
        edges = np.where(blend[:, None, None], s * problem.edges + (1.0 - s) * problem.warp_edges, problem.edges)
        return problem.rebuild(edges, released)

    systems, rhs, offset, tied = constants(0.0)
    _, rhs_own, offset_own, _ = constants(1.0)

    def at(t, start, steps=None):
        """(the minimum at blend ``t`` from ``start`` in at most ``steps`` Newton steps, its margin (inf
        where it stopped there), stopped); one failing the margin is not kept: its run does not count."""
        converged, args = record.converged, (systems, rhs + t * (rhs_own - rhs), offset + t * (offset_own - offset))
        point, how = _converge_grid(problem, *args, tied, start, floor, record, steps, kappa=kappa)
        stopped = steps is not None and not how.converged and how.steps >= steps
        value = np.inf if stopped else margin(point)      # a stopped run's point is not used
        if value > 0:
            record.converged = converged
        return point, value, stopped

    def settle(t, start):
        """The minimum at ``t`` from ``start`` (which passes) where it passes, else the chord
        from ``start`` towards it as far as passes: no jump where its margin crosses 0."""
        point, value, _ = at(t, start)
        return point if value <= 0 else furthest_move(lambda u: start + u * (point - start), margin,
                                                      problem.triangles, floor)[0]

    best, s = problem.solver(systems, rhs, offset)(), 0.0
    along = problem.solver(systems, rhs_own, offset_own)() - best     # d(solution)/ds
    if margin(best) <= 0:
        start = best
        x, s = furthest_move(lambda t: start + t * along, margin, problem.triangles, floor)
        if not steps:
            return settle(s, x), s
    elif origin is not None and systems.admits(origin, offset):
        x, value, _ = at(0.0, origin)
        if value > 0:
            return None
    else:
        return None
    first, count = s, steps if s < 1.0 else min(steps, 1)
    for step in range(1, count + 1):
        t = first + (1.0 - first) * step / count
        trial, value, stopped = at(t, x, TRIAL_STEPS if t > s else None)
        if stopped:                             # a minimum far away: the path ends at its last point
            record.release_cut = True
            return settle(s, x), s
        if value > 0:                           # between the two points, as far as passes
            between, share = furthest_move(lambda u: x + u * (trial - x), margin, problem.triangles, floor)
            s = s + share * (t - s)
            return settle(s, between), s
        x, s = trial, t
    return x, s


def _open_window(problem: Problem, x, floor, record):
    """Converge the energy with the barrier continued below a share of the floor
    (:func:`barrier.converge` with ``below``; the shares of :data:`CONTINUED_BELOW` in turn, the
    next from the last one's minimum where that folds) from the least-squares solution ``x`` (it
    folds, or crushes a triangle below the share) in the window of :func:`window.window_around` around the triangles below
    :data:`injectivity.CRUSHED_SHARE` of their floor, reaching WINDOW_MARGIN times their extent
    and the ground around the tied features it reaches (not where that would take in more than
    WINDOW_MAX_FRACTION of the grid: large features on a small image; a preview: of its nodes).

    A minimum that folds nothing opens the folds: where it keeps every triangle at the share or
    above, it is the barrier energy's own minimum; else that is converged from it (no fold:
    :meth:`window.Window.converge`). Each outcome is decided on a minimum, but for a run cut at
    :data:`WINDOW_STEPS`; a result that keeps every triangle at the share or above may be a point
    converged to the path's tolerance only (:meth:`window.Window.continued`): the whole grid is
    converged from it, outside a preview.

    Returns
    -------
    x : (N, 2) ndarray or None
        New positions; None where there is no window, or a run did not converge in
        :data:`WINDOW_STEPS`, or the last minimum folds.
    steps : int
        Newton steps of the run from ``x``.
    quads : int
        Quads whose shape the window may change.
    """
    crushed = injectivity.grid_areas(problem.grid, x) < injectivity.CRUSHED_SHARE * floor
    margin = max(WINDOW_MIN_MARGIN, int(WINDOW_MARGIN * injectivity.extent(problem.grid, np.flatnonzero(crushed)
                                                                         % problem.features.weight.size)))
    window = (not problem.preview and _window(problem, x, crushed, margin, around_ties=True)
              or _window(problem, x, crushed, margin))
    if window is None:
        return None, 0, 0
    local_floor = window.floor(floor)
    kappa = barrier.weights(window.warped, window.triangles, window.stiffness, local_floor)
    moved, steps = x[window.nodes], 0
    for below in CONTINUED_BELOW:                # a preview: PREVIEW_STEPS a run, its last point taken
        moved, how = window.continued(moved, local_floor, kappa, below)
        record.newton_steps, steps = record.newton_steps + how.steps, steps + how.steps
        ratio = signed_areas(moved, window.triangles) / local_floor
        if not (how.converged or problem.preview) or ratio.min() > 0:
            break
    x = x.copy()
    x[window.nodes] = moved                     # outside the window x is held: the whole grid checked
    if not ((how.converged or problem.preview) and ratio.min() > 0) or injectivity.flipped(x, problem.triangles).any():
        return None, steps, 0
    if ratio.min() < below:               # in the last run's continued part: the barrier's own minimum
        x[window.nodes] = window.converge(x, floor, record)
    return x, steps, int(window.quads.size)

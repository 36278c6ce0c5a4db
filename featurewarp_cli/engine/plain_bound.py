"""Never worse than plain: where a component comes out more distorted than under the warp W
itself, the guard's result is moved towards W as little as makes it no worse.

``state`` below is the warper's grid state: ``nodes``, ``triangles``, ``grid``, ``features``,
``tri_component`` (the component of each triangle of a feature quad, -1 elsewhere),
``node_component`` and ``node_middle`` (:func:`middle_nodes`); :class:`PlainMargin` stores its
:class:`FeatureFigures` there as ``figures``.
"""

from __future__ import annotations

import cv2
import numpy as np

from . import barrier, injectivity, quality
from .grid import signed_areas
from .guard import Problem, blend_search
from .injectivity import CRUSHED_SHARE, grid_areas, max_step
from .roots import bracketed_root

#: Cells over which the move towards W tapers off around offending triangles
#: (:func:`no_worse_than_plain`).
TAPER_CELLS = 3
#: Evenly spaced points at which :func:`furthest_move` looks for the first where the margin
#: fails (its first root lies before it).
MOVE_SAMPLES = 8
#: How far :func:`furthest_move` looks for the margin's root: within ROOT_TOLERANCE of the move
#: (1e-7 px of a 100 px move; a 1e-12 search took 37 margins, 0.2 s at 12 MP, where this takes 27).
ROOT_TOLERANCE = 1e-9
#: How far :func:`furthest_move` steps back from the margin's root, in turn, until the margin
#: passes there (its rounding noise is about 1e-13 of the move; the root is within ROOT_TOLERANCE).
ROOT_BACKOFF = (4 * ROOT_TOLERANCE, 1e-6, 1e-4, 1e-2)
#: Where :func:`furthest_move` looks last, as a share of the way to where a triangle reaches its
#: floor short of it: there the margin's thinness is 0 by construction (its sign was rounding,
#: and it decided whether the way before it was looked at: fish at 320 px, 4 px apart).
REACH_INSIDE = 1e-9
#: How far past a root of the plain margin :func:`_fixable_root` looks for the tapered moves
#: that fix the point (and past their root, for one that no longer fixes it).
ROOT_STEP = 1e-6
#: The anisotropy (sigma_max / sigma_min - 1) below which a component counts as no worse than
#: under W whatever W's (5e-4: 0.05 px across 100 px). Without it a component that W maps by
#: an exact similarity (one centred on a swirl, fisheye or bulge: its fit is one by symmetry)
#: has no headroom: a solution that broke the symmetry by 2e-4 failed, and the whole grid moved
#: to W (the coins at 256 px, swirl 90, on OpenBLAS's Sandybridge kernels: 24 px).
EXACT_ENOUGH = 5e-4


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


class FeatureFigures:
    """What the plain bound measures of the features under any positions (:meth:`of`): the
    anisotropy of every feature triangle, and of each component's best-fitting affine map
    over all its nodes and over its middle (:func:`middle_nodes`: a rim kept at the middle's
    cost is worse for keypoints), which is what keypoints measure. Both are linear in the
    positions, so what depends on the source alone is made once per grid state (the state's
    ``figures``, made at its first use; a state's grid and mask do not change).

    ``state``: the warper's grid state (``nodes``, ``triangles``, ``tri_component``,
    ``node_component``, ``node_middle``, ``features``).
    """

    def __init__(self, state):
        self.on = state.tri_component >= 0
        self.component = state.tri_component[self.on]
        triangles = state.triangles[self.on]
        self.corners = [np.ascontiguousarray(triangles[:, k]) for k in range(3)]
        a, b, c = (state.nodes[corner].astype(float) for corner in self.corners)
        (s00, s10), (s01, s11) = (b - a).T, (c - a).T          # the source's edge matrix S
        det = s00 * s11 - s01 * s10
        self.inverse = (s11 / det, -s10 / det, -s01 / det, s00 / det)       # J = T S^-1 in T's terms
        self.n = state.features.n_components
        self.operators = [_fit_operator(state.nodes, state.node_component, self.n, on)
                          for on in (state.node_component >= 0, state.node_middle)]

    def entries(self, points: np.ndarray) -> tuple[tuple, list]:
        """The 2x2 maps that :meth:`of` measures, entry by entry ((j00, j01, j10, j11) arrays):
        of each feature triangle (M_f,), and of each component's two fits ((C,) each). Linear in
        ``points`` (a translation drops out)."""
        x, y = np.ascontiguousarray(points[:, 0]), np.ascontiguousarray(points[:, 1])
        a, b, c = self.corners
        t00, t10 = x.take(b) - x.take(a), y.take(b) - y.take(a)             # T's columns: edges ab, ac
        t01, t11 = x.take(c) - x.take(a), y.take(c) - y.take(a)
        u0, u1, v0, v1 = self.inverse
        triangles = (t00 * u0 + t01 * u1, t00 * v0 + t01 * v1, t10 * u0 + t11 * u1, t10 * v0 + t11 * v1)
        maps = [(operator @ points).reshape(self.n, 2, 2) for operator, _ in self.operators]  # [k, b, a]: (a, b)
        return triangles, [(m[:, 0, 0], m[:, 1, 0], m[:, 0, 1], m[:, 1, 1]) for m in maps]

    def of(self, points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(M,) the anisotropy (sigma_max / sigma_min) of each feature triangle under ``points`` (1
        elsewhere, inf where degenerate) and (2, C) of each component's two fits (at most 1e9:
        1e9 where a component has fewer than three nodes, or nodes on a line, or its fit is
        singular or nearly)."""
        entries, maps = self.entries(points)
        triangles = np.ones(self.on.size)
        triangles[self.on] = quality.entry_anisotropy(*entries)
        fits = []
        for fit, (_, good) in zip(maps, self.operators):
            ratio = quality.entry_anisotropy(*fit)
            fits.append(np.where(good, np.minimum(np.nan_to_num(ratio, nan=1.0, posinf=1e9), 1e9), 1e9))
        return triangles, np.stack(fits)

    def first_root(self, start: np.ndarray, end: np.ndarray, limits: tuple) -> float:
        """The first t in [0, 1] at which a feature triangle or a fit on start -> end turns more
        anisotropic than its limit (``limits``: (C,) for the triangles of each component, (2, C)
        for the fits; :meth:`of` caps a fit at 1e9, so a limit of 1e9 or more never fails);
        1.0 where none does. With u and v the lengths of :func:`quality.conformal_parts`
        (sigma_max, sigma_min = (u + v) / 2, |u - v| / 2), a map keeps sigma_max / sigma_min <= c
        exactly while m^2 u^2 - v^2 >= 0 (m = (c - 1) / (c + 1); u > v: orientation kept) or,
        for one that reverses orientation, m^2 v^2 - u^2 >= 0; between the two the ratio passes
        infinity, so the first failure is the first root of the start's quadratic. The maps are
        affine in t: first roots of quadratics (:func:`injectivity.first_root`), with no search."""
        (tri0, fits0), (tri1, fits1) = self.entries(start), self.entries(end - start)
        roots = [_ratio_root(tri0, tri1, limits[0][self.component])]
        for k, (_, good) in enumerate(self.operators):
            kept = good & (limits[1][k] < 1e9)
            roots.append(_ratio_root(*(tuple(e[kept] for e in fit) for fit in (fits0[k], fits1[k])),
                                     limits[1][k][kept]))
        return min(roots)


def _ratio_root(at_start, along, limit: np.ndarray) -> float:
    """:meth:`FeatureFigures.first_root` for maps ``at_start + t along`` (entry tuples) and
    anisotropy limits ``limit``."""
    m2 = ((limit - 1.0) / (limit + 1.0)) ** 2
    (u0, v0), (u1, v1) = (tuple(np.stack(part) for part in quality.conformal_parts(*entries))
                          for entries in (at_start, along))              # u^2 = |u0 + t u1|^2
    reversed_ = (v0 * v0).sum(0) > (u0 * u0).sum(0)              # det < 0: the roles swap
    u0, v0 = np.where(reversed_, v0, u0), np.where(reversed_, u0, v0)
    u1, v1 = np.where(reversed_, v1, u1), np.where(reversed_, u1, v1)
    c = m2 * (u0 * u0).sum(0) - (v0 * v0).sum(0)
    b = 2.0 * (m2 * (u0 * u1).sum(0) - (v0 * v1).sum(0))
    a = m2 * (u1 * u1).sum(0) - (v1 * v1).sum(0)
    return injectivity.first_root(np.maximum(c, 0.0), b, a)


def _fit_operator(nodes: np.ndarray, node_component: np.ndarray, n: int, on: np.ndarray):
    """(operator, good): the (2 n, N) sparse matrix whose product with positions t gives, in
    row 2 k + b and column a, entry (a, b) of component k's least-squares affine map over the
    nodes ``on``: sum_i t_i[a] (S_k^-1 p_i)[b], with p_i a node's offset from its component's
    centre in the source and S_k the sum of p_i p_i' (the translation drops out: the weights
    sum to 0 over each component); ``good``: (n,) components with three nodes or more, not on a line."""
    import scipy.sparse as sp                 # SciPy: imported by the solves that need it

    index = np.flatnonzero(on)
    labels, source = node_component[index], nodes[index].astype(float)
    count = np.bincount(labels, minlength=n)
    sums = np.stack([np.bincount(labels, source[:, k], minlength=n) for k in range(2)], 1)
    centre = sums / np.maximum(count, 1)[:, None]                   # (bincount of nothing is int)
    offset = source - centre[labels]
    spread = np.stack([np.stack([np.bincount(labels, offset[:, i] * offset[:, j], minlength=n) for j in range(2)], -1)
                       for i in range(2)], -2)
    det = spread[:, 0, 0] * spread[:, 1, 1] - spread[:, 0, 1] * spread[:, 1, 0]
    good = (count >= 3) & (det > 1e-9 * np.maximum(spread[:, 0, 0] * spread[:, 1, 1], 1e-300))
    inverse = np.zeros((n, 2, 2))
    inverse[good] = np.linalg.inv(spread[good])
    weights = np.einsum("kij,kj->ki", inverse[labels], offset)
    # They sum to 0 over a component only to rounding, which the positions' size (thousands of
    # pixels) would amplify: centred again, a fit is as exact as fitted from centred positions.
    weights -= (np.stack([np.bincount(labels, weights[:, b], minlength=n) for b in range(2)], 1)
                / np.maximum(count, 1)[:, None])[labels]
    rows = (2 * labels[:, None] + np.arange(2)).ravel()
    operator = sp.csr_matrix((weights.ravel(), (rows, np.repeat(index, 2))), shape=(2 * n, node_component.size))
    return operator, good


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

    Tried in turn, each as far as it passes (:func:`furthest_move`): the move
    ``(1 - t) w (W - x)`` with ``w`` 1 around the offending triangles, tapering to 0 over
    :data:`TAPER_CELLS` cells (then around the offending components); a new solve
    (``problem``) with only the offending components untied and their targets blended towards
    W's, so the other features stay as they are, finished by the tapered move where needed;
    last, every node moved evenly towards W."""
    margin = plain_margin(state, warped)
    if margin is None:
        return x
    floor = barrier.SAFE_FRACTION * signed_areas(warped, state.triangles)

    def ok(points):
        return margin(points) <= 0

    figures = margin.figures(x)
    if margin(x, figures) <= 0:
        return x
    offending = np.unique(state.tri_component[_worse(state, figures, margin.plain)])
    fixed = _tapered_fix(state, x, warped, margin, floor, figures)
    if fixed is not None:
        x, record.plain_blend = fixed
        record.degraded_components = [int(c) for c in offending if c >= 0]
        return x
    if problem is not None:     # CRUSHED_SHARE of the floor, or of x's thinnest where x is thinner
        thinnest = CRUSHED_SHARE * min(1.0, float(np.min(grid_areas(state.grid, x) / floor)))
        found = blend_search(problem, offending, floor, record, margin=release_margin(state, warped, margin),
                             origin=x, steps=0, thinnest=thinnest)
        if found is not None:
            best, blend = found
            best, taper = (best, 1.0) if ok(best) else _tapered_fix(state, best, warped, margin, floor)
            record.degraded_components = [int(c) for c in offending]
            record.plain_blend = blend * taper
            return best
    if ok(warped):
        x, record.plain_blend = furthest_move(lambda t: warped + t * (x - warped), margin, state.triangles, floor)
        return x
    record.plain_blend = 0.0
    return warped


def plain_margin(state, warped: np.ndarray):
    """The :class:`PlainMargin` of W, or None where W itself folds a triangle."""
    if np.any(signed_areas(warped, state.triangles) <= 0):
        return None
    return PlainMargin(state, warped)


class PlainMargin:
    """``margin(points)``: how much more distorted than under W the worst component comes out
    under ``points`` (relative; <= 0: no worse; inf with a fold), as its worst triangle or as
    its best-fitting affine map. ``plain`` holds W's figures (per component: worst triangle,
    and affine fits), with a relative slack of 1e-9 for rounding, and at least
    1 + :data:`EXACT_ENOUGH`."""

    def __init__(self, state, warped: np.ndarray):
        self.state = state
        triangles, fits = self.figures(warped)
        self.plain = tuple(np.maximum(figure * (1.0 + 1e-9) + 1e-9, 1.0 + EXACT_ENOUGH)
                           for figure in (_worst_per_component(state, triangles), fits))

    def figures(self, points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(the anisotropy of every feature triangle (M,), and of each component's fits (2, C))
        under ``points``."""
        return self._feature_figures().of(points)

    def _feature_figures(self) -> FeatureFigures:
        """The state's :class:`FeatureFigures`, made at the first use."""
        if self.state.figures is None:
            self.state.figures = FeatureFigures(self.state)
        return self.state.figures

    def first_root(self, start: np.ndarray, end: np.ndarray, upto: float) -> float:
        """Where on start -> end (t in [0, ``upto``]) a component first turns worse than under W,
        or a triangle folds (``upto`` where none does before it), in closed form
        (:meth:`FeatureFigures.first_root`, :func:`injectivity.max_step`)."""
        return min(upto, self._feature_figures().first_root(start, end, self.plain),
                   max_step(start, end, self.state.triangles))

    def __call__(self, points: np.ndarray, figures=None) -> float:
        """Relative excess of the worst component over W's figures (<= 0: no worse); ``figures``:
        :meth:`figures` of ``points``, where they are at hand."""
        if np.any(grid_areas(self.state.grid, points) <= 0):      # the grid's own triangles, by slicing
            return np.inf
        triangles, fits = self.figures(points) if figures is None else figures
        return max(float(np.max(_worst_per_component(self.state, triangles) / self.plain[0], initial=0.0)),
                   float(np.max(fits / self.plain[1], initial=0.0))) - 1.0


def _worse(state, figures: tuple, plain: tuple) -> np.ndarray:
    """Feature triangles more anisotropic than their component's worst under W, and every
    triangle of a component whose affine fit is (``figures``: :meth:`PlainMargin.figures` of the
    positions; ``plain``: both figures under W)."""
    component = np.maximum(state.tri_component, 0)
    triangles, fits = figures
    fit_worse = np.any(fits > plain[1], axis=0)
    return (state.tri_component >= 0) & ((triangles > plain[0][component]) | fit_worse[component])


def _moves_towards_plain(state, points: np.ndarray, warped: np.ndarray, margin, figures=None):
    """The moves of :func:`_tapered_fix`: ``move(t)`` from ``points`` (t = 1) towards W (t = 0)
    around the offending triangles, then around the offending components, tapered
    (``margin``: W's :class:`PlainMargin`; ``figures``: its figures of ``points``, if at hand)."""
    return [lambda t, weight=weight: points + (1.0 - t) * weight * (warped - points)
            for weight in _move_weights(state, points, margin, figures)]


def _move_weights(state, points: np.ndarray, margin, figures=None) -> list:
    """The (N, 1) weights of :func:`_moves_towards_plain`'s two moves."""
    worse = _worse(state, margin.figures(points) if figures is None else figures, margin.plain)
    n_quads = state.features.weight.size
    local = np.zeros(n_quads, bool)
    local[np.flatnonzero(worse) % n_quads] = True
    offending = np.unique(state.tri_component[worse])
    bad = np.isin(state.features.component, offending) & state.features.is_constrained
    others = (state.node_component >= 0) & ~np.isin(state.node_component, offending)
    weights = []
    for region in (local, bad):
        weight = _taper(state, region)
        weight[others] = 0.0                # the move leaves the other features as they are
        weights.append(weight)
    return weights


def release_margin(state, warped: np.ndarray, margin=None):
    """The margin a release's blend must pass (:func:`guard.blend_search`): no component worse
    than under W, or a tapered move towards W fixes it (:func:`_fixable_margin`); anything
    passes where W folds. ``margin``: :func:`plain_margin`'s, where it is at hand; else it is
    made at the first call (most solves never release, and W's figures cost a pass over the
    features). Its ``first_root`` is :func:`_fixable_root`'s (see :func:`furthest_move`)."""
    made = [] if margin is None else [margin]

    def plain():
        if not made:
            made.append(plain_margin(state, warped))
        return made[0]

    def fixable(points):
        return -1.0 if plain() is None else _fixable_margin(state, points, warped, plain())

    def first_root(start, end, upto):
        return upto if plain() is None else _fixable_root(state, warped, plain(), start, end, upto)
    fixable.first_root = first_root
    return fixable


def thinnest_margin(problem, floor, shape_margin, thinnest_share: float):
    """``margin(points)`` of a release's blend (:func:`guard.blend_search`): how far the thinnest
    triangle is below ``thinnest_share`` of its floor (relative), where it is; else the larger
    of that and ``shape_margin(points)``; its ``first_root`` (:func:`furthest_move`) where the
    shape margin has one."""
    def margin(points):
        thinnest = float(np.min(grid_areas(problem.grid, points) / floor))
        crushed = 1.0 - thinnest / thinnest_share
        return crushed if crushed > 0 else max(shape_margin(points), crushed)

    def first_root(start, end, upto):
        root = shape_margin.first_root(start, end, upto)      # None: it cannot tell
        return None if root is None else min(root, max_step(start, end, problem.triangles,
                                                             thinnest_share * floor))
    margin.first_root = first_root if hasattr(shape_margin, "first_root") else None
    return margin


def _fixable_margin(state, points: np.ndarray, warped: np.ndarray, margin) -> float:
    """``margin(points)``, or where that fails the best margin of the tapered moves' full
    step (<= 0: :func:`_tapered_fix` finds a fix)."""
    figures = margin.figures(points)
    value = margin(points, figures)
    if value <= 0:
        return value
    return min(margin(move(0.0)) for move in _moves_towards_plain(state, points, warped, margin, figures))


def _fixable_root(state, warped: np.ndarray, margin, start: np.ndarray, end: np.ndarray, upto: float):
    """A point where :func:`_fixable_margin` turns positive on start -> end (t in [0, ``upto``]),
    in closed form, or None where this cannot tell (a search finds one). Past the plain
    margin's root (:meth:`PlainMargin.first_root`; 0 where the start passes only through a
    fix), the tapered moves that fix the point :data:`ROOT_STEP` beyond it, each a path affine
    in t for its weights, fix it up to their own roots; the last of them counts where that
    move's weights are the same there and nothing fixes the point ROOT_STEP beyond it."""
    root = 0.0 if margin(start) > 0 else margin.first_root(start, end, upto)
    if root >= upto:
        return upto
    beyond = min(upto, root + ROOT_STEP)
    furthest, weights_there = root, None
    ahead, last = start + beyond * (end - start), start + upto * (end - start)
    for weight in _move_weights(state, ahead, margin):
        moved = ahead + weight * (warped - ahead)             # the move's path from ``beyond`` on
        if margin(moved) <= 0:
            reach = beyond + (upto - beyond) * margin.first_root(moved, last + weight * (warped - last), 1.0)
            if reach > furthest:
                furthest, weights_there = reach, weight
    if weights_there is None:
        return root
    before, after = max(beyond, furthest - ROOT_STEP), min(upto, furthest + ROOT_STEP)
    if not any(np.array_equal(weight, weights_there)
               for weight in _move_weights(state, start + before * (end - start), margin)):
        return None
    if furthest >= upto:
        return upto
    return furthest if _fixable_margin(state, start + after * (end - start), warped, margin) > 0 else None


def _tapered_fix(state, points: np.ndarray, warped: np.ndarray, margin, floor, figures=None):
    """``points`` moved towards W around the offending triangles (then components), tapered,
    as little as passes (``margin`` <= 0): (positions, t) as :func:`furthest_move`, or None
    where even the whole move does not pass (``figures``: :meth:`PlainMargin.figures` of
    ``points``, if at hand)."""
    for move in _moves_towards_plain(state, points, warped, margin, figures):
        if margin(move(0.0)) <= 0:
            return furthest_move(move, margin, state.triangles, floor)
    return None


def furthest_move(move, margin, triangles: np.ndarray, floor: np.ndarray) -> tuple[np.ndarray, float]:
    """(``move(t)``, t) at the largest t in [0, 1] that passes (``margin(move(t)) <= 0``), given
    t = 0 does; ``move`` is affine in t.

    Up to where a triangle falls to half its floor (or to half its area at t = 0 where that is
    smaller: the first root of quadratics, :func:`injectivity.max_step`) and, where the margin
    turns positive before that, at its first root: the first of :data:`MOVE_SAMPLES` evenly
    spaced points where it fails (every one is looked at, the last :data:`REACH_INSIDE` short of
    the triangle's root, so that a margin that fails and passes again is not jumped) brackets it, and the root is the margin's own in closed form where it
    gives one in the bracket (``margin.first_root(start, end, upto)``: :class:`PlainMargin`, and
    :func:`release_margin` where it can tell), else :func:`roots.bracketed_root` finds it to
    convergence. Both are functions of the inputs, and a root has no threshold to flip; where
    the margin turns positive more than once in the bracket, the closed form may find another
    root than the bracketed search would have (an earlier one)."""
    start, end = move(0.0), move(1.0)
    reach = max_step(start, end, triangles, CRUSHED_SHARE * np.minimum(floor, signed_areas(start, triangles)))
    samples = reach * np.arange(1, MOVE_SAMPLES + 1) / MOVE_SAMPLES
    samples[-1] = reach * (1.0 - REACH_INSIDE)
    failing = next((k for k, t in enumerate(samples) if margin(move(t)) > 0), None) if reach > 0 else None
    if failing is None:
        reach = samples[-1] if reach > 0 else reach     # the last point looked at: it passes
    else:
        low, high = (samples[failing - 1] if failing else 0.0), samples[failing]
        closed_form = getattr(margin, "first_root", None)
        root = closed_form(start, end, high) if closed_form is not None else None
        if root is None or not low <= root <= high:
            root = bracketed_root(lambda t: margin(move(t)), low, high, xtol=ROOT_TOLERANCE)
        # The margin is noisy at the root (areas of crushed triangles lose digits): back off a
        # little, then a little more, rather than all the way to the last sample that passed.
        reach = next((t for t in (max(low, root - back) for back in ROOT_BACKOFF) if margin(move(t)) <= 0), low)
    return move(reach), reach

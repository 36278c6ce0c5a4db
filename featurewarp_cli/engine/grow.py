"""Features that grow past the edges that cut them (``--grow-past-edge``, issue 22 item 5).

A portrait cut by the bottom edge under ``stretch --sy 2`` keeps its bust's shape only at one
scale, and the thin strip above the head takes the rest of the stretch (28-54x beyond the
warp: stars become needles). With this option a component cut by the frame may grow past the
edges that cut it, so the head rises into that strip and the cut edges crop more of the bust.

The least-squares solution's similarity ``S`` of each such component is scaled by ``k`` about
an anchor ``P``: ``S_k = P + k (S - P)``. Along each axis the anchor keeps

- a cut side moving outward only (the crop grows, the frame is never uncovered), and
- a side the frame does not cut from moving outward by more than the background between it
  and the border is stretched beyond W (a gap that W makes g_W wide and the solution g may
  shrink to g_W, no further: background the solution does not stretch is not squeezed),

and among such anchors takes the one that crops least. ``k`` is the smallest in [1, k_max]
whose least-squares solution stretches the background beyond W by at most ``limit``
(:data:`SCAN` growths evenly over the range, then a bisection between the last two around
the limit), where ``k_max`` closes the widest stretched gap; the caller guards it against
folds like any solution and keeps it only if the guard relaxes nothing. The background is re-solved for
each ``k`` with the component placed, the border nodes of the cut sides free to go outward
with it (an active set: those that would go inward are held at W again).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from . import canvas

#: Growths tried evenly over (1, k_max], then bisection steps between the last two around the limit.
SCAN = 8
GROW_BISECTIONS = 8
#: Rounds of the active set on the cut sides' border nodes.
BORDER_ROUNDS = 4
#: Side lines (top, bottom, left, right) W keeps axis-parallel within this many px.
STRAIGHT_PX = 1e-6


@dataclass
class Growth:
    """One grown solution: the growth ``k`` of the components ``grown``, and what to solve with.

    Attributes
    ----------
    k : float
    grown : (C,) bool ndarray
    ties : components.Ties
    ab : (C, 2) ndarray
    border : tuple of 2 (N,) bool ndarray
        (fixed_x, fixed_y) in force: the grid's, less the cut sides' nodes that go outward.
    pins : (N, 2) ndarray
        Where the grown components' pinned nodes go.
    solved : tuple
        (x, edges, rhs, offset) of the solve.
    stretch : float
        The background's largest stretch beyond W there.
    sides : dict
        The sides the grown features cut ('top', 'bottom', 'left', 'right') and where W puts
        each (px on the canvas, along its normal): the image may go past them.
    """

    k: float
    grown: np.ndarray
    ties: object
    ab: np.ndarray
    border: tuple
    pins: np.ndarray
    solved: tuple
    stretch: float
    sides: dict

    @property
    def components(self) -> list[int]:
        """The grown components' indices."""
        return [int(c) for c in np.flatnonzero(self.grown)]

    def summary(self) -> dict:
        """``record.grown``: k, the components and the sides they grew past (``past_px`` is
        added when the result is assessed)."""
        return {"k": self.k, "components": self.components, "sides": dict(self.sides)}


def side_nodes(nx: int, ny: int) -> list[np.ndarray]:
    """Node indices of the grid's sides: top, bottom, left, right."""
    index = np.arange(nx * ny).reshape(ny, nx)
    return [index[0], index[-1], index[:, 0], index[:, -1]]


def grow(solve_at, stretch_of, x, ab, ties, nx, ny, fixed, warped, limit: float) -> list[Growth]:
    """Grown solutions within ``limit``, the smallest growth first (for the guard to try in
    turn). Empty: no component can grow, or no growth brings the background within ``limit``.

    Parameters
    ----------
    solve_at : callable
        ``solve_at(ties, ab, border, pins)`` -> (x, edges, rhs, offset).
    stretch_of : callable
        ``stretch_of(x)`` -> the background's largest stretch beyond W.
    x : (N, 2) ndarray
        The least-squares solution.
    ab : (C, 2) ndarray
        Its components' similarities.
    ties : components.Ties
    nx, ny : int
        The grid's nodes per row and column.
    fixed : tuple of 2 (N,) bool ndarray
        The grid's border conditions (fixed_x, fixed_y).
    warped : (N, 2) ndarray
        W at the nodes.
    limit : float
        The stretch beyond W to reach.
    """
    sides = side_nodes(nx, ny)
    lines = [float(np.median(warped[s, 1 if i < 2 else 0])) for i, s in enumerate(sides)]
    straight = [np.ptp(warped[s, 1 if i < 2 else 0]) <= STRAIGHT_PX for i, s in enumerate(sides)]
    comp = ties.node_component
    cut = np.zeros((ties.tied.size, 4), bool)
    for i, s in enumerate(sides):
        on = s[comp[s] >= 0]
        cut[np.unique(comp[on]), i] = True
    grown = ties.tied & ~ties.unpinned & cut.any(axis=1) & np.all(~cut | straight, axis=1)
    if not grown.any():
        return []
    plans = [plan for plan in (_plan(c, x, warped, comp, cut[c], lines, straight) for c in np.flatnonzero(grown))
             if plan.k_max > 1.0]
    if not plans:
        return []
    grown[:] = False
    grown[[plan.component for plan in plans]] = True
    k_max = max(plan.k_max for plan in plans)
    cut_sides = cut[grown].any(axis=0)
    released = [s[comp[s] < 0] if cut_sides[i] else s[:0] for i, s in enumerate(sides)]

    def at(k):
        return _solve_grown(solve_at, stretch_of, k, plans, grown, x, ab, ties, fixed, released, warped, lines,
                            cut_sides)

    tried = [at(1.0 + (k_max - 1.0) * (i + 1) / SCAN) for i in range(SCAN)]
    first = next((i for i, g in enumerate(tried) if g.stretch <= limit), None)
    if first is None:                               # the limit is out of reach
        return []
    best, low = tried[first], (tried[first - 1].k if first else 1.0)
    for _ in range(GROW_BISECTIONS):
        trial = at(0.5 * (low + best.k))
        if trial.stretch <= limit:
            best = trial
        else:
            low = trial.k
    return [best] + [g for g in tried[first + 1:] if g.stretch <= limit]


def declined(reason: str) -> dict:
    """``record.grown`` when ``--grow-past-edge`` grew nothing, and why."""
    return {"k": 1.0, "components": [], "sides": {}, "declined": reason}


@dataclass
class _Plan:
    """One component's growth: its extremes (left, top, right, bottom) under the solution,
    which sides cut it, how far each other side may move out, and k_max."""

    component: int
    low: np.ndarray            # (left, top)
    high: np.ndarray           # (right, bottom)
    cut_low: np.ndarray        # (left, top) cut
    cut_high: np.ndarray       # (right, bottom) cut
    spare_low: np.ndarray      # how far the left / top extreme may move out
    spare_high: np.ndarray
    k_max: float


def _plan(c: int, x, warped, comp, cut, lines, straight) -> _Plan:
    """The growth plan of component ``c`` (``cut``: top, bottom, left, right; ``lines``: where W
    puts those sides, along their normals; ``straight``: which W keeps straight, the others
    give no room)."""
    nodes = np.flatnonzero(comp == c)
    low, high = x[nodes].min(axis=0), x[nodes].max(axis=0)
    w_low, w_high = warped[nodes].min(axis=0), warped[nodes].max(axis=0)
    border_low, border_high = np.array([lines[2], lines[0]]), np.array([lines[3], lines[1]])
    cut_low, cut_high = np.array([cut[2], cut[0]]), np.array([cut[3], cut[1]])
    # a gap the solution stretches beyond W's may close down to W's, not further
    spare_low = np.where(cut_low, np.inf, np.maximum(0.0, (low - border_low) - (w_low - border_low)))
    spare_high = np.where(cut_high, np.inf, np.maximum(0.0, (border_high - high) - (border_high - w_high)))
    spare_low[~np.array([straight[2], straight[0]])] = 0.0
    spare_high[~np.array([straight[3], straight[1]])] = 0.0
    extent = np.maximum(high - low, 1e-9)
    free = np.where(cut_low, 0.0, spare_low) + np.where(cut_high, 0.0, spare_high)
    useful = np.where(cut_low & cut_high, 1.0, 1.0 + free / extent)      # all stretched gaps closed
    feasible = np.where(cut_low | cut_high, np.inf, 1.0 + free / extent)  # nothing squeezed
    return _Plan(c, low, high, cut_low, cut_high, spare_low, spare_high,
                 float(min(useful.max(), feasible.min())))


def _anchor(plan: _Plan, k: float) -> np.ndarray:
    """The point (x, y) the component grows ``k`` times about: outward only on cut sides, within
    the spare gap on the others, cropping least."""
    grow_by = k - 1.0
    lo = np.where(plan.cut_low, plan.low, -np.inf)
    hi = np.where(plan.cut_low, np.inf, plan.low + plan.spare_low / grow_by)
    hi = np.minimum(hi, np.where(plan.cut_high, plan.high, np.inf))
    lo = np.maximum(lo, np.where(plan.cut_high, -np.inf, plan.high - plan.spare_high / grow_by))
    middle = 0.5 * (np.clip(lo, plan.low, plan.high) + np.clip(hi, plan.low, plan.high))
    only_low, only_high = plan.cut_low & ~plan.cut_high, plan.cut_high & ~plan.cut_low
    return np.where(only_low, lo, np.where(only_high, hi, middle))


#: The grid's sides in :func:`side_nodes`'s order, and each one's outward sign along its normal.
SIDES = ("top", "bottom", "left", "right")
_OUTWARD = (-1.0, 1.0, -1.0, 1.0)


def beyond(target: np.ndarray, nx: int, ny: int, sides: dict) -> dict:
    """Per side of ``sides`` (name -> W's line): the border nodes of ``target`` past it, (N,) bool."""
    ring = canvas.outline(nx, ny)
    out = {}
    for i, name in enumerate(SIDES):
        if name in sides:
            past = np.zeros(nx * ny, bool)
            past[ring] = (target[ring, 1 if i < 2 else 0] - sides[name]) * _OUTWARD[i] > 0
            out[name] = past
    return out


def _solve_grown(solve_at, stretch_of, k, plans, grown, x, ab, ties, fixed, released, warped, lines,
                 cut_sides) -> Growth:
    """The solution with every planned component grown ``k`` times (an active set on the cut
    sides' border nodes: free to go outward, held at W where they would go inward)."""
    ab_k = ab.copy()
    pins = warped.copy()
    for plan in plans:
        k_c = min(k, plan.k_max)                    # none grows past what its own gaps allow
        anchor = _anchor(plan, k_c)
        ab_k[plan.component] = k_c * ab[plan.component]
        for axis in range(2):
            pin = ties.pin[plan.component, axis]
            if pin >= 0:
                pins[pin, axis] = anchor[axis] + k_c * (x[pin, axis] - anchor[axis])
    grown_ties = type(ties)(**{**ties.__dict__, "grown": grown})
    free = [r.copy() for r in released]
    for _ in range(BORDER_ROUNDS):
        fixed_x, fixed_y = fixed[0].copy(), fixed[1].copy()
        for i, nodes in enumerate(free):
            (fixed_y if i < 2 else fixed_x)[nodes] = False
        solved = solve_at(grown_ties, ab_k, (fixed_x, fixed_y), pins)
        inward = [nodes[(solved[0][nodes, 1 if i < 2 else 0] - lines[i]) * _OUTWARD[i] < -1e-9]
                  for i, nodes in enumerate(free)]
        if not any(len(n) for n in inward):
            break
        free = [np.setdiff1d(nodes, back) for nodes, back in zip(free, inward)]
    sides = {SIDES[i]: lines[i] for i, nodes in enumerate(released) if cut_sides[i]}
    return Growth(k, grown, grown_ties, ab_k, (fixed_x, fixed_y), pins, solved, stretch_of(solved[0]), sides)

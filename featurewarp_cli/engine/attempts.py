"""One solve's least-squares problem and what the warper does with it after the scale search:
the fold guard (:mod:`guard`) and, with ``--grow-past-edge``, features grown past the edges
that cut them (:mod:`grow`). ``state`` is the warper's grid state."""

from __future__ import annotations

import time

import numpy as np

from .. import stages
from . import canvas, components, grow, guard, plain_bound, scale_search
from .record import STREAKS, SolveRecord

#: Grown solutions guarded at most (``--grow-past-edge``), the preferred first; the first the
#: guard has to relax ends the tries.
GROW_TRIES = 4


class Attempt:
    """One least-squares problem of a solve: ties, border and pins (None: the grid's, W) and
    W's edge vectors, with ``solve(ab)`` -> (x, edges, rhs, offset) on its factored systems;
    ``ab`` and ``solved`` once solved."""

    def __init__(self, warper, state, constants, ties, border=None, pins=None, warp_edges=None):
        """``warper``: the :class:`FeatureWarper` (its factored systems and timings); ``state``: its
        grid state; ``constants(ab, ties, edges, border, pins)`` -> (edges, rhs, offset)."""
        self.constants, self.ties, self.border, self.pins = constants, ties, border, pins
        self.warp_edges = warp_edges
        self.systems = warper._systems(state, ties, border)
        self.timings = warper.timings
        self.ab = self.solved = None

    def solve(self, ab):
        """(x, edges, rhs, offset): the nodes for the features' similarities ``ab``."""
        edges, rhs, offset = self.constants(ab, self.ties, None, self.border, self.pins)
        t0 = time.perf_counter()
        x = self.systems.solve(rhs, offset)
        self.timings["solve"] = self.timings.get("solve", 0.0) + time.perf_counter() - t0
        return x, edges, rhs, offset


def guarded(warper, state, warped, record: SolveRecord, attempt: Attempt, scale_solver, low, ease=None):
    """The least-squares solution ``attempt.solved`` guarded against folds and kept no worse
    than plain (:mod:`guard`); where features were relaxed, smaller similarities (towards
    ``low()``) are tried first. With ``ease`` (x -> (eased x, share)), an interactive update's
    preview (see ``guard.Problem``): where its window does not open the folds, the solution
    is eased instead. Returns (x, tied, unpinned)."""
    ties, ab, (x, edges, rhs, offset) = attempt.ties, attempt.ab, attempt.solved
    grid, features = state.grid, state.features

    def rebuild(new_edges, released):
        loose = components.Ties(**{**ties.__dict__, "tied": ties.tied & ~np.isin(np.arange(ties.tied.size),
                                                                                  released)})
        _, new_rhs, new_offset = attempt.constants(ab, loose, new_edges, attempt.border, attempt.pins)
        return warper._systems(state, loose, attempt.border), new_rhs, new_offset, loose.window_ties()

    problem = guard.Problem(grid, features, state.triangles, warped, state.normal, state.stiffness,
                            ties.window_fixed(*(attempt.border or (state.fixed_x, state.fixed_y))),
                            ties.window_ties(), attempt.systems, rhs, offset, edges,
                            attempt.warp_edges, rebuild, warper.timings, ease is not None,
                            plain_bound.release_margin(state, warped) if warper.formulation == "exact" else None)
    before = {k: warper.timings.get(k, 0.0) for k in ("solve", "factor", "rhs")}
    stages.enter("guard")
    t0 = time.perf_counter()
    shrunk = []

    def smaller() -> bool:
        """Where the features cannot keep their shape at this scale, before any is released: do
        they at a smaller one? (The release's result went unused where they did.)"""
        shrunk.append(scale_search.shrink_to_fit(attempt.solve, low(), ab, attempt.solved, state.triangles, warped))
        return shrunk[0] is not None

    x = guard.guard(problem, x, record.guard, smaller if scale_solver is not None and scale_solver.n_columns else None)
    if shrunk and shrunk[0] is not None:
        ab, (x, edges, rhs, offset) = shrunk[0]
        record.guard = guard.GuardRecord()
        problem.rhs, problem.offset, problem.edges = rhs, offset, edges
        x = guard.guard(problem, x, record.guard)
    elif x is None:                              # a preview: eased, as a drag's update is
        x, record.guard.drag_step = ease(attempt.solved[0])
        record.guard.preview_eased = True
        _guard_seconds(warper.timings, before, time.perf_counter() - t0)
        return x, ties.tied, ties.unpinned & ties.tied
    if warper.formulation == "exact":            # the paper's soft targets are kept as published
        x = plain_bound.no_worse_than_plain(state, x, warped, record.guard, problem)
    _guard_seconds(warper.timings, before, time.perf_counter() - t0)
    released = np.isin(np.arange(ties.tied.size), record.guard.released_components)
    return x, ties.tied & ~released, ties.unpinned & ties.tied & ~released


def _guard_seconds(timings: dict, before: dict, wall: float) -> None:
    """Add the guard's ``wall`` seconds to ``timings["guard"]`` as the progress line shows its
    stages: its back-substitutions and right-hand sides are the guard's (they went to "solve" and
    "rhs", which the report then showed as the larger part of a guard's time), the
    factorizations it asks for are "factor" (``before``: the three at its start)."""
    factored = timings.get("factor", 0.0) - before["factor"]
    timings["solve"], timings["rhs"] = before["solve"], before["rhs"]
    timings["guard"] = timings.get("guard", 0.0) + wall - factored


def grown(warper, state, warped, record: SolveRecord, attempt: Attempt, result, mode: str):
    """``--grow-past-edge``: where ``result`` streaks, the frame-cut features grown past
    their cut edges (:func:`grow.grow`), guarded; kept only where the guard relaxed nothing
    and the streaks are gone (else ``record.grown`` says why not, and ``result`` stays)."""
    background = state.triangles[state.tri_component < 0]

    def stretch(points):
        return canvas.largest_stretch(points, warped, background)[0]

    if stretch(result[0]) <= STREAKS:
        return result
    if mode != "similarity" or warper.formulation != "exact":
        record.grown = grow.declined(f"features keep their size in {mode} mode" if mode != "similarity" else
                                     "the paper's formulation has no similarity to grow")
        return result
    candidates = grow.grow(lambda t, ab, border, pins: Attempt(warper, state, attempt.constants, t, border, pins)
                           .solve(ab), stretch, attempt.solved[0], attempt.ab, attempt.ties, state.grid.nx,
                           state.grid.ny, (state.fixed_x, state.fixed_y), warped, STREAKS)
    kept_record = record.guard
    for growth in candidates[:GROW_TRIES]:
        record.guard = guard.GuardRecord()
        grown = Attempt(warper, state, attempt.constants, growth.ties, growth.border, growth.pins,
                        attempt.warp_edges)
        grown.ab, grown.solved = growth.ab, growth.solved
        trial = guarded(warper, state, warped, record, grown, None, None)
        relaxed = record.guard.release_rounds or record.guard.plain_blend < 1.0
        if not relaxed and stretch(trial[0]) <= STREAKS:
            record.grown = growth.summary()
            return trial
        if relaxed:                 # a larger growth folds no less: no use guarding the next ones
            break
    record.guard = kept_record
    record.grown = grow.declined("the features that could grow past the edges cutting them would fold "
                                 "into their surroundings" if candidates else "no feature cut by straight edges "
                                 "can grow enough without squeezing the background the warp does not stretch")
    return result

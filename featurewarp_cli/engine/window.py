"""The fold-over guard's windows: the nodes around some quads, everything else held, their
least-squares system, and the runs of the barrier's energy on them (:func:`guard._open_window`).

Outside the window the grid stays where it was; the guard converges the whole grid from a
window's result (converged to the path's tolerance where that keeps every triangle at the
continuation's share; else to the barrier's), but for a preview, whose window's minimum is its result.
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np

from . import barrier, injectivity, system
from .grid import signed_areas
from .path import PATH_TOLERANCE

#: Newton steps of one of :func:`guard._open_window`'s runs at most: one not converged in as many
#: leaves the folds to the path from W (a speed limit, and a count that decides: the path may end
#: elsewhere, or be blocked; the windows of the 28 ``floor`` solves at 1 MP take 5-23 with the
#: runs of :meth:`Window.continued`, 7-20 to 1e-12; one whose minimum folds can crawl for hundreds).
WINDOW_STEPS = 60
#: Newton steps of a preview's convergence (``Problem.preview``): slivers lifted part of the way,
#: in bounded time (the editor's hard release: 35 steps, 0.6 s, to converge).
PREVIEW_STEPS = 4
#: Windows larger than this fraction of the grid go to the path from W; a preview's (nodes) is eased.
WINDOW_MAX_FRACTION = 0.5


def timed(timings: dict, function):
    """``function``, adding its wall time to ``timings["solve"]`` (the report's solve stage)."""
    def timed_function(*args):
        t0 = time.perf_counter()
        result = function(*args)
        timings["solve"] = timings.get("solve", 0.0) + time.perf_counter() - t0
        return result
    return timed_function


@dataclass
class Window:
    """The nodes around some quads, everything else held, and their least-squares system.

    Attributes
    ----------
    nodes : (n,) int ndarray
        The window's nodes (its moving ones and the held ones around them).
    quads : (q,) int ndarray
        Quads whose shape the window may change; ``triangles`` are theirs, in window indices.
    matrix, solve, linear
        The normal matrix's rows for the nodes, ``solve(force)`` -> (n, 2) positions, and its
        linear part (the change of the positions under ``force``).
    movable : (n,) bool ndarray
        Nodes moved one by one (not held, not tied to a feature).
    warped, stiffness : (n, 2), (n,) ndarray
    max_steps : int or None
        A preview's Newton steps a run (:data:`PREVIEW_STEPS`); None: :data:`WINDOW_STEPS` for
        :meth:`continued`, :data:`barrier.MAX_STEPS` for :meth:`converge`.
    inverse : barrier.InverseRows
    tolerance : float
        Of the runs: :data:`path.PATH_TOLERANCE` where the guard converges the whole grid from the
        window's result (the window only starts it, as a corrector of the path starts the next
        step; the whole grid's run meets :data:`barrier.TOLERANCE`), :data:`barrier.TOLERANCE` for
        a preview, whose window's minimum is its result.
    """

    nodes: np.ndarray
    quads: np.ndarray
    triangles: np.ndarray
    matrix: object
    solve: object
    movable: np.ndarray
    warped: np.ndarray
    stiffness: np.ndarray
    max_steps: int | None = None
    inverse: object = None
    linear: object = None
    tolerance: float = barrier.TOLERANCE

    def floor(self, floor: np.ndarray) -> np.ndarray:
        """The window's triangles' entries of a per-triangle array of the grid."""
        n_quads = floor.size // 2
        return np.concatenate([floor[self.quads], floor[self.quads + n_quads]])

    def converge(self, x: np.ndarray, floor: np.ndarray, record) -> np.ndarray:
        """The window's nodes at the barrier energy's minimum from ``x`` (grid positions, no fold),
        to :attr:`tolerance`; ``record`` (:class:`guard.GuardRecord`) counts the run."""
        local_floor = self.floor(floor)
        kappa = barrier.weights(self.warped, self.triangles, self.stiffness, local_floor)
        moved, how = barrier.converge(self.solve, self.matrix, self.movable, x[self.nodes], self.triangles,
                                      local_floor, kappa, max_steps=self.max_steps, inverse=self.inverse,
                                      linear=self.linear, tolerance=self.tolerance)
        record.count(how)
        return moved

    def continued(self, moved: np.ndarray, floor: np.ndarray, kappa: np.ndarray, below: float):
        """One run of :func:`guard._open_window`: (the window's nodes, :class:`barrier.Convergence`) of the
        barrier continued below ``below`` from ``moved``, converged to :attr:`tolerance` and, where that
        point has a triangle below ``below`` of its ``floor`` (folded, or in the continued part), on to
        :data:`barrier.TOLERANCE`, in :data:`WINDOW_STEPS` Newton steps in all (a preview's
        :attr:`max_steps`). So a window fails, or leaves a triangle in the continued part, only on
        a minimum, as the path's stop is decided (a loosely converged point moves with one ulp of
        the input by more than rounding); it is accepted on a loose point only where that keeps
        every triangle at ``below`` or above (a whole share of the floor from a fold; there the two
        energies agree), and the whole grid is converged from it."""
        def run(start, steps, tolerance):
            return barrier.converge(self.solve, self.matrix, self.movable, start, self.triangles, floor, kappa,
                                    max_steps=steps, inverse=self.inverse, linear=self.linear, below=below,
                                    tolerance=tolerance)
        cap = self.max_steps or WINDOW_STEPS
        moved, how = run(moved, cap, self.tolerance)
        if how.converged and self.tolerance > barrier.TOLERANCE and (signed_areas(moved, self.triangles)
                                                                     / floor).min() < below:
            moved, more = run(moved, cap - how.steps, barrier.TOLERANCE)
            how = barrier.Convergence(how.steps + more.steps, more.converged)
        return moved, how


def window_around(problem, x, crushed: np.ndarray, margin: int, around_ties: bool = False) -> Window | None:
    """For a :class:`guard.Problem`, the :class:`Window` of the quads within ``margin`` quads of
    those with a ``crushed`` triangle ((M,) bool), holding every other node at ``x``, except that a tied feature
    reaching into it keeps its shared unknown (it may shift as a whole); None when nothing
    could move or when it would take in more than WINDOW_MAX_FRACTION of the grid's quads (a
    preview's: of its nodes, tied features' included).

    With ``around_ties`` (once), a tied feature that reaches into the window brings its quads
    and ``margin`` quads around them: it can only shift if the ground around all of it may
    follow. Without, a window could not open the folds by the astronaut's head cut by the top
    edge under ``fish`` (1 MP: 600 Newton steps, not converged; with its ground, 22)."""
    grid, n_quads, tied = problem.grid, problem.features.weight.size, problem.tied
    quads = np.zeros(n_quads, bool)
    quads[np.flatnonzero(crushed) % n_quads] = True
    _, near, inner = injectivity.window(grid, quads, margin)
    corners = grid.quads()
    def reached(nodes):                   # the nodes of every tied feature with a node in ``nodes``
        return np.isin(tied, np.unique(tied[nodes & (tied >= 0)])) & (tied >= 0)
    if around_ties:
        _, near, inner = injectivity.window(grid, quads | reached(near)[corners].any(axis=1), margin)
    moving = (inner & ~problem.fixed & (tied < 0)) | reached(near)
    touched = moving[corners].any(axis=1)
    ties = tied[corners]
    rigid = (ties[:, 0] >= 0) & (ties == ties[:, :1]).all(axis=1)    # inside one tied feature
    changing = np.flatnonzero(touched & ~rigid)
    if changing.size == 0 or changing.size > WINDOW_MAX_FRACTION * n_quads:
        return None
    in_system = np.zeros(grid.n_nodes, bool)
    in_system[corners[touched].ravel()] = True
    nodes = np.flatnonzero(in_system)
    if problem.preview and nodes.size > WINDOW_MAX_FRACTION * grid.n_nodes:
        return None                       # a preview's runs there: 0.8 s of 12 steps that open nothing
    local_moving = moving[nodes]
    unknown = system.number_unknowns(~local_moving, np.where(local_moving, tied[nodes], -1))
    from .solver import ReducedSystem         # SciPy: imported by the solves that need it

    matrix = problem.normal[nodes][:, nodes]
    reduced = ReducedSystem(matrix, unknown)
    held = np.where(local_moving[:, None], problem.offset[nodes], x[nodes])
    local_rhs, timings = problem.rhs[nodes], problem.timings

    solve = timed(timings, lambda force: reduced.solve(local_rhs + force, held))
    linear = timed(timings, reduced.move)
    inverse = barrier.InverseRows(timed(timings, lambda rows, columns: np.broadcast_to(
        reduced.entries(rows, columns), (2, rows.size, columns.size))), np.stack([unknown, unknown]),
        lambda axis, ids: reduced.normal_between(ids))   # one system for both axes

    local = np.full(grid.n_nodes, -1)
    local[nodes] = np.arange(nodes.size)
    quad_corners = local[corners[changing]]
    triangles = np.concatenate([quad_corners[:, [0, 1, 2]], quad_corners[:, [0, 2, 3]]])
    return Window(nodes, changing, triangles, matrix, solve, local_moving & (tied[nodes] < 0),
                  problem.warped[nodes], problem.stiffness[nodes], PREVIEW_STEPS if problem.preview else None, inverse,
                  linear, barrier.TOLERANCE if problem.preview else PATH_TOLERANCE)

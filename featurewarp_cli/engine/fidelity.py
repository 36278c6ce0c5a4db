"""How closely a grid follows a warp, and the automatic cell size that makes it follow.

The rendered mapping is piecewise linear on the grid's triangles. Where the warp
curves faster than the cells are small, the triangles cut its corners; the
largest gap sits near the midpoints of the triangle edges, where it is
|W(midpoint) - (W(a) + W(b)) / 2|.
"""

from __future__ import annotations

import math

import numpy as np

from .grid import Grid, grid_for

#: Largest piecewise-linear deviation from the warp the automatic cell allows, in pixels.
MAX_PL_ERROR = 0.5
#: Largest grid the automatic rule builds, so memory and time stay bounded (a fold-over
#: guard on 830 000 nodes took 43 s and 2 GB). The ladder of :func:`auto_cell` halves the
#: cell's area from :data:`BASE_NODES`, so on images above 0.48 MP its finest rung has about
#: 480 000 nodes (:func:`finest_cell`: the swirl's tightest radius); a warp that bends an
#: image thinner than a pixel around a ring (arc 360 of a 1 x 5000 image) never comes within
#: 0.5 px of its grid and stops here, its remaining error in the report. 800 000 lets a
#: 1 x 5000 strip follow swirl 360 at radius 10 (680 000 nodes).
MAX_NODES = 800_000
#: Node count the automatic rule aims for when the warp is gentle (images above 0.48 MP;
#: smaller ones get the 4 px cell). The warp's own accuracy does not depend on it (the
#: 0.5 px rule refines the grid where W needs it: the 12 MP swirl 180 gets 60 000 nodes);
#: what it sets is how closely the grid's feature quads hug the mask, within one cell (5.9 px
#: on 1 MP, 20 px on 12 MP: 200 cells across a 4:3 image), the decay two more, and how
#: finely the background gives way beside a feature. Every mask pixel is in a feature quad
#: at any cell, so features stay exact. The 28 solves of the 14 presets with two masks take
#: 4.6 s at 1 MP and 6.5 s at 12 MP, against 11.4 s and 14.2 s at 80 000, the same features
#: kept in each; at 20 000, 6.1 s at 12 MP and one feature fewer kept (fish, the shuttle).
BASE_NODES = 30_000


def _deviation(grid: Grid, warp) -> tuple[float, np.ndarray]:
    """(:func:`pl_error`, W at the nodes as an (ny, nx, 2) array)."""
    nodes = grid.nodes().reshape(grid.ny, grid.nx, 2)
    warped = warp(nodes.reshape(-1, 2)).reshape(grid.ny, grid.nx, 2)
    worst = 0.0
    for a, b, wa, wb in (
        (nodes[:, :-1], nodes[:, 1:], warped[:, :-1], warped[:, 1:]),        # horizontal edges
        (nodes[:-1, :], nodes[1:, :], warped[:-1, :], warped[1:, :]),        # vertical edges
        (nodes[:-1, :-1], nodes[1:, 1:], warped[:-1, :-1], warped[1:, 1:]),  # diagonals
    ):
        gap = warp(((a + b) / 2.0).reshape(-1, 2)) - ((wa + wb) / 2.0).reshape(-1, 2)
        # The largest squared length, then one square root: the same number as the largest
        # np.linalg.norm(gap, axis=1) (sqrt is monotonic and correctly rounded), at less cost.
        squared = gap[:, 0] * gap[:, 0] + gap[:, 1] * gap[:, 1]
        worst = max(worst, float(np.sqrt(squared.max(initial=0.0))))
    return worst, warped


def _lattice_deviation(grid: Grid, warped: np.ndarray, warp, step: float) -> float:
    """Largest distance between ``warp`` and its piecewise-linear version on ``grid`` (W at the
    nodes: ``warped``, (ny, nx, 2)) over a lattice of points about ``step`` px apart."""
    columns = np.linspace(-0.5, grid.width - 0.5, max(2, math.ceil(grid.width / step) + 1))
    rows = np.linspace(-0.5, grid.height - 0.5, max(2, math.ceil(grid.height / step) + 1))
    x, y = (v.ravel() for v in np.meshgrid(columns, rows))
    (sx, sy), (qy, qx) = grid.spacing, grid.quad_shape
    i = np.minimum(((x + 0.5) / sx).astype(int), qx - 1)
    j = np.minimum(((y + 0.5) / sy).astype(int), qy - 1)
    u, v = ((x + 0.5) / sx - i)[:, None], ((y + 0.5) / sy - j)[:, None]
    tl, tr, br, bl = warped[j, i], warped[j, i + 1], warped[j + 1, i + 1], warped[j + 1, i]
    upper = u >= v                        # the triangles (tl, tr, br) and (tl, br, bl), as Grid cuts them
    linear = np.where(upper, tl + u * (tr - tl) + v * (br - tr), tl + u * (br - bl) + v * (bl - tl))
    gap = warp(np.stack([x, y], axis=1)) - linear
    return float(np.sqrt((gap[:, 0] * gap[:, 0] + gap[:, 1] * gap[:, 1]).max(initial=0.0)))


def pl_error(grid: Grid, warp) -> float:
    """Largest distance between the warp and its piecewise-linear grid version, in pixels.

    Measured at the midpoints of every horizontal, vertical and diagonal triangle edge, and on a
    lattice of points half the base cell apart (:func:`base_cell`): a coarse given cell's
    midpoints may all sit where W happens to agree with its grid (a swirl's centre and a border
    it leaves in place, at ``--cell 1000`` on 512 px: 0.0 px), where the lattice finds 100 px.

    Parameters
    ----------
    grid : Grid
    warp : callable
        (N, 2) source points -> (N, 2) canvas points.

    Returns
    -------
    float
    """
    error, warped = _deviation(grid, warp)
    return max(error, _lattice_deviation(grid, warped, warp, 0.5 * base_cell(grid.width, grid.height)))


def smallest_area(points: np.ndarray) -> float:
    """Smallest signed area of the grid's triangles with nodes at ``points`` ((ny, nx, 2)).

    The same numbers as :func:`grid.signed_areas` over ``grid.triangles()`` (two
    triangles per quad: top-left, top-right, bottom-right and top-left,
    bottom-right, bottom-left), from slices instead of index arrays. NaN if any is.
    """
    tl, tr, br, bl = points[:-1, :-1], points[:-1, 1:], points[1:, 1:], points[1:, :-1]
    lowest = np.inf
    for b, c in ((tr, br), (br, bl)):
        u, v = b - tl, c - tl
        lowest = np.minimum(lowest, (0.5 * (u[..., 0] * v[..., 1] - u[..., 1] * v[..., 0])).min())
    return float(lowest)


def _cell_for_nodes(width: int, height: int, nodes: int) -> float:
    """The cell at which a ``width`` x ``height`` grid has about ``nodes`` nodes, counting
    the extra row and column of nodes (what matters for images a few pixels thin)."""
    # (w / c + 1)(h / c + 1) = n  ->  (n - 1) c^2 - (w + h) c - w h = 0
    a, b = nodes - 1.0, float(width + height)
    return (b + math.sqrt(b * b + 4.0 * a * width * height)) / (2.0 * a)


def base_cell(width: int, height: int) -> float:
    """Cell size for a gentle warp: 4 px, or larger so the grid keeps about :data:`BASE_NODES` nodes."""
    return max(4.0, math.sqrt(width * height / BASE_NODES))


def finest_cell(width: int, height: int) -> float:
    """The coarsest cell at which :func:`auto_cell` may stop refining: the last rung of its
    ladder within :data:`MAX_NODES`. A warp this grid cannot follow (within 0.5 px, without
    a fold) is followed by no automatic grid, so a preset can refuse such parameters
    before any solve (``swirl``: a tight radius at a large angle)."""
    cell = base_cell(width, height)
    smallest = min(_cell_for_nodes(width, height, MAX_NODES), cell)
    while cell / math.sqrt(2.0) >= smallest:
        cell /= math.sqrt(2.0)
    return cell


def follows(grid: Grid, warp) -> tuple[bool, float]:
    """Whether ``grid`` follows ``warp``: error <= 0.5 px and no triangle folded by W.

    Returns
    -------
    ok : bool
    error : float
        Piecewise-linear error in pixels.
    """
    error, warped = _deviation(grid, warp)
    if error > MAX_PL_ERROR:
        return False, error
    return bool(smallest_area(warped) > 0), error


def auto_cell(width: int, height: int, warp=None) -> tuple[float, float]:
    """Automatic cell size: the base cell, made finer until the grid follows ``warp``.

    Rule: start from :func:`base_cell` (4 px, or larger so the grid keeps about
    :data:`BASE_NODES` nodes); while the piecewise-linear grid strays more than 0.5 px from
    the warp, or folds a triangle the warp itself does not fold, divide the
    cell by sqrt(2) (sub-pixel cells included), down to the size at which the grid
    would pass :data:`MAX_NODES`. The sizes are a fixed ladder, so warps that need the
    same fineness share one grid (and one factorization). The cell is a function of the
    image size and the warp alone: never of the machine (its memory, cores or timing), so
    the same command gives the same grid everywhere; a memory budget refuses a grid it
    cannot hold (:class:`featurewarp_cli.engine.warper.FeatureWarper`), it never coarsens it.

    Parameters
    ----------
    width, height : int
    warp : callable, optional
        Without it, the base cell is returned.

    Returns
    -------
    cell : float
    error : float
        Piecewise-linear error at that cell in pixels (nan without a warp).
    """
    base = cell = base_cell(width, height)
    if warp is None:
        return cell, float("nan")
    smallest = min(_cell_for_nodes(width, height, MAX_NODES), cell)
    lattice = getattr(warp, "lattice", None)
    ok, error = follows(grid_for(width, height, cell, lattice), warp)
    rung = 0                   # the cell is base / sqrt(2)^rung, with even rungs exact (4 px -> 1 px, not 1 - 3e-16)
    while not ok and cell / math.sqrt(2.0) >= smallest:
        # The error scales with the cell's square: skip rungs that cannot suffice.
        rung += max(1, math.floor(math.log(max(error, 1e-9) / MAX_PL_ERROR, 2.0)))
        cell = max(base * 2.0 ** -(rung // 2) / math.sqrt(2.0) ** (rung % 2), smallest)
        ok, error = follows(grid_for(width, height, cell, lattice), warp)
    return cell, error


class GridBudgetError(ValueError):
    """The grid a warp needs is larger than the memory budget allows."""


def check_budget(width: int, height: int, cell: float, max_nodes: int | None, lattice: Grid | None = None) -> None:
    """Refuse an automatic grid above ``max_nodes`` (the budget never coarsens it); the grid
    is :func:`grid_for`'s (``lattice``: the warp's own, for a handles warp).

    Raises
    ------
    GridBudgetError
    """
    nodes = grid_for(width, height, cell, lattice).n_nodes
    if max_nodes is not None and nodes > max_nodes:
        raise GridBudgetError(
            f"this warp needs a grid of {nodes} nodes (cell {cell:.3g} px) to follow it within "
            f"{MAX_PL_ERROR} px, above the {max_nodes} that the memory limit allows "
            f"(a larger --max-memory, or a gentler warp)")

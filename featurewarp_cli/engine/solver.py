"""Sparse Cholesky factorization of the normal equations under a linear reparametrization.

Node positions are written x = P z + q: a node is either fixed (its position is
q), free (its own unknown), or tied to a shared unknown (x = q + t, used to move
a whole feature as one rigid piece whose linear part is already in q). The
reduced matrix P^T L P depends on L and on which node maps to which unknown,
never on q, so one factorization serves every warp.

CHOLMOD factors it, through scikit-sparse (every call to it is in
:mod:`featurewarp_cli.engine.cholmod`). Where scikit-sparse cannot be imported,
SciPy's sparse LU does (``splu``; slower), with one notice on stderr per process.
Matrices are ``scipy.sparse`` matrices.

Ordering
--------
When L has the pattern of a grid's 5-point Laplacian (what
:func:`featurewarp_cli.engine.system.normal_matrix` builds: offsets 0, +-1 and +-nx),
the free unknowns are numbered in a geometric nested-dissection order of the
grid cut along diagonals (:func:`.ordering.grid_nested_dissection`); the shared unknowns
of tied features, each coupled to every node around its feature, come after
everything else. The reduced matrix is permuted into that order and CHOLMOD
factors it with its natural ordering, which skips the ordering it would
otherwise compute. Measured against CHOLMOD's default ordering (AMD here; METIS
fills as little as ours but takes seconds to analyse) on the Table 1 grids
(benchmarks/solver_orderings.py, supernodal, medians of 5, 2 cores):
500 x 500 nodes: nnz(L) 4.55 M vs 5.30 M, analysis + factor 0.16 s vs 0.24 s;
1000 x 1000: 21.2 M vs 27.4 M, 0.70 s vs 1.32 s (our ordering itself takes 0.02
and 0.09 s). Other patterns use CHOLMOD's default ordering. Symbolic
analyses (keyed by the sparsity pattern) and grid orderings (keyed by the tied
nodes) are kept in a small module-level cache, so refactoring a matrix with
the same pattern (new weights, same ties) reuses both, and the x and y systems
of a sliding border share the ordering.

The x and y systems of a sliding border are factored one after the other:
scikit-sparse holds the GIL while CHOLMOD factors.
"""

from __future__ import annotations

import hashlib
import threading
from collections import OrderedDict

import numpy as np
import scipy.sparse as sp

from .. import stages
from . import cholmod
from .ordering import grid_nested_dissection

_fallback_noted = False

#: More shared unknowns (tied features) than this and the grid order, which eliminates them
#: last (a dense block of their count), gives way to CHOLMOD's own (see ReducedSystem):
#: measured on 1 MP with 100-3000 single-pixel features, the crossover lies at 200-300.
MAX_SHARED_LAST = 256
#: Largest system factored by CHOLMOD's simplicial method (supernodal above). Grid
#: systems in the grid order (2 cores, medians of 5-9, OpenMP off, see cholmod.py):
#: simplicial vs supernodal factor 0.030 vs 0.032 s at 51 k unknowns, 0.15 vs 0.13 s at
#: 191 k, 1.42 vs 0.67 s at 772 k; simplicial solves (x and y) are about twice as fast
#: (1.7 vs 6.4 ms at 51 k, 10 vs 18 ms at 191 k), and the fold-over guard back-substitutes
#: tens to hundreds of times: the 12 MP swirl 360 with the head + helmet mask (160 k nodes)
#: 11.5 -> 8.9 s, the swirl 540 (321 k) 46 -> 36 s, the same results.
_SIMPLICIAL_MAX = 400_000
#: Columns of one back-substitution of a simplicial factor in :meth:`ReducedSystem.entries` at
#: most: a multiple of 4, as CHOLMOD solves a simplicial factor's right-hand sides 4 columns at
#: a time, each group on its own (the same bits in any such split). The guard's first direct
#: step on the 1 MP grid (187 unit forces, 30 k unknowns, in 6 calls of 34): 99 ms in a solve
#: of 34 columns, 61 ms 8 at a time, each with its own right-hand sides (2 cores, loaded).
_SOLVE_COLUMNS = 8
#: Entries kept in the cache: symbolic analyses (keyed by the reduced matrix's
#: sparsity pattern) and grid orderings (keyed by the tied nodes).
_SYMBOLIC_CACHE_SIZE = 8
_symbolic_cache: OrderedDict = OrderedDict()
#: Solves may run in two threads (the editor's Export beside a preview): one at a time in the cache.
_cache_lock = threading.Lock()


def _grid_width(row: np.ndarray, col: np.ndarray, n: int) -> int | None:
    """nx when the lower-triangle entries (row >= col) of an (n, n) matrix lie on
    the pattern of an (n/nx) x nx grid's 5-point stencil (offsets 0, 1, nx), else None."""
    if row.size == 0 or n < 4:
        return None
    offset = row - col
    nx = int(offset.max())
    if nx < 2 or n % nx or not np.all((offset <= 1) | (offset == nx)):
        return None
    return nx


def _digest(*arrays: np.ndarray) -> str:
    """Hash of the arrays' types, shapes and contents (a cache key)."""
    digest = hashlib.blake2b(digest_size=16)
    for a in arrays:
        digest.update(str((a.dtype, a.shape)).encode())
        digest.update(np.ascontiguousarray(a))
    return digest.hexdigest()


def _cached(key: tuple, compute):
    """``_symbolic_cache[key]``, computed by ``compute()`` when missing (least recently
    used entries dropped)."""
    with _cache_lock:
        if key in _symbolic_cache:
            _symbolic_cache.move_to_end(key)
            return _symbolic_cache[key]
    value = compute()                       # outside the lock: two threads may both compute it
    with _cache_lock:
        _symbolic_cache[key] = value
        while len(_symbolic_cache) > _SYMBOLIC_CACHE_SIZE:
            _symbolic_cache.popitem(last=False)
    return value


def _unknown_order(unknown: np.ndarray, n_unknowns: int, nx: int) -> np.ndarray:
    """Elimination order of the unknowns: ``order[k]`` is the unknown eliminated k-th.

    Free unknowns (one node each) in the grid's nested-dissection order, then
    shared unknowns (tied features) and any unused index. The dissection is of
    every node not tied (fixed ones dropped afterwards), so the x and y systems of
    a sliding border share it; it is cached with the symbolic analyses.
    """
    counts = np.bincount(unknown[unknown >= 0], minlength=n_unknowns)
    single = counts[np.maximum(unknown, 0)] == 1
    untied = ((unknown < 0) | single).reshape(-1, nx)
    nodes = _cached(("nested-dissection", untied.shape, _digest(np.packbits(untied))),
                    lambda: grid_nested_dissection(untied))
    nodes = nodes[unknown[nodes] >= 0]
    return np.concatenate([unknown[nodes], np.flatnonzero(counts != 1)])


def _cholmod_factor(lower, natural: bool):
    """CHOLMOD factor of the symmetric matrix whose lower triangle is ``lower`` (CSC),
    reusing a cached symbolic analysis of the same pattern.

    Up to :data:`_SIMPLICIAL_MAX` unknowns the simplicial factorization is used,
    above it the supernodal one.
    """
    n = lower.shape[0]
    supernodal = n > _SIMPLICIAL_MAX
    key = ("symbolic", n, natural, supernodal, _digest(lower.indptr, lower.indices))
    analysis = _cached(key, lambda: cholmod.analyze(lower, "natural" if natural else "default", supernodal))
    return cholmod.factorize(analysis, lower, simplicial=not supernodal)


def _splu_solve(lower):
    """``solve(b)`` by SciPy's sparse LU of the symmetric matrix with this lower triangle."""
    from scipy.sparse.linalg import splu

    global _fallback_noted
    if not _fallback_noted:
        stages.notice("scikit-sparse (CHOLMOD) cannot be imported; using SciPy's sparse LU, which is slower")
        _fallback_noted = True
    try:
        return splu((lower + sp.tril(lower, -1).T).tocsc()).solve
    except RuntimeError as error:                      # "Factor is exactly singular"
        raise cholmod.NotPositiveDefinite(f"the matrix is singular ({error})") from None


def _unknown_entries(matrix, unknown: np.ndarray):
    """(row, col, val, ur, uc): the lower triangle's entries of L between nodes that have an
    unknown, and those unknowns; an edge between two nodes of one unknown counts twice (it lands
    twice on that unknown's diagonal, once from each triangle of L)."""
    row, col, val = _lower_entries(matrix)
    ur, uc = unknown[row], unknown[col]
    keep = np.flatnonzero((ur >= 0) & (uc >= 0))
    row, col, val, ur, uc = row[keep], col[keep], val[keep], ur[keep], uc[keep]
    return row, col, np.where((ur == uc) & (row != col), 2 * val, val), ur, uc


def _reduced_lower(val, ur: np.ndarray, uc: np.ndarray, n: int):
    """The reduced lower triangle P' L P as a CSC matrix (duplicates summed, indices sorted)
    from entries on unknowns ``ur``, ``uc`` numbered in the elimination order."""
    lower = sp.csc_matrix((val, (np.maximum(ur, uc), np.minimum(ur, uc))), shape=(n, n))
    lower.sort_indices()
    return lower


def _lower_entries(matrix) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(rows, cols, vals) of the lower triangle (rows >= cols) of a sparse matrix."""
    coo = matrix.tocoo()
    low = coo.row >= coo.col
    return coo.row[low].astype(np.int64), coo.col[low].astype(np.int64), coo.data[low].astype(np.float64)


class ReducedSystem:
    """Factor P^T L P once; solve for many right-hand sides and offsets.

    Parameters
    ----------
    matrix : (N, N) scipy.sparse matrix
        Symmetric positive semi-definite normal matrix L = A^T A
        (:func:`featurewarp_cli.engine.system.normal_matrix`, or rows and
        columns of it).
    unknown : (N,) int ndarray
        Unknown index of each node, or -1 for a fixed node. Several nodes may
        share one unknown.

    Attributes
    ----------
    method : str
        ``'cholmod'``, ``'scipy-splu'`` or ``'none'`` (nothing to solve).
    ordering : str
        ``'grid-nested-dissection'`` when the grid order was used, else ``'default'``.

    Raises
    ------
    featurewarp_cli.engine.cholmod.NotPositiveDefinite
        When P^T L P is not positive definite (singular, with SciPy's LU).
    """

    def __init__(self, matrix, unknown: np.ndarray):
        unknown = np.asarray(unknown, dtype=np.int64)
        self.unknown = unknown
        self.n_unknowns = n = int(unknown.max()) + 1 if unknown.size else 0
        self.matrix = matrix
        self._solve = None
        self._lower, self._rank = None, None
        self.method = "none"
        self.ordering = "default"
        if n == 0:
            return
        row, col, val, ur, uc = _unknown_entries(matrix, unknown)
        nx = _grid_width(row, col, matrix.shape[0])
        shared = np.count_nonzero(np.bincount(unknown[unknown >= 0], minlength=n) > 1)
        if shared > MAX_SHARED_LAST:
            nx = None           # many tied features: CHOLMOD's own ordering (see MAX_SHARED_LAST)
        position = unknown[unknown >= 0]
        if nx is not None:
            rank = np.empty(n, dtype=np.int64)
            rank[_unknown_order(unknown, n, nx)] = np.arange(n)
            ur, uc = rank[ur], rank[uc]
            position = rank[position]
            self.ordering, self._rank = "grid-nested-dissection", rank
        self._set_projection(unknown, position, n)
        lower = _reduced_lower(val, ur, uc, n)
        if cholmod.AVAILABLE:
            self.method = "cholmod"
            factor = _cholmod_factor(lower, natural=nx is not None)
            self._solve = lambda b: cholmod.solve(factor, b)
        else:
            self.method = "scipy-splu"
            self._solve = _splu_solve(lower)

    def _set_projection(self, unknown: np.ndarray, position: np.ndarray, n: int) -> None:
        """P in the elimination order (``position``: the unknown of each non-fixed node).

        The scatter puts each unknown's value on its nodes, the gather (P^T) sums
        them back: a copy for the unknowns of one node, np.bincount (in node order,
        as a sparse product adds) for the shared ones. (np.take is several times as
        fast as fancy indexing on (N, 2) arrays.)
        """
        nodes = np.flatnonzero(unknown >= 0)
        self._scatter = np.full(unknown.size, n, dtype=np.int64)   # n: a zero row (fixed nodes)
        self._scatter[nodes] = position
        single = np.bincount(position, minlength=n)[position] == 1
        self._gather = np.zeros(n, dtype=np.int64)                   # the node of each unknown
        self._gather[position[single]] = nodes[single]
        shared = ~single
        self._shared = ((nodes[shared], position[shared], np.unique(position[shared]))
                        if shared.any() else None)

    def solve(self, rhs: np.ndarray, offset: np.ndarray) -> np.ndarray:
        """Minimise |A x - b|^2 over x = P z + q.

        Parameters
        ----------
        rhs : (N, k) ndarray
            A^T b for the k coordinates (x and y: k = 2).
        offset : (N, k) ndarray
            q: the position of fixed nodes, the offset of tied nodes, 0 for free ones.
            Or both SciPy sparse matrices (many columns that are mostly zero: L q is then a
            sparse product, a third of :class:`components.ScaleSolver`'s set-up on 46).

        Returns
        -------
        (N, k) ndarray
            All node positions.
        """
        sparse = hasattr(offset, "toarray")
        if self.n_unknowns == 0:
            return offset.toarray() if sparse else offset.copy()
        if sparse:
            residual = np.ascontiguousarray((rhs - self.matrix @ offset).toarray().T)
            offset = offset.toarray()
        else:
            residual = rhs.T - (self.matrix @ offset).T                   # (k, N)
        return offset + self._back_substitute(residual)

    def move(self, force: np.ndarray) -> np.ndarray:
        """(N, k): the positions' change under ``force``, :meth:`solve` with a zero offset but
        without its product of the matrix and the offset (0 on fixed nodes, one per unknown)."""
        if self.n_unknowns == 0:
            return np.zeros_like(force)
        return self._back_substitute(np.ascontiguousarray(force.T))

    def _back_substitute(self, residual: np.ndarray) -> np.ndarray:
        """(N, k): P (P' L P)^-1 P' of ``residual`` ((k, N) float64)."""
        n = self.n_unknowns
        gathered = np.take(residual, self._gather, axis=1)
        if self._shared is not None:
            nodes, position, shared = self._shared
            for j, row in enumerate(residual):
                gathered[j, shared] = np.bincount(position, row[nodes], minlength=n)[shared]
        z = np.zeros((n + 1, residual.shape[0]))
        z[:n] = self._solve(gathered.T)                               # (n, k), F-ordered: no copy
        return np.take(z, self._scatter, axis=0)

    def normal_between(self, ids: np.ndarray):
        """(k, k) COO matrix: the lower triangle of P' L P (the reduced system's own matrix)
        between the unknowns ``ids`` (unique), in their order, each entry once: a slice of the
        factored matrix, so a tied feature's thousands of nodes cost nothing here (summing
        their rows of L did, per step). That matrix is built again at the first call (the
        factorization does not keep it: 39 bytes an unknown) and kept for the later ones."""
        if self.n_unknowns == 0:
            return sp.coo_matrix((ids.size, ids.size))
        if self._lower is None:
            _, _, val, ur, uc = _unknown_entries(self.matrix, self.unknown)
            if self._rank is not None:
                ur, uc = self._rank[ur], self._rank[uc]
            self._lower = _reduced_lower(val, ur, uc, self.n_unknowns)
        at = ids if self._rank is None else self._rank[ids]
        block = self._lower[:, at].tocsr()[at].tocoo()   # each pair once, below in elimination order
        return sp.coo_matrix((block.data, (np.maximum(block.row, block.col), np.minimum(block.row, block.col))),
                             shape=block.shape)      # folded onto the lower triangle in ``ids``' order

    def entries(self, rows: np.ndarray, columns: np.ndarray) -> np.ndarray:
        """(r, c): the moves of the nodes ``rows`` under a unit force on each node of ``columns``
        (the solve's linear part, the inverse's entries; back-substitutions of
        :data:`_SOLVE_COLUMNS` columns at a time on a simplicial factor, else one for all columns;
        fixed nodes neither move nor pass a force on)."""
        n, at = self.n_unknowns, self._scatter[rows]
        out = np.zeros((rows.size, columns.size))
        inside = at < n
        step = _SOLVE_COLUMNS if self.method == "cholmod" and n <= _SIMPLICIAL_MAX else max(columns.size, 1)
        for start in range(0, columns.size if n else 0, step):
            part = columns[start:start + step]
            forces = np.zeros((n + 1, part.size), order="F")
            forces[self._scatter[part], np.arange(part.size)] = 1.0
            moved = self._solve(forces[:n])                       # F-ordered slice: no copy
            out[inside, start:start + step] = moved[at[inside]]
        return out


class AxisSystems:
    """The factored system for x and for y: one shared factorization when both
    coordinates hold the same nodes, two when a sliding border frees one of them
    (factored one after the other).

    Parameters
    ----------
    matrix : (N, N) scipy.sparse matrix
        The normal matrix (:func:`featurewarp_cli.engine.system.normal_matrix`).
    unknown_x, unknown_y : (N,) int ndarray
        Unknown numbering per coordinate (see :class:`ReducedSystem`).

    Attributes
    ----------
    method : str
        See :class:`ReducedSystem`.
    factorizations : int
        1 or 2.
    """

    def __init__(self, matrix, unknown_x: np.ndarray, unknown_y: np.ndarray):
        self.x = ReducedSystem(matrix, unknown_x)
        self.y = self.x if np.array_equal(unknown_x, unknown_y) else ReducedSystem(matrix, unknown_y)
        self.method = self.x.method
        self.factorizations = 1 if self.y is self.x else 2

    def solve(self, rhs: np.ndarray, offset: np.ndarray) -> np.ndarray:
        """Node positions (N, 2); see :meth:`ReducedSystem.solve`."""
        if self.y is self.x:
            return self.x.solve(rhs, offset)
        return np.concatenate([self.x.solve(rhs[:, :1], offset[:, :1]),
                               self.y.solve(rhs[:, 1:], offset[:, 1:])], axis=1)

    def move(self, force: np.ndarray) -> np.ndarray:
        """(N, 2): :meth:`ReducedSystem.move` for x and for y."""
        if self.y is self.x:
            return self.x.move(force)
        return np.concatenate([self.x.move(force[:, :1]), self.y.move(force[:, 1:])], axis=1)

    def admits(self, points: np.ndarray, offset: np.ndarray, tolerance: float = 1e-9) -> bool:
        """Whether ``points`` ((N, 2)) are positions of these systems for ``offset``: held
        coordinates at it, the nodes of one unknown at it plus one shared move (a start that
        Newton steps built from :meth:`solve`'s linear part keep so exactly)."""
        for k, unknown in enumerate((self.x.unknown, self.y.unknown)):
            moved, on = points[:, k] - offset[:, k], unknown >= 0
            low, high = np.full(unknown.max() + 1, np.inf), np.full(unknown.max() + 1, -np.inf)
            np.minimum.at(low, unknown[on], moved[on])
            np.maximum.at(high, unknown[on], moved[on])
            if np.abs(moved[~on]).max(initial=0.0) > tolerance or (high - low).max(initial=0.0) > tolerance:
                return False
        return True

    def normal_between(self, axis: int, ids: np.ndarray):
        """:meth:`ReducedSystem.normal_between` of the x (``axis`` 0) or the y system."""
        return (self.x, self.y)[axis].normal_between(ids)

    def entries(self, rows: np.ndarray, columns: np.ndarray) -> np.ndarray:
        """(2, r, c): :meth:`ReducedSystem.entries` for x and for y."""
        x = self.x.entries(rows, columns)
        return np.stack([x, x if self.y is self.x else self.y.entries(rows, columns)])


def spd_solver(matrix, lower: bool = False):
    """``solve(b)`` for a symmetric positive definite sparse ``matrix`` (``lower``: its lower
    triangle only, CSC), factored once (CHOLMOD with its default ordering, or SciPy's sparse LU
    without scikit-sparse).

    ``b``: (n,) or (n, k) ndarray. Raises :class:`cholmod.NotPositiveDefinite`."""
    lower = matrix if lower else sp.tril(matrix, format="csc")
    lower.sort_indices()
    if not cholmod.AVAILABLE:
        return _splu_solve(lower)
    factor = _cholmod_factor(lower, natural=False)
    return lambda b: cholmod.solve(factor, np.asfortranarray(b, dtype=np.float64))

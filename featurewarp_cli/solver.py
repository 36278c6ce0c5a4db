"""Sparse Cholesky factorization of the normal equations under a linear reparametrization.

Node positions are written x = P z + q: a node is either fixed (its position is
q), free (its own unknown), or tied to a shared unknown (x = q + t, used to move
a whole feature as one rigid piece whose linear part is already in q). The
reduced matrix P^T L P depends on L and on which node maps to which unknown,
never on q, so one factorization serves every warp.

CHOLMOD (scikit-sparse) when it can be imported; SciPy's sparse LU otherwise,
with one notice on stderr per process.

Ordering
--------
When L has the pattern of a grid's 5-point Laplacian (what
:func:`featurewarp_cli.system.normal_matrix` builds: offsets 0, +-1 and +-nx),
the unknowns are numbered in a geometric nested-dissection order of the grid
(:func:`grid_nested_dissection`): each rectangle is cut by its middle row or
column of nodes, the two halves are numbered first and the separator last; the
shared unknowns of tied features, each coupled to every node around its
feature, come after everything else. CHOLMOD then factors with its natural
ordering, which skips the graph partitioning it would otherwise run (seconds on
a million unknowns) and gives a factor as sparse as METIS's. Other patterns use
CHOLMOD's default ordering. The symbolic analysis is kept in a small
module-level cache keyed by the sparsity pattern, so refactoring a matrix with
the same pattern (another mask with the same ties, new weights) reuses it.
"""

from __future__ import annotations

import hashlib
import sys
from collections import OrderedDict
from functools import lru_cache

import numpy as np
import scipy.sparse as sp

_fallback_noted = False

#: Grid rectangles with at most this many nodes are numbered row by row.
_LEAF_NODES = 16
#: Largest system factored by CHOLMOD's simplicial method (supernodal above).
#: Measured on the grid systems (2 cores): up to ~60 k unknowns simplicial factors
#: as fast; at 190 k it factors 0.2 s slower (0.55 s vs 0.35 s) but solves twice
#: as fast (22 ms vs 38 ms for x and y), which pays off after ~12 solves, and the
#: fold-over guard solves dozens of times per factorization.
_SIMPLICIAL_MAX = 250_000
#: Symbolic analyses kept (keyed by the reduced matrix's sparsity pattern).
_SYMBOLIC_CACHE_SIZE = 4
_symbolic_cache: OrderedDict = OrderedDict()


def grid_nested_dissection(ny: int, nx: int, leaf: int = _LEAF_NODES) -> np.ndarray:
    """Nested-dissection order of the nodes of an ``ny`` x ``nx`` grid (row-major numbering).

    The rectangle is split by its middle column (or row, whichever side is
    longer) into two halves and a one-node-wide separator; the halves are
    ordered recursively, then the separator. For the 5-point stencil a
    separator line disconnects the halves, so the Cholesky factor of a matrix
    numbered this way has O(n log n) fill and O(n^1.5) work.

    Computed level by level, vectorized over the rectangles of a level: every
    node gets a key whose base-4 digits are its path in the dissection tree
    (0 first half, 1 second half, 2 separator or leaf), so sorting the keys
    gives the post-order.

    Parameters
    ----------
    ny, nx : int
        Rows and columns of nodes.
    leaf : int
        Rectangles with at most this many nodes are numbered row by row.

    Returns
    -------
    (ny * nx,) int ndarray
        Node indices (``j * nx + i``) in elimination order (read-only, cached).
    """
    return _nested_dissection(int(ny), int(nx), int(leaf))


@lru_cache(maxsize=8)
def _nested_dissection(ny: int, nx: int, leaf: int) -> np.ndarray:
    order = np.empty(ny * nx, dtype=np.int64)
    # Active rectangles [r0, r1) x [c0, c1) and the position of their first node in the order.
    r0, r1 = np.array([0]), np.array([ny])
    c0, c1 = np.array([0]), np.array([nx])
    start = np.zeros(1, dtype=np.int64)
    while r0.size:
        h, w = r1 - r0, c1 - c0
        alive = (h > 0) & (w > 0)
        r0, r1, c0, c1, start, h, w = (a[alive] for a in (r0, r1, c0, c1, start, h, w))
        is_leaf = h * w <= max(leaf, 1)
        if is_leaf.any():                      # every node of the rectangle, row by row
            lh, lw, ls = h[is_leaf], w[is_leaf], start[is_leaf]
            size = lh * lw
            rect = np.repeat(np.arange(size.size), size)
            local = np.arange(size.sum()) - np.repeat(np.cumsum(size) - size, size)
            rows = r0[is_leaf][rect] + local // lw[rect]
            cols = c0[is_leaf][rect] + local % lw[rect]
            order[ls[rect] + local] = rows * nx + cols
        split = ~is_leaf
        r0, r1, c0, c1, start, h, w = (a[split] for a in (r0, r1, c0, c1, start, h, w))
        vertical = w >= h                      # cut by the middle column, else the middle row
        mid = np.where(vertical, (c0 + c1) // 2, (r0 + r1) // 2)
        first = (r0, np.where(vertical, r1, mid), c0, np.where(vertical, mid, c1))
        second = (np.where(vertical, r0, mid + 1), r1, np.where(vertical, mid + 1, c0), c1)
        first_size = (first[1] - first[0]) * (first[3] - first[2])
        second_size = (second[1] - second[0]) * (second[3] - second[2])
        # The separator comes after both halves.
        length = np.where(vertical, h, w)
        rect = np.repeat(np.arange(length.size), length)
        step = np.arange(length.sum()) - np.repeat(np.cumsum(length) - length, length)
        v = vertical[rect]
        rows = np.where(v, r0[rect] + step, mid[rect])
        cols = np.where(v, mid[rect], c0[rect] + step)
        order[(start + first_size + second_size)[rect] + step] = rows * nx + cols
        r0, r1, c0, c1 = (np.concatenate(pair) for pair in zip(first, second))
        start = np.concatenate([start, start + first_size])
    order.flags.writeable = False
    return order


def _grid_width(row: np.ndarray, col: np.ndarray, n: int) -> int | None:
    """nx when the entries (row, col) of an (n, n) matrix lie on the pattern of an
    (n/nx) x nx grid's 5-point stencil (offsets 0, +-1, +-nx), else None."""
    if row.size == 0 or n < 4:
        return None
    offset = np.abs(col.astype(np.int64) - row)
    nx = int(offset.max())
    if nx < 2 or n % nx or not np.all((offset <= 1) | (offset == nx)):
        return None
    return nx


def _unknown_order(unknown: np.ndarray, n_unknowns: int, nx: int | None) -> np.ndarray | None:
    """Elimination order of the unknowns: ``order[k]`` is the unknown eliminated k-th.

    Free unknowns (one node each) in the grid's nested-dissection order, then
    shared unknowns (tied features) in index order. None without a grid.
    """
    if nx is None:
        return None
    nodes = grid_nested_dissection(unknown.size // nx, nx)
    counts = np.bincount(unknown[unknown >= 0], minlength=n_unknowns)
    u = unknown[nodes]
    single = u[u >= 0]
    single = single[counts[single] == 1]
    shared = np.flatnonzero(counts > 1)
    rest = np.setdiff1d(np.arange(n_unknowns), np.concatenate([single, shared]), assume_unique=True)
    return np.concatenate([single, rest, shared]).astype(np.int64)


def _pattern_key(matrix: sp.csc_matrix) -> tuple:
    digest = hashlib.blake2b(digest_size=16)
    digest.update(np.ascontiguousarray(matrix.indptr, dtype=np.int64).tobytes())
    digest.update(np.ascontiguousarray(matrix.indices, dtype=np.int64).tobytes())
    return matrix.shape[0], matrix.nnz, digest.hexdigest()


def _cholmod_factor(lower: sp.csc_matrix, natural: bool):
    """CHOLMOD factor of the symmetric matrix whose lower triangle is ``lower``,
    reusing a cached symbolic analysis of the same pattern.

    Up to :data:`_SIMPLICIAL_MAX` unknowns the simplicial factorization is used:
    its solves are twice as fast (no BLAS calls on small blocks, no idle BLAS
    threads) for a factorization that is as fast or a little slower; above,
    the supernodal one.
    """
    from sksparse.cholmod import analyze

    mode = "simplicial" if lower.shape[0] <= _SIMPLICIAL_MAX else "supernodal"
    key = _pattern_key(lower) + (natural, mode)
    symbolic = _symbolic_cache.get(key)
    if symbolic is None:
        symbolic = analyze(lower, mode=mode, ordering_method="natural" if natural else "default")
        _symbolic_cache[key] = symbolic
        while len(_symbolic_cache) > _SYMBOLIC_CACHE_SIZE:
            _symbolic_cache.popitem(last=False)
    else:
        _symbolic_cache.move_to_end(key)
    return symbolic.cholesky(lower)


class ReducedSystem:
    """Factor P^T L P once; solve for many right-hand sides and offsets.

    Parameters
    ----------
    matrix : (N, N) sparse matrix
        Symmetric positive semi-definite normal matrix L = A^T A.
    unknown : (N,) int ndarray
        Unknown index of each node, or -1 for a fixed node. Several nodes may
        share one unknown.

    Attributes
    ----------
    method : str
        ``'cholmod'``, ``'scipy-splu'`` or ``'none'`` (nothing to solve).
    ordering : str
        ``'grid-nested-dissection'`` when the grid order was used, else ``'default'``.
    """

    def __init__(self, matrix: sp.spmatrix, unknown: np.ndarray):
        global _fallback_noted
        unknown = np.asarray(unknown, dtype=np.int64)
        self.unknown = unknown
        self.n_unknowns = int(unknown.max()) + 1 if unknown.size else 0
        self.matrix = sp.csr_matrix(matrix)
        self._solve = None
        self.method = "none"
        self.ordering = "default"
        if self.n_unknowns == 0:
            return
        coo = self.matrix.tocoo()
        nonzero = coo.data != 0
        row, col, val = coo.row[nonzero], coo.col[nonzero], coo.data[nonzero]
        ur, uc = unknown[row], unknown[col]
        keep = (ur >= 0) & (uc >= 0)
        ur, uc, val = ur[keep], uc[keep], val[keep]
        order = _unknown_order(unknown, self.n_unknowns, _grid_width(row[keep], col[keep], coo.shape[0]))
        if order is not None:
            rank = np.empty(self.n_unknowns, dtype=np.int64)
            rank[order] = np.arange(self.n_unknowns)
            ur, uc = rank[ur], rank[uc]
            self.ordering = "grid-nested-dissection"
        n = self.n_unknowns
        # P in the elimination order: row k of the gather sums the nodes of the
        # k-th eliminated unknown; the scatter puts each solution back on its nodes.
        nodes = np.flatnonzero(unknown >= 0)
        position = unknown[nodes] if order is None else rank[unknown[nodes]]
        self._gather = sp.csr_matrix((np.ones(nodes.size), (position, nodes)), shape=(n, unknown.size))
        self._scatter = self._gather.T.tocsr()
        try:
            import sksparse.cholmod  # noqa: F401
        except ImportError:
            from scipy.sparse.linalg import splu

            if not _fallback_noted:
                sys.stderr.write("featurewarp: scikit-sparse (CHOLMOD) is not installed; "
                                 "using SciPy's sparse LU, which is slower\n")
                _fallback_noted = True
            self.method = "scipy-splu"
            reduced = sp.csc_matrix((val, (ur, uc)), shape=(n, n))
            self._solve = splu(reduced).solve
        else:
            self.method = "cholmod"
            low = ur >= uc
            lower = sp.csc_matrix((val[low], (ur[low], uc[low])), shape=(n, n))
            lower.sum_duplicates()
            lower.sort_indices()
            self._solve = _cholmod_factor(lower, natural=order is not None)

    def solve(self, rhs: np.ndarray, offset: np.ndarray) -> np.ndarray:
        """Minimise |A x - b|^2 over x = P z + q.

        Parameters
        ----------
        rhs : (N, 2) ndarray
            A^T b for the x and y coordinates.
        offset : (N, 2) ndarray
            q: the position of fixed nodes, the offset of tied nodes, 0 for free ones.

        Returns
        -------
        (N, 2) ndarray
            All node positions.
        """
        if self.n_unknowns == 0:
            return offset.copy()
        residual = rhs - self.matrix @ offset
        z = self._solve(np.ascontiguousarray(self._gather @ residual))
        return self._scatter @ z + offset

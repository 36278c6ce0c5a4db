"""Sparse Cholesky factorization of the normal equations under a linear reparametrization.

Node positions are written x = P z + q: a node is either fixed (its position is
q), free (its own unknown), or tied to a shared unknown (x = q + t, used to move
a whole feature as one rigid piece whose linear part is already in q). The
reduced matrix P^T L P depends on L and on which node maps to which unknown,
never on q, so one factorization serves every warp.

CHOLMOD through the small binding :mod:`featurewarp_cli._cholmod` when it is
built; SciPy's sparse LU otherwise (imported only then), with one notice on
stderr per process. Nothing here imports SciPy when the binding is there: the
reduced matrix is assembled as triplets with numpy, and P and P^T are numpy
indexing and :func:`numpy.bincount`.

Ordering
--------
When L has the pattern of a grid's 5-point Laplacian (what
:func:`featurewarp_cli.engine.system.normal_matrix` builds: offsets 0, +-1 and +-nx),
the free unknowns are numbered in a geometric nested-dissection order of the
grid cut along diagonals (:func:`grid_nested_dissection`); the shared unknowns
of tied features, each coupled to every node around its feature, come after
everything else. CHOLMOD then factors with its natural ordering, which skips
the graph partitioning it would otherwise run (seconds on a million unknowns)
for a factor about as sparse as METIS's. Other patterns use CHOLMOD's default
ordering. Symbolic analyses (keyed by the sparsity pattern) and grid orderings
(keyed by the tied nodes) are kept in a small module-level cache, so
refactoring a matrix with the same pattern (new weights, same ties) reuses
both, and the x and y systems of a sliding border share the ordering.

Threads
-------
Systems may be factored in several threads at once (the x and y systems of a
sliding border are): the binding runs CHOLMOD without the GIL, each factor has
its own CHOLMOD workspace, and the cache computes each entry once (a second
thread asking for an entry being computed waits for it).
"""

from __future__ import annotations

import ctypes
import hashlib
import os
import sys
import threading
from collections import OrderedDict
from concurrent.futures import Future, ThreadPoolExecutor
from contextlib import contextmanager

import numpy as np

try:
    from .. import _cholmod
except ImportError:              # not built: SciPy's splu (see ReducedSystem)
    _cholmod = None
#: Index type of the binding's triplets (CHOLMOD's int API).
INDEX = np.int32

_fallback_noted = False

#: Pieces of the grid with at most this many live nodes are not dissected further.
_LEAF_NODES = 16
#: A cut may move this fraction of a piece's extent away from its middle (to cross holes).
_CUT_WINDOW = 0.1
#: Largest system factored by CHOLMOD's simplicial method (supernodal above).
#: Measured on the grid systems (2 cores): up to ~120 k unknowns both factor as
#: fast, and simplicial solves are twice as fast (7 vs 13 ms for x and y at 68 k);
#: at 190 k the supernodal factorization is 0.05-0.1 s faster (0.29 vs 0.34-0.39 s)
#: for solves 20 ms slower (35 vs 15 ms), and a warp solves its full grid once (the
#: fold-over guard's many solves use a smaller window system).
_SIMPLICIAL_MAX = 150_000
#: Entries kept in the cache: symbolic analyses (keyed by the reduced matrix's
#: sparsity pattern) and grid orderings (keyed by the tied nodes).
_SYMBOLIC_CACHE_SIZE = 8
#: key -> Future of the value (done, or being computed by one thread).
_symbolic_cache: OrderedDict = OrderedDict()
_cache_lock = threading.Lock()


def grid_nested_dissection(live: np.ndarray, leaf: int = _LEAF_NODES,
                           window: float = _CUT_WINDOW) -> np.ndarray:
    """Nested-dissection order of the live nodes of a grid, cut along diagonals.

    In the 5-point stencil a node touches only its row and column neighbours,
    so a diagonal line of nodes (x + y or x - y constant) separates the two
    sides as well as a straight one, and a diamond-shaped piece has about
    0.7 times the boundary of a square of the same area. Dissecting along
    diagonals gives two thirds of the fill and half the work of straight cuts
    on the feature grids (about as sparse as METIS). In the rotated
    coordinates u = x + y, v = x - y the pieces are rectangles: each is cut
    across its longer side, at the line with the fewest live nodes within
    ``window`` of the middle (cuts through holes are cheap); the two halves
    are numbered first, then the cut. Pieces with at most ``leaf`` live nodes
    are numbered line by line.

    A grid more than about twice as long as wide is first cut straight across
    into blocks at most that long (the rotated bounding box of a long strip
    would be mostly empty); the blocks come first, then the lines between
    them. The blocks are dissected together level by level, vectorized over
    the pieces of a level, with prefix sums of the live nodes for the counts.

    Parameters
    ----------
    live : (ny, nx) bool ndarray
        Nodes to order (the others, fixed or tied, are left out).
    leaf : int
        Pieces with at most this many live nodes are not cut.
    window : float
        How far from the middle a cut may move, as a fraction of the piece's extent.

    Returns
    -------
    (live.sum(),) int ndarray
        Node indices (``j * nx + i``) in elimination order.
    """
    live = np.asarray(live, dtype=bool)
    ny, nx = live.shape
    if ny > nx:                                # tall: as its transpose
        x, y = np.divmod(grid_nested_dissection(live.T, leaf, window), ny)
        return y * nx + x
    # Blocks at most about twice as wide as high, between separator columns numbered last.
    blocks = -(-nx // (2 * ny + 2))
    cuts = np.arange(1, blocks) * (nx + 1) // blocks - 1
    left = np.concatenate([[0], cuts + 1])     # first column of each block
    width = np.concatenate([cuts, [nx]]) - left
    which, row = np.nonzero(live[:, cuts].T)
    separators = row * nx + cuts[which]
    y, x = np.nonzero(live)
    block = np.searchsorted(cuts, x)
    inside = ~np.isin(x, cuts)
    y, x, block = y[inside], x[inside], block[inside]
    order = np.empty(y.size, dtype=np.int64)
    if not y.size:
        return separators
    # The blocks side by side in rotated coordinates: cell[u, v] is the node at
    # x' + y = u, x' - y + ny - 1 + size * block = v (x' from its block's first
    # column), or -1 where there is no live node.
    size = ny + int(width.max()) - 1
    xb = x - left[block]
    cell = np.full((size, size * blocks), -1, dtype=np.int32)
    cell[xb + y, xb - y + ny - 1 + size * block] = y * nx + x
    total = np.zeros((size + 1, size * blocks + 1), dtype=np.int32)
    total[1:, 1:] = cell >= 0
    np.cumsum(total, axis=0, out=total)
    np.cumsum(total, axis=1, out=total)

    def count(r0, r1, c0, c1):                 # live nodes in [r0, r1) x [c0, c1)
        return total[r1, c1] - total[r0, c1] - total[r1, c0] + total[r0, c0]

    # Pieces [r0, r1) x [c0, c1) in (u, v), their live count and first position in the order.
    r0, r1 = np.zeros(blocks, dtype=np.int64), np.full(blocks, size)
    c0 = np.arange(blocks) * size
    c1 = c0 + size
    n = count(r0, r1, c0, c1)
    start = np.cumsum(n) - n
    while r0.size:
        small = n <= leaf
        if small.any():
            _place(order, start[small], n[small], cell, r0[small], r1[small], c0[small], c1[small])
        r0, r1, c0, c1, n, start = (a[~small] for a in (r0, r1, c0, c1, n, start))
        # Cut a column (fixed v) of wide pieces, a row of tall ones; candidates near the middle.
        across = c1 - c0 >= r1 - r0
        lo, hi = np.where(across, c0, r0), np.where(across, c1, r1)
        mid = (lo + hi) // 2
        reach = (window * (hi - lo)).astype(np.int64)
        first, last = np.maximum(lo, mid - reach), np.minimum(hi - 1, mid + reach)
        k = last - first + 1
        piece = np.repeat(np.arange(k.size), k)
        cut = first[piece] + np.arange(k.sum()) - np.repeat(np.cumsum(k) - k, k)
        column = across[piece]
        line = count(np.where(column, r0[piece], cut), np.where(column, r1[piece], cut + 1),
                     np.where(column, cut, c0[piece]), np.where(column, cut + 1, c1[piece]))
        # Per piece the emptiest line, the one nearest the middle among equals.
        cut = cut[np.lexsort((np.abs(cut - mid[piece]), line, piece))[np.cumsum(k) - k]]
        one = (r0, np.where(across, r1, cut), c0, np.where(across, cut, c1))
        two = (np.where(across, r0, cut + 1), r1, np.where(across, cut + 1, c0), c1)
        n1, n2 = count(*one), count(*two)
        _place(order, start + n1 + n2, n - n1 - n2, cell, np.where(across, r0, cut),
               np.where(across, r1, cut + 1), np.where(across, cut, c0), np.where(across, cut + 1, c1))
        r0, r1, c0, c1 = (np.concatenate(pair) for pair in zip(one, two))
        n, start = np.concatenate([n1, n2]), np.concatenate([start, start + n1])
        keep = n > 0
        r0, r1, c0, c1, n, start = (a[keep] for a in (r0, r1, c0, c1, n, start))
    return np.concatenate([order, separators])


def _place(order, start, n, cell, r0, r1, c0, c1):
    """Write the live nodes of each rectangle of ``cell`` (row by row) to
    ``order[start:start + n]`` (``n`` = its number of live nodes)."""
    w = c1 - c0
    area = (r1 - r0) * w
    rect = np.repeat(np.arange(area.size), area)
    row, col = np.divmod(np.arange(area.sum()) - np.repeat(np.cumsum(area) - area, area), w[rect])
    nodes = cell.ravel()[(r0 * cell.shape[1] + c0)[rect] + row * cell.shape[1] + col]
    nodes = nodes[nodes >= 0]
    order[np.repeat(start - (np.cumsum(n) - n), n) + np.arange(nodes.size)] = nodes


def _grid_width(row: np.ndarray, col: np.ndarray, n: int, nx: int | None = None) -> int | None:
    """nx when the lower-triangle entries (row >= col) of an (n, n) matrix lie on
    the pattern of an (n/nx) x nx grid's 5-point stencil (offsets 0, 1, nx), else None.

    ``nx``: the grid width when the matrix is known to be a grid's stencil
    (:class:`featurewarp_cli.engine.system.StencilMatrix`); the entries are then not inspected.
    """
    if nx is not None:
        return nx if nx >= 2 and n >= 4 and n > nx else None
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
    """``_symbolic_cache[key]``, computed by ``compute()`` when missing (least recently used
    dropped). Thread-safe: one thread computes a missing entry, others asking meanwhile wait."""
    with _cache_lock:
        future = _symbolic_cache.get(key)
        mine = future is None
        if mine:
            future = _symbolic_cache[key] = Future()
            while len(_symbolic_cache) > _SYMBOLIC_CACHE_SIZE:
                _symbolic_cache.popitem(last=False)
        else:
            _symbolic_cache.move_to_end(key)
    if mine:
        try:
            future.set_result(compute())
        except BaseException as error:
            with _cache_lock:
                if _symbolic_cache.get(key) is future:
                    del _symbolic_cache[key]
            future.set_exception(error)
    return future.result()


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


_omp = None
_settings_lock = threading.Lock()


class _SharedSetting:
    """A process-wide runtime setting held at ``value`` while any thread is inside a
    ``with`` block of it: the first thread in sets it, the last one out restores it
    (counted under a lock, so nested and concurrent uses are safe)."""

    def __init__(self, get, set_, value):
        self._get, self._set, self._value = get, set_, value
        self._users, self._saved = 0, None

    def __enter__(self):
        with _settings_lock:
            self._users += 1
            if self._users == 1:
                self._saved = self._get()
                self._set(self._value)

    def __exit__(self, *exc):
        with _settings_lock:
            self._users -= 1
            if self._users == 0:
                self._set(self._saved)


def _openmp_runtime():
    """The OpenMP runtime loaded in this process (by CHOLMOD), as a ctypes library, or None;
    with ``per_thread`` set (see :func:`_without_openmp`)."""
    global _omp
    if _omp is not None:
        return _omp or None
    mode = getattr(os, "RTLD_NOLOAD", None)
    for name in ("libgomp.so.1", "libomp.so", "libomp.so.5") if mode is not None else ():
        try:
            omp = ctypes.CDLL(name, mode=mode)        # only when already loaded
        except OSError:
            continue
        with _settings_lock:
            omp.per_thread = _per_thread_levels(omp)
        omp.shared = _SharedSetting(omp.omp_get_max_active_levels, omp.omp_set_max_active_levels, 0)
        _omp = omp
        return omp
    if _cholmod is not None:                           # loaded with CHOLMOD or not at all
        _omp = False
    return None


def _per_thread_levels(omp) -> bool:
    """Whether the runtime keeps max-active-levels per thread (libgomp since GCC 11: an
    ICV of each thread's implicit task) rather than one value for the process."""
    level = omp.omp_get_max_active_levels()
    other = 0 if level > 0 else 1
    thread = threading.Thread(target=omp.omp_set_max_active_levels, args=(other,))
    thread.start()
    thread.join()
    if omp.omp_get_max_active_levels() == level:
        return True
    omp.omp_set_max_active_levels(level)
    return False


@contextmanager
def _without_openmp():
    """Run the OpenMP loops started from this thread (CHOLMOD's) on one thread.

    Debian's CHOLMOD runs the assembly loops of its supernodal factorization in
    OpenMP teams of a fixed 4 threads (several small parallel regions per
    supernode). On 2 cores the start-up and barriers of those teams cost more
    than the loops: the 1 M-unknown factorization took 1.2 s with them and
    0.85 s without (medians, other work running; the dense blocks still use
    the BLAS threads).

    Safe in several threads at once: where the runtime keeps the setting per
    thread (libgomp does) each thread sets and restores its own; where it keeps
    one for the process, the first thread in sets it and the last one out
    restores it (:class:`_SharedSetting`).
    """
    omp = _openmp_runtime()
    if omp is None:
        yield
        return
    if omp.per_thread:
        levels = omp.omp_get_max_active_levels()
        omp.omp_set_max_active_levels(0)
        try:
            yield
        finally:
            omp.omp_set_max_active_levels(levels)
        return
    with omp.shared:
        yield


_blas = None


def _openblas_runtime():
    """The system OpenBLAS that CHOLMOD uses, as a ctypes library, or None (another BLAS,
    or not loaded). NumPy's own OpenBLAS is a different library, not affected."""
    global _blas
    if _blas is None:
        _blas = False
        mode = getattr(os, "RTLD_NOLOAD", None)
        for name in ("libopenblas.so.0", "libblas.so.3", "libopenblas.so") if mode is not None else ():
            try:
                lib = ctypes.CDLL(name, mode=mode)       # only when already loaded
                lib.openblas_get_num_threads, lib.openblas_set_num_threads
            except (OSError, AttributeError):
                continue
            lib.shared = _SharedSetting(lib.openblas_get_num_threads, lib.openblas_set_num_threads, 1)
            _blas = lib
            break
    return _blas or None


@contextmanager
def _single_threaded_blas():
    """Run the system OpenBLAS on one thread (a process-wide :class:`_SharedSetting`).

    Two supernodal factorizations at once with OpenBLAS's own threads ran one
    after the other (its threaded calls share one server): the x and y systems
    of a 12 MP stretch (2 x 196 k unknowns) took 0.55 s either way; with one
    BLAS thread each, 0.31 s in parallel (2 cores).
    """
    blas = _openblas_runtime()
    if blas is None:
        yield
        return
    with blas.shared:
        yield


def factor_concurrently(matrix, unknowns: list) -> list:
    """A :class:`ReducedSystem` of ``matrix`` for each numbering in ``unknowns``, factored
    in parallel threads (CHOLMOD runs without the GIL), the BLAS on one thread each.

    Parameters
    ----------
    matrix : (N, N) matrix
    unknowns : list of (N,) int ndarray

    Returns
    -------
    list of ReducedSystem
    """
    if len(unknowns) < 2 or _cholmod is None:
        return [ReducedSystem(matrix, unknown) for unknown in unknowns]
    with _single_threaded_blas(), ThreadPoolExecutor(len(unknowns) - 1,
                                                     thread_name_prefix="featurewarp-factor") as pool:
        others = [pool.submit(ReducedSystem, matrix, unknown) for unknown in unknowns[1:]]
        first = ReducedSystem(matrix, unknowns[0])
        return [first] + [future.result() for future in others]


def _cholmod_factor(n: int, rows: np.ndarray, cols: np.ndarray, vals: np.ndarray, natural: bool, key):
    """CHOLMOD factor of the n x n symmetric matrix whose lower triangle has the triplets
    (rows >= cols; duplicates are summed), reusing a cached symbolic analysis of the
    same pattern (``key``: a hashable that identifies it).

    Up to :data:`_SIMPLICIAL_MAX` unknowns the simplicial factorization is used:
    its solves are twice as fast (no BLAS calls on small blocks, no idle BLAS
    threads) for a factorization that is as fast or a little slower; above,
    the supernodal one.
    """
    supernodal = n > _SIMPLICIAL_MAX
    ordering = _cholmod.NATURAL if natural else _cholmod.DEFAULT
    symbolic = _cached(("symbolic", n, key, natural, supernodal),
                       lambda: _cholmod.analyze(n, rows, cols, supernodal, ordering))
    with _without_openmp():
        return symbolic.factorize(rows, cols, vals)


def _lower_triplets(matrix) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(rows, cols, vals) of the lower triangle of a symmetric matrix: a
    :mod:`featurewarp_cli.system` matrix, or any SciPy sparse matrix."""
    if hasattr(matrix, "lower_triplets"):
        return matrix.lower_triplets()
    coo = matrix.tocoo()
    low = coo.row >= coo.col
    return coo.row[low].astype(np.int64), coo.col[low].astype(np.int64), coo.data[low].astype(np.float64)


class ReducedSystem:
    """Factor P^T L P once; solve for many right-hand sides and offsets.

    Parameters
    ----------
    matrix : (N, N) matrix
        Symmetric positive semi-definite normal matrix L = A^T A: a
        :class:`featurewarp_cli.engine.system.StencilMatrix` or ``StencilWindow``, or any
        SciPy sparse matrix (tests, benchmarks; read
        with ``tocoo()``). It needs a ``dot`` method.
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
    featurewarp_cli._cholmod.NotPositiveDefinite
        When P^T L P is not positive definite (with CHOLMOD).
    """

    def __init__(self, matrix, unknown: np.ndarray):
        global _fallback_noted
        unknown = np.asarray(unknown, dtype=np.int64)
        self.unknown = unknown
        self.n_unknowns = n = int(unknown.max()) + 1 if unknown.size else 0
        self.matrix = matrix
        self._solve = None
        self.method = "none"
        self.ordering = "default"
        if n == 0:
            return
        # Lower triangle of L on the unknowns; an edge between two nodes of one
        # unknown lands twice on its diagonal (once from each triangle of L).
        size = matrix.shape[0]
        row, col, val = _lower_triplets(matrix)
        stencil = getattr(matrix, "nx", None)
        index = unknown.astype(INDEX)
        ur, uc = index[row], index[col]
        keep = (ur >= 0) & (uc >= 0)
        if stencil is None:
            keep &= val != 0
        keep = np.flatnonzero(keep)
        row, col, val, ur, uc = row[keep], col[keep], val[keep], ur[keep], uc[keep]
        val = np.where((ur == uc) & (row != col), 2 * val, val)
        nx = _grid_width(row, col, size, stencil)
        position = unknown[unknown >= 0]
        if nx is not None:
            rank = np.empty(n, dtype=INDEX)
            rank[_unknown_order(unknown, n, nx)] = np.arange(n, dtype=INDEX)
            ur, uc = rank[ur], rank[uc]
            position = rank[position]
            self.ordering = "grid-nested-dissection"
        # P in the elimination order: the scatter puts each unknown's value on its
        # nodes, the gather (P^T) sums them back: a copy for the unknowns of one node,
        # np.bincount (in node order, as a sparse product adds) for the shared ones.
        # (np.take is several times as fast as fancy indexing on (N, 2) arrays.)
        nodes = np.flatnonzero(unknown >= 0)
        self._scatter = np.full(unknown.size, n, dtype=np.int64)   # n: a zero row (fixed nodes)
        self._scatter[nodes] = position
        single = np.bincount(position, minlength=n)[position] == 1
        self._gather = np.zeros(n, dtype=np.int64)                   # the node of each unknown
        self._gather[position[single]] = nodes[single]
        shared = ~single
        self._shared = ((nodes[shared], position[shared], np.unique(position[shared]))
                        if shared.any() else None)
        rows, cols = np.maximum(ur, uc), np.minimum(ur, uc)
        if _cholmod is None:
            from scipy.sparse.linalg import splu

            if not _fallback_noted:
                sys.stderr.write("featurewarp: the CHOLMOD binding (featurewarp_cli._cholmod) is not built; "
                                 "using SciPy's sparse LU, which is slower\n")
                _fallback_noted = True
            self.method = "scipy-splu"
            lu = splu(_full_csc(n, rows, cols, val))

            def solve(b, out):
                out[...] = lu.solve(b)

            self._solve = solve
        else:
            self.method = "cholmod"
            # The pattern of P^T L P: for a stencil, fixed by the grid and the numbering.
            key = ((size, nx, _digest(unknown)) if stencil is not None and nx is not None
                   else _digest(rows, cols))
            self._solve = _cholmod_factor(n, rows, cols, val, natural=nx is not None, key=key).solve

    def solve(self, rhs: np.ndarray, offset: np.ndarray) -> np.ndarray:
        """Minimise |A x - b|^2 over x = P z + q.

        Parameters
        ----------
        rhs : (N, k) ndarray
            A^T b for the k coordinates (x and y: k = 2).
        offset : (N, k) ndarray
            q: the position of fixed nodes, the offset of tied nodes, 0 for free ones.

        Returns
        -------
        (N, k) ndarray
            All node positions.
        """
        if self.n_unknowns == 0:
            return offset.copy()
        n = self.n_unknowns
        residual = rhs.T - self.matrix.dot(offset).T                 # (k, N), rows contiguous
        gathered = np.take(residual, self._gather, axis=1)
        if self._shared is not None:
            nodes, position, shared = self._shared
            for j, row in enumerate(residual):
                gathered[j, shared] = np.bincount(position, row[nodes], minlength=n)[shared]
        z = np.zeros((n + 1, residual.shape[0]))
        self._solve(np.ascontiguousarray(gathered.T), z[:n])
        return offset + np.take(z, self._scatter, axis=0)


def _full_csc(n: int, rows: np.ndarray, cols: np.ndarray, vals: np.ndarray):
    """The symmetric n x n matrix with this lower triangle, as SciPy CSC (for splu)."""
    import scipy.sparse as sp

    lower = sp.csc_matrix((vals, (rows, cols)), shape=(n, n))
    lower.sum_duplicates()
    return (lower + sp.tril(lower, -1).T).tocsc()

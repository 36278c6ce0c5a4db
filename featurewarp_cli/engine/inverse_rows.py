"""The least-squares inverse between the nodes the barrier touches, for exact Newton directions.

:func:`barrier.step_direction` solves a Newton system whose barrier touches few nodes exactly,
by the Woodbury identity on those nodes: it needs the inverse of the factored least-squares
system between them, from back-substitutions of unit forces (:class:`InverseRows`).
"""

from __future__ import annotations

import numpy as np

#: The direct solve's nodes at most (:func:`barrier.step_direction`); the rows kept grow to
#: twice that before they start over. The back-substitutions go in chunks of at most
#: CHUNK_BYTES of right-hand sides (a 1 MP grid: 20 columns), so they stay within the memory
#: limit's share per node.
MAX_NODES, CHUNK_BYTES = 600, 2 ** 23
#: Rows of the diagonal blocks :func:`cholesky_solve` substitutes a block at a time.
_BLOCK = 128


def cholesky_solve(lower: np.ndarray, rhs: np.ndarray) -> np.ndarray:
    """x with L L' x = ``rhs`` for the Cholesky factor ``lower`` (n, n), by forward and back
    substitution a block of :data:`_BLOCK` rows at a time (NumPy has no triangular solve, and
    scipy.linalg costs 0.1 s to import): O(n^2), where a general solve factors anew (a
    1 200 x 1 200 system, the machine loaded: 14 ms against 62 ms)."""
    n, x = lower.shape[0], np.array(rhs, dtype=np.float64)
    starts = range(0, n, _BLOCK)
    for i in starts:                                    # L y = rhs
        j = min(i + _BLOCK, n)
        x[i:j] = np.linalg.solve(lower[i:j, i:j], x[i:j] - lower[i:j, :i] @ x[:i])
    for i in reversed(starts):                          # L' x = y
        j = min(i + _BLOCK, n)
        x[i:j] = np.linalg.solve(lower[i:j, i:j].T, x[i:j] - lower[j:, i:j].T @ x[j:])
    return x


class InverseRows:
    """The least-squares inverse S between some nodes (G = P' S P per axis), from
    back-substitutions of unit forces (``inverse(rows, columns)`` -> (2, r, c) entries), kept
    as the barrier's active set grows: S is the factored system's, the same for every
    :func:`barrier.converge` run on it (a release's path of minima passes one instance to each).
    ``unknowns`` ((2, N) int) is the solve's unknown of each node in x and in y (-1 held; the
    nodes of a tied feature share one): it says which nodes' rows of S are zero or the same.
    ``between(axis, ids)`` -> (k, k) sparse: the lower triangle of the reduced system's matrix
    P' H P between the unknowns ``ids`` of that axis (entries of the factored matrix,
    :meth:`solver.ReducedSystem.normal_between`), for the barrier's local preconditioner; None:
    :func:`barrier.step_direction` sums the node-space matrix's rows (:func:`barrier.summed_between`)."""

    def __init__(self, inverse, unknowns: np.ndarray, between=None):
        self.inverse, self.unknowns, self.between = inverse, np.asarray(unknowns), between
        n = self.unknowns.shape[1]
        self.index = np.full(n, -1)
        self.known = np.zeros(0, dtype=np.int64)
        self.block = np.zeros((2, 0, 0))
        self.last = None

    def rows(self, nodes: np.ndarray) -> np.ndarray:
        """(2, u, u): S's entries between ``nodes`` (sorted, unique) for x and for y."""
        new = nodes[self.index[nodes] < 0]
        if self.known.size + new.size > 2 * MAX_NODES:       # the active set moved on: start over
            self.index[self.known] = -1
            self.known, self.block, new = np.zeros(0, dtype=np.int64), np.zeros((2, 0, 0)), nodes
        size = int(np.clip(CHUNK_BYTES // (8 * self.index.size), 1, 256))
        for start in range(0, new.size, size):
            chunk = new[start:start + size]
            known, old = np.concatenate([self.known, chunk]), self.known.size
            columns = self.inverse(known, chunk)                     # (2, k, c)
            grown = np.zeros((2, known.size, known.size))
            grown[:, :old, :old] = self.block
            grown[:, :, old:] = columns
            grown[:, old:, :old] = np.transpose(columns[:, :old], (0, 2, 1))
            self.block, self.known = grown, known
            self.index[chunk] = np.arange(old, known.size)
        at = self.index[nodes]
        return self.block[:, at][:, :, at]

    def factor(self, nodes: np.ndarray) -> np.ndarray:
        """(2u, r) C with C C' = G (interleaved x, y coordinates of ``nodes``); the last one is
        kept for the same nodes. Per axis, G's rows are S's between one node of each unknown
        (positive definite: the inverse of the reduced system, restricted), Cholesky-factored,
        and repeated for the nodes that share the unknown (zero for held nodes).

        Raises
        ------
        numpy.linalg.LinAlgError
            Where rounding left that block not numerically positive definite."""
        key = nodes.tobytes()
        if self.last is None or self.last[0] != key:
            parts = []
            for block, unknown in zip(self.rows(nodes), self.unknowns[:, nodes]):
                ids, first, group = np.unique(unknown, return_index=True, return_inverse=True)
                moving = ids >= 0
                lower = np.linalg.cholesky(block[np.ix_(first[moving], first[moving])])
                part = np.zeros((nodes.size, lower.shape[1]))
                on = unknown >= 0
                part[on] = lower[(np.cumsum(moving) - 1)[group.ravel()[on]]]
                parts.append(part)
            factor = np.zeros((2 * nodes.size, parts[0].shape[1] + parts[1].shape[1]))
            factor[0::2, :parts[0].shape[1]], factor[1::2, parts[0].shape[1]:] = parts
            self.last = (key, factor)
        return self.last[1]

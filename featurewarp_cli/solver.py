"""Sparse Cholesky factorization of the normal equations under a linear reparametrization.

Node positions are written x = P z + q: a node is either fixed (its position is
q), free (its own unknown), or tied to a shared unknown (x = q + t, used to move
a whole feature as one rigid piece whose linear part is already in q). The
reduced matrix P^T L P depends on L and on which node maps to which unknown,
never on q, so one factorization serves every warp.

CHOLMOD (scikit-sparse) when it can be imported; SciPy's sparse LU otherwise,
with one notice on stderr per process.
"""

from __future__ import annotations

import sys

import numpy as np
import scipy.sparse as sp

_fallback_noted = False


def cholmod_available() -> bool:
    """True when scikit-sparse's CHOLMOD can be imported."""
    try:
        import sksparse.cholmod  # noqa: F401
    except ImportError:
        return False
    return True


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
    """

    def __init__(self, matrix: sp.spmatrix, unknown: np.ndarray):
        global _fallback_noted
        unknown = np.asarray(unknown)
        self.n_unknowns = int(unknown.max()) + 1 if unknown.size else 0
        rows = np.flatnonzero(unknown >= 0)
        self.p = sp.csr_matrix((np.ones(rows.size), (rows, unknown[rows])),
                               shape=(unknown.size, self.n_unknowns))
        self.matrix = sp.csr_matrix(matrix)
        self._solve = None
        self.method = "none"
        if self.n_unknowns == 0:
            return
        reduced = (self.p.T @ self.matrix @ self.p).tocsc()
        try:
            from sksparse.cholmod import cholesky
        except ImportError:
            from scipy.sparse.linalg import splu

            if not _fallback_noted:
                sys.stderr.write("featurewarp: scikit-sparse (CHOLMOD) is not installed; "
                                 "using SciPy's sparse LU, which is slower\n")
                _fallback_noted = True
            self.method = "scipy-splu"
            self._solve = splu(reduced).solve
        else:
            self.method = "cholmod"
            self._solve = cholesky(reduced)

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
        reduced = self.p.T @ (rhs - self.matrix @ offset)
        z = self._solve(np.ascontiguousarray(reduced))
        return self.p @ z + offset

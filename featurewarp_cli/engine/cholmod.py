"""CHOLMOD (SuiteSparse's sparse Cholesky) through scikit-sparse: every call to it is here.

The rest of the package asks this module for three things: a symbolic analysis
of a pattern (:func:`analyze`), a numeric factorization of a matrix with that
pattern (:func:`factorize`), and solves (:func:`solve`). Matrices are
``scipy.sparse`` CSC matrices holding the lower triangle of a symmetric positive
definite matrix (CHOLMOD reads the lower triangle only; 32-bit indices, which
CHOLMOD factors faster than 64-bit ones).

:data:`AVAILABLE` is False when scikit-sparse cannot be imported; the solver
then uses SciPy instead (:mod:`featurewarp_cli.engine.solver`).

Version
-------
Pinned to scikit-sparse 0.4.16, the last release that builds against the
SuiteSparse 5 of Debian 12 (``libsuitesparse-dev``). scikit-sparse 0.5 needs
SuiteSparse >= 7.4 and rewrote this interface (scikit-sparse pull request 148):
``Factor`` became ``CholeskyFactor`` (made by ``cho_factor``), ``Common`` is
gone, solves are ``factor.solve(b, system=...)``, the permutation is
``factor.perm``. Moving to it means a newer SuiteSparse (a newer distribution or a
source build), the new pin, and rewriting the four functions below and the
error mapping, keeping their contracts (tests/test_cholmod.py checks them).
Check first how 0.5 reuses a symbolic analysis for new values and how it
selects the natural ordering and the simplicial/supernodal method: the speed
of a warp depends on both.
"""

from __future__ import annotations

import ctypes
import os
from contextlib import contextmanager

import numpy as np

try:
    from sksparse import cholmod as _sksparse
except ImportError:              # the solver falls back to SciPy (one notice)
    _sksparse = None

#: True when scikit-sparse (and so CHOLMOD) can be used.
AVAILABLE = _sksparse is not None
#: The OpenMP runtime CHOLMOD loaded (ctypes library), False when there is none; None: not looked up yet.
_openmp = None


class NotPositiveDefinite(ArithmeticError):
    """The matrix handed to :func:`factorize` is not positive definite."""


#: Orderings :func:`analyze` accepts: ``natural`` keeps the given order (the caller has
#: permuted the matrix); ``default`` is CHOLMOD's choice (AMD, or METIS when AMD fills
#: much); the others force one method.
ORDERINGS = ("natural", "default", "amd", "metis", "nesdis")


def analyze(lower, ordering: str = "default", supernodal: bool = False):
    """Symbolic analysis (ordering, elimination tree, structure of L) of a pattern.

    Parameters
    ----------
    lower : (n, n) scipy.sparse CSC matrix
        Lower triangle of the symmetric matrix; only its pattern is read.
    ordering : str
        One of :data:`ORDERINGS`.
    supernodal : bool
        CHOLMOD's supernodal method (dense blocks through the BLAS), else the
        simplicial one.

    Returns
    -------
    object
        An analysis for :func:`factorize`; it stays symbolic, so it serves every
        matrix with the same pattern.
    """
    if ordering not in ORDERINGS:
        raise ValueError(f"ordering must be one of {', '.join(ORDERINGS)}, not {ordering!r}")
    return _sksparse.analyze(lower, mode="supernodal" if supernodal else "simplicial", ordering_method=ordering)


def factorize(analysis, lower, simplicial: bool = False):
    """Numeric factorization of ``lower`` (same pattern as the analysed matrix).

    The analysis is copied first (its symbolic part only: cheap), so that it stays
    symbolic and earlier factors stay valid; the copy is factored in place. With
    ``simplicial`` (an analysis for the simplicial method), the LDL' factor's pivots are
    checked: CHOLMOD's simplicial method factors an indefinite matrix without complaint
    (D = [2, -3.5, 16/7] for [[2, 1, 0], [1, -3, 1], [0, 1, 2]]), the supernodal one raises.

    Returns
    -------
    object
        A factor for :func:`solve`.

    Raises
    ------
    NotPositiveDefinite
    """
    factor = analysis.copy()
    try:
        with _openmp_off():
            factor.cholesky_inplace(lower)
    except _sksparse.CholmodNotPositiveDefiniteError as error:
        raise NotPositiveDefinite(f"the matrix is not positive definite ({error})") from None
    if simplicial and not factor.D().min(initial=1.0) > 0:
        raise NotPositiveDefinite("the matrix is not positive definite (a pivot of its LDL' factor is not positive)")
    return factor


def solve(factor, b: np.ndarray) -> np.ndarray:
    """x with A x = b for a factor of A; ``b`` (n,) or (n, k) ndarray (an F-ordered
    float64 array is used without a copy). Returns a new array of b's shape."""
    return factor.solve_A(b)


def factor_nnz(factor) -> int:
    """Entries of L (its lower triangle with the diagonal) in a numeric factor."""
    return int(factor.L().nnz)


def _openmp_runtime():
    """The OpenMP runtime already loaded in this process (by CHOLMOD), as a ctypes library, or None."""
    global _openmp
    if _openmp is None:
        _openmp = False
        mode = getattr(os, "RTLD_NOLOAD", None)
        for name in ("libgomp.so.1", "libomp.so", "libomp.so.5") if mode is not None else ():
            try:
                _openmp = ctypes.CDLL(name, mode=mode)          # only when already loaded
                break
            except OSError:
                continue
    return _openmp or None


@contextmanager
def _openmp_off():
    """Run the OpenMP loops started from this thread (CHOLMOD's) on one thread.

    Debian's CHOLMOD runs the assembly loops of its supernodal factorization in
    OpenMP teams of 4 threads (several small parallel regions per supernode); on
    2 cores their start-up and barriers cost more than the loops. Grid systems,
    grid ordering, medians of 9 interleaved runs (load about 2.5): 191 k unknowns
    0.207 -> 0.153 s, 772 k unknowns 0.90 -> 0.67 s (the BLAS keeps its threads:
    one BLAS thread gave 0.150 and 0.655 s, no clear gain). libgomp keeps the
    setting per thread, so factorizations in other threads are not affected.
    """
    omp = _openmp_runtime()
    if omp is None:
        yield
        return
    levels = omp.omp_get_max_active_levels()
    omp.omp_set_max_active_levels(0)
    try:
        yield
    finally:
        omp.omp_set_max_active_levels(levels)

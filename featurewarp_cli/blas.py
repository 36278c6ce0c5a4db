"""The command line runs OpenBLAS with one thread (unless ``OPENBLAS_NUM_THREADS`` says otherwise).

OpenBLAS starts as many threads as the host has cores, and they spin while they wait for
work. On a machine whose cores are busy (a shared server, ``batch`` with several workers,
``make test`` with two), a dense factorization of a few hundred unknowns, as the fold
guard's Newton steps make, then takes a hundred times longer: on this 2-core machine with
one other process running, numpy's Cholesky of a 500 x 500 matrix took 250 ms with two
threads and 2.5 ms with one, and the astronaut's 1 MP ``squeeze`` (head, patch and shuttle
masked) 5.5 s against 1.0 s. The thread count also changes the last bits of those products
(meshes 1e-8 px apart), so a default that followed the host's cores would let the machine
decide them.

Only the first import of numpy, SciPy or scikit-sparse reads the variable: :func:`one_thread`
must run before them (the command's entry point, the test suite's conftest and the
benchmarks do).
"""

from __future__ import annotations

import os

#: OpenBLAS threads of a command, a test run and a benchmark.
THREADS = "1"


def one_thread() -> None:
    """Set ``OPENBLAS_NUM_THREADS`` to :data:`THREADS` where the environment does not set it."""
    os.environ.setdefault("OPENBLAS_NUM_THREADS", THREADS)

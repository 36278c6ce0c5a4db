"""Running a batch's jobs on a Dask cluster (``featurewarp batch ... --scheduler ADDRESS``).

Dask (``dask.distributed``) is an optional extra: ``pip install 'featurewarp[dask]'``.
Each job is one call of :func:`featurewarp_cli.app.batch.timed_job` on a worker, exactly as
the local batch runs it, so the outputs are the same bytes. Inputs, masks and the output
folder must be paths that every worker sees (a shared file system) or fsspec URLs
(:mod:`featurewarp_cli.app.remote`); the workers need featurewarp installed in the same version.

What the cluster gives beyond ``--jobs``: workers on other machines (started by
dask-jobqueue on Slurm or PBS, by dask-kubernetes, or by hand with ``dask scheduler`` and
``dask worker``), and a job whose worker dies is run again on another one by the
scheduler (up to ``distributed.scheduler.allowed-failures`` times, 3 by default). Outputs
stay all-or-nothing: each is written to an unnamed temporary file and linked into place
only when complete, so a worker killed mid-job leaves nothing behind.
"""

from __future__ import annotations

import os
import threading
import time
from typing import Iterator

from .pipeline import WarpError

#: ``--scheduler local:N`` starts a local cluster of N single-threaded worker processes.
LOCAL_PREFIX = "local:"
#: Dask settings of the workers ``local:N`` starts: no statistical profiler sampling the
#: solve's thread every 10 ms (it holds the GIL; a few % of a batch). Workers started by
#: hand take the same from ``DASK_DISTRIBUTED__WORKER__PROFILE__ENABLED=False``.
WORKER_CONFIG = {"distributed.worker.profile.enabled": False}
#: Seconds to wait for a scheduler to answer.
CONNECT_TIMEOUT = 20


def _distributed():
    """The ``distributed`` module, or a WarpError that says how to install it."""
    try:
        import distributed
    except ImportError:
        raise WarpError("needs Dask: pip install 'featurewarp[dask]' (dask.distributed)", "--scheduler",
                        usage=True) from None
    return distributed


def local_workers(scheduler: str) -> int:
    """N of ``local:N``: the processes on this machine that share its memory (0 when N is not
    a whole number); 1 for any other scheduler (its workers have machines of their own)."""
    if not scheduler.startswith(LOCAL_PREFIX):
        return 1
    count = scheduler[len(LOCAL_PREFIX):]
    return int(count) if count.isdigit() else 0


def connect(scheduler: str):
    """A ``distributed.Client`` for ``scheduler`` and the cluster it started (or None).

    Parameters
    ----------
    scheduler : str
        ``tcp://host:port`` (or any address Dask takes), a scheduler file (``.json``, as
        ``dask scheduler --scheduler-file`` writes it), or ``local:N``.

    Returns
    -------
    (distributed.Client, distributed.LocalCluster or None)

    Raises
    ------
    WarpError
        Dask missing, a bad ``local:N``, or a scheduler that cannot be reached.
    """
    distributed = _distributed()
    if scheduler.startswith(LOCAL_PREFIX):
        count = local_workers(scheduler)
        if not 1 <= count <= 1024:
            raise WarpError(f"{scheduler!r}: local:N takes a number of workers from 1 to 1024", "--scheduler",
                            usage=True)
        import dask

        with dask.config.set(WORKER_CONFIG):
            cluster = distributed.LocalCluster(n_workers=count, threads_per_worker=1, processes=True,
                                               dashboard_address=None)
        return distributed.Client(cluster), cluster
    try:
        if scheduler.endswith(".json"):
            if not os.path.isfile(scheduler):
                raise WarpError(f"{scheduler}: no such scheduler file", "--scheduler", usage=True)
            return distributed.Client(scheduler_file=scheduler, timeout=CONNECT_TIMEOUT), None
        return distributed.Client(scheduler, timeout=CONNECT_TIMEOUT), None
    except WarpError:
        raise
    except (OSError, TimeoutError, ValueError) as err:
        raise WarpError(f"cannot reach the Dask scheduler at {scheduler} ({err})", "--scheduler") from None


#: glibc's mallopt parameters, and the values a worker sets (see :func:`cluster_job`).
_M_TRIM_THRESHOLD, _M_MMAP_THRESHOLD = -1, -3
_TRIM_BYTES, _MMAP_BYTES = 256 << 20, 64 << 20
_malloc_tuned = False
#: A worker started with several threads runs one job at a time: the decoders' stderr is
#: captured per process (a truncated JPEG's warning must reach its own job).
_ONE_AT_A_TIME = threading.Lock()


def cluster_job(settings, job):
    """:func:`featurewarp_cli.app.batch.timed_job` on a Dask worker.

    Dask's nanny starts workers with ``MALLOC_TRIM_THRESHOLD_=65536``, which also turns
    off glibc's adaptive mmap threshold: every large array is then a fresh mmap with its
    page faults, and a 1 MP warp took 1.1 s instead of 0.5 s (cProfile: numpy's take and
    sparse products 2-5 times slower, most of the time in the kernel). The first job on a
    worker sets fixed thresholds instead (arrays up to 64 MiB from the heap, trimmed above
    256 MiB), as the local batch's processes get by default. Jobs run one at a time per worker
    process, and OpenCV's decoders get ``--max-pixels`` when this worker has not imported them.

    Parameters
    ----------
    settings : Settings
    job : Job

    Returns
    -------
    (str or None, dict or None, float)
        As :func:`featurewarp_cli.app.batch.timed_job`.
    """
    global _malloc_tuned
    from ..io import limits
    from .batch import timed_job

    limits.limit_opencv_decoders(settings.max_pixels)   # before this worker first imports cv2
    if not _malloc_tuned:
        _malloc_tuned = True
        try:
            import ctypes

            libc = ctypes.CDLL("libc.so.6")
            libc.mallopt(_M_MMAP_THRESHOLD, _MMAP_BYTES)
            libc.mallopt(_M_TRIM_THRESHOLD, _TRIM_BYTES)
        except (OSError, AttributeError):
            pass                                    # not glibc: nothing to undo
    with _ONE_AT_A_TIME:                            # stderr capture is per process: one job at a time
        return timed_job(settings, job)


def run_on_cluster(settings, jobs: list, scheduler: str) -> Iterator[tuple]:
    """Run ``jobs`` on the cluster; yield (index, job, error, summary, seconds) as they finish.

    A job whose workers died too often (Dask's ``KilledWorker``) or that the cluster could
    not run is reported as failed with the reason; the others go on.

    Parameters
    ----------
    settings : Settings
    jobs : list of Job
    scheduler : str
        As :func:`connect`.

    Yields
    ------
    (int, Job, str or None, dict or None, float)
    """
    distributed = _distributed()
    client, cluster = connect(scheduler)
    try:
        futures = client.map(cluster_job, [settings] * len(jobs), jobs, pure=False,
                             key=[f"featurewarp-job-{i}-{os.getpid()}-{time.monotonic_ns()}"
                                  for i in range(len(jobs))])
        index = {future.key: i for i, future in enumerate(futures)}
        for future in distributed.as_completed(futures):
            i = index[future.key]
            try:
                error, summary, seconds = future.result()
            except distributed.KilledWorker:
                error, summary, seconds = "the Dask workers running it died (KilledWorker)", None, 0.0
            except Exception as err:                      # the cluster's failure, not the job's
                error, summary, seconds = f"{type(err).__name__}: {err}", None, 0.0
            yield i, jobs[i], error, summary, seconds
    finally:
        client.close()
        if cluster is not None:
            cluster.close()

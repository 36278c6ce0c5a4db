"""A batch's job on a Dask worker (``featurewarp batch ... --scheduler ADDRESS``).

Dask (``dask.distributed``) is an optional extra: ``pip install 'featurewarp[dask]'``.
Each job is one call of :func:`featurewarp_cli.app.batch.timed_job` on a worker, exactly as
the local batch runs it, so the outputs are the same bytes. Inputs, masks and the output
folder must be paths that every worker sees (a shared file system; the command sends them
absolute) or fsspec URLs (:mod:`featurewarp_cli.app.remote`); the workers need featurewarp
installed in the same version. The command's side (connecting, sending, results, stopping)
is :mod:`featurewarp_cli.app.cluster_run`; the scheduler it names,
:mod:`featurewarp_cli.app.scheduler`.

What the cluster gives beyond ``--jobs``: workers on other machines (started by
dask-jobqueue on Slurm or PBS, by dask-kubernetes, or by hand with ``dask scheduler`` and
``dask worker``), and a job whose worker dies is run again on another one by the
scheduler (up to ``distributed.scheduler.allowed-failures`` times, 3 by default). Outputs
stay all-or-nothing: each is written to an unnamed temporary file and linked into place
only when complete, so a worker killed mid-job leaves nothing behind.

No output of a run may appear after its command has exited. A job checks at its write stage
(:func:`_write_gate`) that its run goes on, its task was not cancelled (its client went away)
and its worker is not closing (its scheduler was lost); if not, it writes nothing. A run is
stopped on the scheduler, by its flag there (a ``distributed.Event`` named :func:`stop_flag`),
which every job asks for right before it writes: a worker that joins after the stop, or that
the command's :func:`stop_run` did not reach, writes nothing either. :func:`stop_run` also
tells each worker at once (a refusal there costs no round-trip) and says whether a job of the
run is writing there: the command waits until none is.
"""

from __future__ import annotations

import contextlib
import threading

from .. import stages

#: glibc's mallopt parameters, and the values a worker sets (see :func:`cluster_job`).
_M_TRIM_THRESHOLD, _M_MMAP_THRESHOLD = -1, -3
_TRIM_BYTES, _MMAP_BYTES = 256 << 20, 64 << 20
_malloc_tuned = False
#: A worker started with several threads runs one job at a time: the decoders' stderr is
#: captured per process (a truncated JPEG's warning must reach its own job).
_ONE_AT_A_TIME = threading.Lock()
#: On a worker, under _GATE: the runs told to stop, and per run the job that last reached its
#: write stage here ([task key, whether it is writing]): jobs run one at a time per worker
#: process, so that job is the only one of the run that may have written a file the command has
#: not heard of yet. Both keep the last RUNS_KEPT runs.
_GATE = threading.Lock()
_STOPPED: dict[str, None] = {}
_LAST_WRITER: dict[str, list] = {}
RUNS_KEPT = 1000
#: Seconds a job waits for the scheduler's answer to "is the run stopped?" at its write stage.
FLAG_TIMEOUT = 20.0


class RunStopped(Exception):
    """Raised at a job's write stage when its run is over: the job writes nothing."""


class NotWritten(str):
    """The error of a job that refused to write because its run was stopped: not a failure of
    its file. The stopping command leaves it out of its messages and its summary, as a job
    that never ran (``--resume`` runs it)."""


def _worker():
    """The Dask worker running this thread's task, or None."""
    try:
        from distributed import get_worker

        return get_worker()
    except (ImportError, ValueError):
        return None


def _may_write(run_id: str, worker) -> bool:
    """On a worker, in a job's thread: whether the job may still write its output."""
    if run_id in _STOPPED:
        return False
    if worker is None:
        return True
    if worker.status.name in ("closing", "closing_gracefully", "closed", "failed"):
        return False                                  # its scheduler was lost, or it is shut down
    task = worker.state.tasks.get(worker.get_current_task())
    return task is not None and task.state != "cancelled"


def _remember(runs: dict, run_id: str, value) -> None:
    """``runs[run_id] = value``, as the newest entry, the oldest beyond RUNS_KEPT forgotten."""
    runs.pop(run_id, None)
    runs[run_id] = value
    while len(runs) > RUNS_KEPT:
        del runs[next(iter(runs))]


def stop_flag(run_id: str) -> str:
    """The name of run ``run_id``'s stop flag on the scheduler (a ``distributed.Event``)."""
    return f"{run_id}-stopped"


def _flag_is_set(run_id: str, worker) -> bool:
    """On a worker, in a job's thread: whether run ``run_id`` is stopped on the scheduler (one
    round-trip on the worker's own connection; no client is made: a median 0.3-0.4 ms per file
    on a local cluster of 2 processes, where a 96x72 file takes about 27 ms).

    When the scheduler does not answer (within FLAG_TIMEOUT s, or with an error), the job fails
    with a WarpError that says so and writes nothing. Writing anyway could put a file in place
    after its command has exited and said it stopped, which no one would hear of: the very case
    the flag exists for. Nor is it a refusal of everything for good: each job asks again, and a
    scheduler that answers again lets the next ones write. A scheduler that is gone loses the
    command too, which then reports the files not written as "not finished" (``--resume`` runs
    them).
    """
    from distributed.utils import sync

    try:
        return bool(sync(worker.loop, worker.scheduler.event_is_set, name=stop_flag(run_id),
                         callback_timeout=FLAG_TIMEOUT))
    except Exception as err:
        from .pipeline import WarpError

        reason = str(err).strip().splitlines()
        raise WarpError(f"not written: the Dask scheduler did not answer whether the batch goes on "
                        f"({type(err).__name__}{': ' + reason[0] if reason else ''})") from None


@contextlib.contextmanager
def _write_gate(run_id: str | None):
    """While the block runs a job of ``run_id``: its write stage raises :class:`RunStopped` when the
    job may not write, and marks it as writing (until the block ends) when it may. The block
    gets a list, not empty once the write was refused so.

    The job is marked as writing before it asks the scheduler's flag, not after: a command that
    sets the flag, then asks the workers (:func:`stop_run`), hears of every job that found the
    flag not set. The question is asked outside ``_GATE``: :func:`stop_run` runs on the
    worker's event loop, which answers it."""
    entry, refused = [], []

    def at_stage(name: str) -> None:
        if name != "write" or entry:
            return
        worker = _worker()
        with _GATE:
            if not _may_write(run_id, worker):
                if run_id in _STOPPED:              # not a worker closing nor a task cancelled
                    refused.append(True)
                raise RunStopped("the batch was stopped before this file was written")
            entry.extend([worker.get_current_task() if worker else None, True])
            _remember(_LAST_WRITER, run_id, entry)
        if worker is None:
            return
        stopped = True
        try:
            stopped = _flag_is_set(run_id, worker)
        finally:
            if stopped:                             # stopped, or no answer: this job writes nothing
                with _GATE:
                    entry[1] = False
        if stopped:
            with _GATE:
                _remember(_STOPPED, run_id, None)   # the run's next jobs here refuse without asking
            refused.append(True)
            raise RunStopped("the batch was stopped before this file was written")

    if run_id is None:
        yield refused
        return
    stages.listen(at_stage)
    try:
        yield refused
    finally:
        stages.forget(at_stage)
        with _GATE:
            if entry:
                entry[1] = False


def stop_run(run_id: str):
    """On a worker (through ``Client.run``): no job of run ``run_id`` starts writing here from now
    on, without asking the scheduler's flag (which the command sets first, for every worker).

    Returns
    -------
    (key, bool) or None
        The task key of the run's job that last reached its write stage on this worker and
        whether it is writing now: the command waits until it is not, then for its result.
    """
    with _GATE:
        _remember(_STOPPED, run_id, None)
        entry = _LAST_WRITER.get(run_id)
        return (entry[0], entry[1]) if entry else None


def cluster_job(settings, job, run_id: str | None = None):
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
    run_id : str, optional
        The batch run the job belongs to: it writes nothing once the run is stopped
        (:func:`stop_run`), its task cancelled or its worker closing.

    Returns
    -------
    (str or None, dict or None, float)
        As :func:`featurewarp_cli.app.batch.timed_job`; the error a :class:`NotWritten` when the
        job refused to write because its run was stopped.
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
    with _ONE_AT_A_TIME, _write_gate(run_id) as refused:   # stderr capture is per process: one job at a time
        error, summary, seconds = timed_job(settings, job)
    return (NotWritten(error) if refused else error), summary, seconds

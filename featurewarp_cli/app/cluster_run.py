"""A batch run on a Dask cluster, as the command sees it: the jobs sent, their results as they
finish, and the run stopped so that nothing of it is written after the command exits.

:class:`ClusterRun` connects (:mod:`featurewarp_cli.app.scheduler`: every problem with
``--scheduler`` is one line before anything is written), warns about workers that run
another featurewarp version, sends each job as :func:`featurewarp_cli.app.cluster.cluster_job`
and yields the results in the order they finish. Its jobs get absolute paths (a worker
resolves a relative one against its own working folder); messages and summaries name the
files as the user did.

How a run ends early, and what the command says:

- SIGINT or SIGTERM: :class:`Stopped` where the run waits for the cluster; the results that
  had arrived are still yielded (so in ``--summary``), then the command exits 130 or 143.
- the command's own error (a ``--summary`` that cannot be written): :meth:`ClusterRun.close`.
- the scheduler lost: the files not finished are yielded as failed (an :class:`Unfinished`
  error; those found written since the run began as ok), then one error line.

Each way, the run's stop flag is set on the scheduler (no job of it starts writing, on any
worker, one that joins later too; :mod:`featurewarp_cli.app.cluster`), the jobs not writing
are cancelled, and the command waits while a worker says it is writing a file of the run
(:func:`featurewarp_cli.app.cluster.stop_run`), up to WRITE_WAIT s: a file still being written
then is named in a warning, as one that may still appear.
"""

from __future__ import annotations

import contextlib
import logging
import os
import signal
import threading
import time
from collections.abc import Iterator

from .. import __version__, stages
from .cluster import NotWritten, cluster_job, stop_flag, stop_run
from .pipeline import WarpError
from .scheduler import connect, distributed_module, resolve

#: Seconds the command waits, when it stops a run, for the results of the jobs that wrote, and
#: for each call to the cluster (a lost scheduler must not keep it waiting).
STOP_WAIT, STOP_CALL = 10.0, 3.0
#: Seconds it waits while a worker says it is writing a file of the run (a large file on a slow
#: shared file system), and after which it says what it waits for.
WRITE_WAIT, WRITE_NOTICE = 120.0, 3.0
#: Seconds given, once the scheduler is lost, to the writes its workers had begun (they write
#: nothing new: a worker that lost its scheduler closes), before the outputs are looked at.
LOST_GRACE = 2.0
LOST = "not finished: the connection to the Dask scheduler was lost"


class Stopped(BaseException):
    """SIGINT or SIGTERM during a cluster run, raised where the run waits for the cluster (the
    command stops the jobs, records what finished, then exits with 128 + ``signum``)."""

    def __init__(self, signum: int):
        super().__init__(signum)
        self.signum = signum


class Unfinished(str):
    """The error of a job whose result was lost with the scheduler (said once, not per file)."""


class _SchedulerLost(Exception):
    """The client lost its scheduler: the results not yet in will not come."""


def _reporting(function):
    """``function`` wrapped to return the worker's featurewarp version and address with its result.

    Built here, not at module level, so that Dask sends the wrapper by value: a worker with another
    featurewarp runs it as it is (``function`` itself is sent by name)."""
    def on_worker(*args):
        import featurewarp_cli
        from distributed import get_worker

        return getattr(featurewarp_cli, "__version__", None), get_worker().address, function(*args)

    return on_worker


def _version_probe():
    """A function (sent by value) that gives a worker's featurewarp version, None without one."""
    def featurewarp_version():
        try:
            import featurewarp_cli
        except ImportError:
            return None
        return getattr(featurewarp_cli, "__version__", "unknown")

    return featurewarp_version


def _bounded(call, seconds: float):
    """``call()``'s result, or None when it fails or takes more than ``seconds`` (a lost scheduler
    must not keep a stopping command waiting)."""
    outcome = []

    def run():
        with contextlib.suppress(Exception):
            outcome.append(call())

    worker = threading.Thread(target=run, name="featurewarp-stop", daemon=True)
    worker.start()
    worker.join(seconds)
    return outcome[0] if outcome else None


@contextlib.contextmanager
def _dask_logs_silenced(verbose: bool):
    """Dask's log lines (a worker lost, a heartbeat that failed at shutdown) kept off stderr unless
    ``verbose``: the command's own one-line messages say what matters."""
    handlers = [] if verbose else [handler for name in ("distributed", "tornado", "bokeh")
                                   for handler in logging.getLogger(name).handlers
                                   if isinstance(handler, logging.StreamHandler)]
    levels = [handler.level for handler in handlers]
    for handler in handlers:
        handler.setLevel(logging.CRITICAL + 1)
    try:
        yield
    finally:
        for handler, level in zip(handlers, levels):
            handler.setLevel(level)


class _Signals:
    """SIGINT and SIGTERM during a cluster run: :class:`Stopped` is raised where the run waits for
    the cluster, or at its next wait when the signal comes in between; a second signal goes to
    the handler installed before (the command's: exit at once)."""

    def __init__(self):
        self.signum, self.waiting, self.previous = None, False, {}

    @contextlib.contextmanager
    def installed(self):
        if threading.current_thread() is not threading.main_thread():
            yield
            return
        for signum in (signal.SIGINT, signal.SIGTERM):
            self.previous[signum] = signal.signal(signum, self._handle)
        try:
            yield
        finally:
            for signum, handler in self.previous.items():
                signal.signal(signum, handler)

    def _handle(self, signum, frame) -> None:
        if self.signum is not None:
            previous = self.previous.get(signum)
            if callable(previous):
                previous(signum, frame)
            elif previous == signal.SIG_DFL:          # the default action: die of the signal
                signal.signal(signum, signal.SIG_DFL)
                os.kill(os.getpid(), signum)
            return
        self.signum = signum
        if self.waiting:
            raise Stopped(signum)

    @contextlib.contextmanager
    def wait(self):
        """The block waits for the cluster: a signal stops it."""
        self.waiting = True
        try:
            if self.signum is not None:
                raise Stopped(self.signum)
            yield
        finally:
            self.waiting = False

    def each(self, items: Iterator):
        """``items``, each waited for in :meth:`wait`."""
        while True:
            with self.wait():
                item = next(items, None)
            if item is None:
                return
            yield item


def _renamed(outcome: tuple, job, sent) -> tuple:
    """(error, summary, seconds) of the job ``sent`` with its paths named as in ``job``."""
    from .remote import named

    paths = {user: given for user, given in zip((job.input, job.mask, job.output, os.path.dirname(job.output)),
                                                (sent.input, sent.mask, sent.output, os.path.dirname(sent.output)))
             if user and user != given}             # the folder: a worker that cannot write it names it
    if not paths:
        return outcome
    error, summary, seconds = outcome
    paths = dict(sorted(paths.items(), key=lambda item: -len(item[1])))      # /a/x.png.mask before /a/x.png
    return named(error, paths), named(summary, paths), seconds


def _clocks(jobs: list) -> dict:
    """Each local output folder's time now, by its file system's clock (a file made and removed
    there): an output whose modification time is not earlier was written by this run. One file
    per folder, not a look at every output (a slow shared file system, 100 000 files)."""
    import tempfile

    from ..io import urls

    clocks = {}
    for folder in {os.path.dirname(job.output) for job in jobs if not urls.is_url(job.output)}:
        with contextlib.suppress(OSError), tempfile.TemporaryFile(dir=folder or ".") as probe:
            clocks[folder] = os.fstat(probe.fileno()).st_mtime_ns
    return clocks


def _in_place(job, clocks: dict) -> bool:
    """Whether ``job``'s local output was written since its folder's time in ``clocks`` (the
    run's start) and is up to date for its input."""
    from .batch import up_to_date

    started = clocks.get(os.path.dirname(job.output))
    try:
        written = started is not None and os.stat(job.output).st_mtime_ns >= started
    except OSError:
        return False
    return written and up_to_date(job)


class ClusterRun:
    """A batch's jobs on a Dask cluster: iterate for (index, job, error, summary, seconds) as they
    finish; :meth:`close` stops the jobs not finished.

    Parameters
    ----------
    settings : Settings
    jobs : list of Job
        As the user named the files (the results name them so).
    scheduler : str
        ``--scheduler`` (see :func:`featurewarp_cli.app.scheduler.resolve`).
    sent : list of Job
        ``jobs`` as the workers get them (absolute paths).
    verbose : bool
        Let Dask's log lines through.

    Raises
    ------
    WarpError
        ``--scheduler`` names no scheduler, or it cannot be reached (all before a job is sent).
    """

    def __init__(self, settings, jobs: list, scheduler: str, sent: list, verbose: bool = False):
        self.target, self.jobs = resolve(scheduler), jobs
        self._logs = contextlib.ExitStack()
        self._logs.enter_context(_dask_logs_silenced(verbose))
        self.futures, self.run_id, self.stopped, self.signals = [], None, False, _Signals()
        self.unfinished: set[int] = set()
        self.warned: set[str] = set()
        self.made_by: dict = {}                     # task key -> the featurewarp version of the worker that ran it
        self.client = self.cluster = None
        try:
            self.client, self.cluster = connect(self.target, verbose)
            found = self.client.run(_version_probe(), on_error="return")
            self._warn_versions({address: version if isinstance(version, (str, type(None))) else None
                                 for address, version in found.items()})
        except BaseException:
            self._disconnect()
            raise
        self._results = self._run(settings, jobs, sent)

    def __iter__(self):
        return self

    def __next__(self):
        return next(self._results)

    def version_of(self, i: int) -> str | None:
        """The featurewarp version of the worker that ran job ``i``: None where it is this command's
        or not known with every worker on it; ``unknown`` for a file found on disk after a stop
        (its result never came back) while a worker of another version was seen, so that its
        --summary stamp matches no settings and --resume warps it again."""
        made = self.made_by.get(self.futures[i].key) if i < len(self.futures) else None
        return made if made is not None or not self.warned else "unknown"

    def close(self) -> None:
        """Stop the jobs not finished (none writes after this returns) and disconnect."""
        try:
            self._results.close()
        finally:
            self._disconnect()

    def _disconnect(self) -> None:
        if self.signals.signum is not None:
            return          # exiting at once: the signal handler kills a local cluster, Dask's logs stay off
        client, cluster, self.client, self.cluster = self.client, self.cluster, None, None
        if client is not None:
            _bounded(lambda: client.close(timeout=STOP_CALL), STOP_CALL + 1)
        if cluster is not None:
            _bounded(lambda: cluster.close(timeout=STOP_CALL), STOP_CALL + 1)
        self._logs.close()

    def _run(self, settings, jobs: list, sent: list):
        distributed = distributed_module()
        self.run_id = f"featurewarp-{os.getpid()}-{time.monotonic_ns()}"
        with self.signals.installed():      # before the jobs go: a signal meanwhile stops them at the first wait
            clocks = _clocks(jobs)
            self.futures = self.client.map(_reporting(cluster_job), [settings] * len(sent), sent,
                                           [self.run_id] * len(sent), pure=False,
                                           key=[f"{self.run_id}-job-{i}" for i in range(len(sent))])
            index = {future.key: i for i, future in enumerate(self.futures)}
            self.unfinished = set(range(len(jobs)))
            try:
                for future in self.signals.each(distributed.as_completed(self.futures, loop=self.client.loop)):
                    i = index[future.key]
                    with self.signals.wait():
                        outcome = _renamed(self._outcome(future), jobs[i], sent[i])
                    self.unfinished.discard(i)
                    yield (i, jobs[i], *outcome)
            except Stopped:
                self._stop()
                yield from self._arrived(jobs, sent, index)
                yield from self._on_disk(jobs, clocks)
                raise
            except _SchedulerLost:
                yield from self._lost(jobs, clocks)
                raise WarpError(f"lost the connection to the Dask scheduler at {self.target.value}: "
                                f"{self.lost} of {len(jobs)} files not finished (failed in --summary; "
                                "--resume runs them)") from None
            finally:
                if self.unfinished:
                    self._stop()

    def _outcome(self, future) -> tuple:
        """(error, summary, seconds) of a finished future: the job's, or the cluster's failure to run
        it (one line); the scheduler lost is :class:`_SchedulerLost`."""
        distributed = distributed_module()
        try:
            version, address, (error, summary, seconds) = future.result()
        except distributed.KilledWorker:
            return "the Dask workers running it died (KilledWorker)", None, 0.0
        except Exception as err:                      # the cluster's failure, not the job's
            if getattr(err, "reason", None) == "scheduler-connection-lost" or self.client.status != "running":
                raise _SchedulerLost() from None
            if isinstance(err, ImportError):
                return (f"a Dask worker cannot run featurewarp ({err}): install featurewarp {__version__} on "
                        "every worker"), None, 0.0
            text = str(err).strip().splitlines()
            return f"the Dask cluster could not run it ({type(err).__name__}: {text[0] if text else ''})", None, 0.0
        self._warn_versions({address: version})
        self.made_by[future.key] = version
        return error, summary, seconds

    def _warn_versions(self, found: dict) -> None:
        """One warning for the workers, not yet named, whose featurewarp is not this command's."""
        other = {address: version for address, version in found.items()
                 if version != __version__ and address not in self.warned}
        if not other:
            return
        self.warned.update(other)
        listed = [f"{address} ({'no featurewarp' if version is None else version})" for address, version in other.items()]
        stages.notice(f"warning: {len(other)} Dask worker(s) run another featurewarp than this command's {__version__}, "
                      f"and may write other bytes: {', '.join(listed[:3])}{', ...' if len(listed) > 3 else ''}")

    def _stop(self) -> None:
        """Stop the run's jobs: its flag set on the scheduler (none starts writing, on any worker,
        present or to come), the jobs that had not written cancelled, those writing waited for
        (:meth:`_writes_waited`), then the results of those that wrote (up to STOP_WAIT s), then
        the rest cancelled. A warning names the files still being written then, or says that
        the cluster did not answer in time (STOP_CALL s). The flag stays on the scheduler (an
        entry of a few hundred bytes per stopped run): a task of the run a worker still runs,
        cancelled or not, finds it."""
        if self.stopped or self.client is None:
            return
        self.stopped = True
        client, distributed = self.client, distributed_module()
        flagged = _bounded(lambda: distributed.Event(stop_flag(self.run_id), client=client).set() or True, STOP_CALL)
        answer = self._writers()
        if not (flagged and answer):
            stages.notice("warning: the Dask cluster did not answer the stop in time: a file of the batch being "
                          "written may still appear")
        written, writing = answer or (set(), set())
        self._cancel(lambda future: future.key not in written)          # they will write nothing
        still = self._writes_waited(written, writing)
        waited = [future for future in self.futures if future.key in written - still]
        deadline = time.monotonic() + STOP_WAIT
        while time.monotonic() < deadline and any(future.status == "pending" for future in waited):
            time.sleep(0.02)                          # their results are on the way
        self._cancel(lambda future: True)
        if still:
            stages.notice(f"warning: {self._named(still)} still being written on the Dask workers when the batch "
                          "stopped, and may still appear (not in --summary)")

    def _writers(self):
        """Every worker's answer to :func:`stop_run`: (keys of the run's jobs that last passed their
        write stage, those of them writing now), or None when the cluster does not answer."""
        client = self.client
        found = _bounded(lambda: client.run(stop_run, self.run_id, on_error="return"), STOP_CALL)
        if found is None:
            return None
        last = [entry for entry in found.values() if isinstance(entry, (tuple, list))]
        return {key for key, _ in last}, {key for key, busy in last if busy}

    def _writes_waited(self, written: set, writing: set) -> set:
        """Ask the workers until none is writing a file of the run (``writing``: the keys said so),
        up to WRITE_WAIT s, said after WRITE_NOTICE s; the keys still writing then, or when the
        cluster stopped answering or a signal came (``written`` grows by those that wrote)."""
        started, said, signum = time.monotonic(), False, self.signals.signum
        while writing:
            waited = time.monotonic() - started
            if waited > WRITE_WAIT or self.signals.signum != signum:
                return writing
            if not said and waited > WRITE_NOTICE:
                said = True
                stages.notice(f"waiting while the Dask workers finish writing {self._named(writing)} (at most "
                              f"{WRITE_WAIT:.0f} s; Ctrl-C stops waiting)")
            time.sleep(0.05)
            answer = self._writers()
            if answer is None:
                return writing
            written |= answer[0]
            writing = answer[1]
        return writing

    def _named(self, keys: set) -> str:
        """'N file(s) (a.png, b.png, c.png, ...)' for the jobs of ``keys``, named as the user did."""
        names = [job.output for future, job in zip(self.futures, self.jobs) if future.key in keys]
        return f"{len(names)} file(s) ({', '.join(names[:3])}{', ...' if len(names) > 3 else ''})"

    def _cancel(self, chosen) -> None:
        """Cancel the run's futures not finished that ``chosen(future)`` picks."""
        pending = [future for future in self.futures if future.status != "finished" and chosen(future)]
        if pending:
            client = self.client
            _bounded(lambda: client.cancel(pending, force=True), STOP_CALL)

    def _arrived(self, jobs: list, sent: list, index: dict):
        """After a signal: the results that had arrived and were not yielded yet (not those of jobs
        that refused to write because the run was stopped: they stay unfinished)."""
        for future in self.futures:
            i = index[future.key]
            if i in self.unfinished and future.status == "finished":
                outcome = _bounded(lambda: self._outcome(future), STOP_CALL)
                if outcome is not None and not isinstance(outcome[0], NotWritten):
                    self.unfinished.discard(i)
                    yield (i, jobs[i], *_renamed(outcome, jobs[i], sent[i]))

    def _on_disk(self, jobs: list, clocks: dict):
        """After a signal: the files not reported but written since the run began, as ok (a
        result cancelled on its way back, its file already in place; its warnings are lost)."""
        for i in sorted(self.unfinished):
            if _in_place(jobs[i], clocks):
                self.unfinished.discard(i)
                yield (i, jobs[i], None, None, 0.0)

    def _lost(self, jobs: list, clocks: dict):
        """After the scheduler was lost: the files not finished, as failed, or as ok where the
        output was written since the run began (its warnings are lost with the scheduler)."""
        self.lost = 0
        time.sleep(LOST_GRACE)                        # a write begun before the loss is finished
        for i in sorted(self.unfinished):
            job, written = jobs[i], None
            if _in_place(job, clocks):
                written = (None, None, 0.0)
            else:
                self.lost += 1
            yield (i, job, *(written or (Unfinished(LOST), None, 0.0)))
        self.unfinished.clear()

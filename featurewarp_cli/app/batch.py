"""``featurewarp batch``: many files, each with its own mask, optionally in parallel processes.

Every file goes through :func:`featurewarp_cli.app.pipeline.warp_file`; a batch only adds
output naming, mask lookup, ``--resume``, a JSON-lines summary, and a process pool or a
Dask cluster (:mod:`featurewarp_cli.app.cluster`). Inputs, masks and the output folder may
be fsspec URLs (:mod:`featurewarp_cli.io.urls`; jobs with one run through
:mod:`featurewarp_cli.app.remote`); plain paths never touch fsspec.
"""

from __future__ import annotations

import glob
import os
import re
import time
from dataclasses import dataclass, replace

from ..io import urls
from ..io.decode import path_problem
from .outputs import file_identity, writable
from .pipeline import Settings, WarpError, warp_file
from .remote import has_url, run_url_job, url_up_to_date


@dataclass(frozen=True)
class Job:
    """One file of a batch: where to read, where to write, and its mask (None: no mask)."""

    input: str
    output: str
    mask: str | None


def plan(inputs, out_dir: str, suffix: str = "", fmt: str | None = None,
         mask_pattern: str | None = "{stem}_mask.png", summary: str | None = None,
         named_masks: list | None = None) -> list[Job]:
    """The jobs of a batch: one per input (an input listed twice once), minus inputs that are
    another input's mask or are named as masks by ``mask_pattern`` and have no mask of their own
    (the default skips a stray ``*_mask.png``).

    Parameters
    ----------
    inputs : sequence of str
    out_dir : str
        Outputs are ``out_dir/{stem}{suffix}.{ext}``; ext is ``fmt`` or the input's extension.
        Created (with its parents) when missing.
    suffix : str
    fmt : str, optional
        Output format name.
    mask_pattern : str or None
        Mask file name with ``{stem}`` (the input's name without extension),
        relative to the input's folder unless absolute. None: no masks.
    summary : str, optional
        The ``--summary`` file: it may not be an input, a mask or an output.
    named_masks : list, optional
        Gets the inputs skipped for their names alone (named as masks, with no input of theirs
        and no mask of their own: a stray mask), for the command to say so.

    Raises
    ------
    WarpError
        An output folder that cannot be created or written, a pattern that does not
        format, two inputs that would write the same output, an output that would replace
        a file the batch reads (its own input too), or a summary that would.
    """
    if "/" in suffix or "\0" in suffix:          # a suffix is part of a name: each file failed, an out-dir made
        raise WarpError(f"{suffix!r} is part of a file name: it holds no '/'", "--suffix", usage=True)
    named_as_mask = _mask_names(mask_pattern)

    def mask_of(path):
        if mask_pattern is None:
            return None
        name = mask_pattern.replace("{stem}", os.path.splitext(os.path.basename(path))[0])
        if urls.is_url(path):
            return _located(urls.join(urls.dirname(path), name), "--mask-pattern")
        return _located(os.path.join(os.path.dirname(path), name), "--mask-pattern")

    inputs = list({_identity(p): p for path in inputs for p in _expanded(path)}.values())
    given = {_identity(p) for p in inputs}                  # skipped ones too: --summary may not name them
    out_dir = _located(out_dir, "--out-dir")
    masks = {_identity(mask_of(p)) for p in inputs} if mask_pattern else set()
    jobs, seen = [], {}
    for path in inputs:
        if _identity(path) in masks:
            continue
        if named_as_mask and named_as_mask.fullmatch(os.path.basename(path)) and not _exists(mask_of(path)):
            if named_masks is not None:           # a photo named like a mask with a mask of its own is warped
                named_masks.append(path)
            continue
        stem, ext = os.path.splitext(os.path.basename(path))
        name = stem + suffix + ("." + fmt if fmt else ext)
        output = urls.join(out_dir, name) if urls.is_url(out_dir) else os.path.join(out_dir, name)
        key = _identity(output)
        if key in seen:
            raise WarpError(f"{seen[key]} and {path} would both write {output} (a --suffix would not help: "
                            "it is added to both); rename one, or run them in separate batches", usage=True)
        seen[key] = path
        jobs.append(Job(path, output, mask_of(path)))
    _check_overwrites(jobs, summary, given | masks)
    if inputs and not jobs:
        raise WarpError("no input left to warp: every INPUT is a mask (another input's, or named as one "
                        "by --mask-pattern with no mask of its own)", usage=True)
    _create(out_dir)
    return jobs


def _check_overwrites(jobs: list[Job], summary: str | None, also_read: set) -> None:
    """Usage error for an output that would replace a file the batch reads (its own input too),
    or a ``summary`` that would replace one of those, an output, or ``also_read`` (identities of
    the inputs skipped as masks, and the masks)."""
    read = {_identity(p): p for job in jobs for p in (job.input, job.mask) if p}
    for job in jobs:
        clash = read.get(_identity(job.output))
        if clash is not None:
            what = "its own input" if clash == job.input else f"a file this batch also reads ({clash})"
            raise WarpError(f"{job.input} would be written to {job.output}, replacing {what}; use another "
                            "--out-dir or a --suffix", usage=True)
    if summary is not None and summary != "-":
        key, linked = _identity(summary), file_identity(summary)
        written = {_identity(job.output) for job in jobs}
        read_files = {file_identity(p) for p in (*read.values(), *also_read)} - {None}    # a hard link: the file
        role = "read by" if key in read or key in also_read or linked in read_files else \
            "an output of" if key in written else None
        if role is not None:
            raise WarpError(f"{summary} is also {role} this batch; it would be overwritten", "--summary",
                            usage=True)


def _exists(path: str) -> bool:
    """Whether a file (or an object at a URL) is there."""
    return urls.isfile(path) if urls.is_url(path) else os.path.isfile(path)


def _mask_names(mask_pattern: str | None):
    """A regular expression for file names ``mask_pattern`` gives to masks (any stem), or None:
    for a pattern without a folder that adds more than an extension to the stem. A usage error
    for a pattern with a field other than ``{stem}`` (no ``str.format``: it ran attribute
    lookups and a 100 MB field width)."""
    if mask_pattern is not None and re.search(r"[{}]", mask_pattern.replace("{stem}", "")):
        shown = mask_pattern if len(mask_pattern) <= 80 else mask_pattern[:80] + "..."
        raise WarpError(f"{shown!r} is not a valid pattern: {{stem}} is its only field (braces "
                        "otherwise are not allowed)", "--mask-pattern", usage=True)
    if not mask_pattern or "/" in mask_pattern or os.sep in mask_pattern or "{stem}" not in mask_pattern:
        return None
    if not os.path.splitext(mask_pattern.replace("{stem}", ""))[0]:
        return None                                  # "{stem}.png": every PNG would match
    before, _, after = mask_pattern.partition("{stem}")
    return re.compile(re.escape(before) + ".+" + re.escape(after))


def _located(path: str, param: str | None = "INPUT") -> str:
    """``path``, a ``file://`` URL as its local path, another URL checked for its back-end
    (a usage error naming what to install)."""
    if not urls.is_url(path):
        return path
    try:
        local = urls.local_path(path)
        if local is None:
            urls.filesystem(path)                   # its back-end is installed
    except ValueError as err:
        raise WarpError(str(err), param, usage=True) from None
    return local or path


def _expanded(path: str) -> list[str]:
    """An INPUT: a path as it is, a URL located; a pattern (glob characters, quoted past the
    shell or past its limit on arguments; a URL's too) as every file it matches, sorted; '-' a
    usage error (a batch reads no stdin)."""
    if path == "-":
        raise WarpError("'-': a batch reads no stdin; name the files (photos/*.jpg)", "INPUT", usage=True)
    if not urls.is_url(path):
        if os.path.lexists(path) or not re.search(r"[*?[]", path):
            return [path]
        found = sorted(glob.glob(path, recursive=True))
        if not found:
            raise WarpError(f"{path} matches no file", "INPUT", usage=True)
        return found
    try:
        return [_located(found) for found in urls.expand(path)]
    except (OSError, ValueError) as err:
        raise WarpError(str(err), "INPUT", usage=True) from None


def _identity(path: str) -> str:
    """What ``path`` names, for comparing: its real path, or a URL's protocol and path."""
    return urls.key(path) if urls.is_url(path) else os.path.realpath(path)


def _create(out_dir: str) -> None:
    """Create ``--out-dir`` (a URL: where its store has folders) and check it can be written
    (a URL: by the first write)."""
    if urls.is_url(out_dir):
        try:
            urls.makedirs(out_dir)
        except (OSError, ValueError, NotImplementedError) as err:
            raise WarpError(f"cannot create {out_dir} ({err})", "--out-dir", usage=True) from None
        return
    try:
        os.makedirs(out_dir, exist_ok=True)
    except OSError as err:
        raise WarpError(f"cannot create {out_dir} ({err.strerror or err})", "--out-dir", usage=True) from None
    writable(os.path.join(out_dir, "probe"), "--out-dir")


def _worker_setup() -> None:
    """In a batch worker: die with the parent (even under SIGKILL), leave Ctrl-C to the parent
    (which stops the workers at once), and clean up on SIGTERM."""
    import signal

    try:
        import ctypes

        ctypes.CDLL(None).prctl(1, signal.SIGKILL)          # PR_SET_PDEATHSIG
    except (OSError, AttributeError):
        pass
    if os.getppid() == 1:                                    # the parent died before prctl
        os._exit(1)
    signal.signal(signal.SIGINT, signal.SIG_IGN)

    def stop(signum, frame):
        from ..io.write import remove_pending
        from .remote import remove_copies

        remove_pending()
        remove_copies([os.getpid()])
        os._exit(128 + signum)

    signal.signal(signal.SIGTERM, stop)


def run_job(settings: Settings, job: Job) -> tuple[str | None, dict | None]:
    """Run one batch job; returns (error message or None, summary or None). Never raises."""
    if has_url(job):
        return run_url_job(settings, job, run_job)
    if not os.path.isfile(job.input):                # named as the input, before its output or mask
        return f"{job.input} {path_problem(job.input)}", None
    try:
        return None, warp_file(settings, job.input, job.output, job.mask)
    except WarpError as err:                         # a --strict refusal keeps the warnings behind it
        return str(err), {"input": job.input, "output": job.output, "warnings": err.warnings} if err.warnings else None
    except Exception as err:  # one bad file must not stop the batch
        return f"{type(err).__name__}: {err}", None


def timed_job(settings: Settings, job: Job) -> tuple[str | None, dict | None, float]:
    """:func:`run_job` and its seconds.

    Returns
    -------
    (str or None, dict or None, float)
        The error, the summary, the seconds. Never raises.
    """
    t0 = time.perf_counter()
    error, summary = run_job(settings, job)
    return error, summary, time.perf_counter() - t0


def up_to_date(job: Job) -> bool:
    """Whether the job's output exists and is newer than its input and mask (``--resume``).

    Strictly newer: on a file system with coarse timestamps an input replaced in the same tick
    as its output is warped again rather than skipped. URLs: by their stores' times."""
    if has_url(job):
        return url_up_to_date(job)
    try:
        written = os.stat(job.output).st_mtime_ns
        return all(os.stat(path).st_mtime_ns < written for path in (job.input, job.mask) if path)
    except OSError:
        return False


def run_jobs(settings: Settings, jobs: list[Job], workers: int = 1, scheduler: str | None = None,
             verbose: bool = False):
    """Start ``jobs``; iterate the result for (index, job, error, summary, seconds).

    Everything that can refuse to start the run (a ``--scheduler`` that names no scheduler or
    cannot be reached, a ``memory://`` URL that other processes would not see) is checked before
    this returns, so a caller opens its own outputs only then. ``close()`` on the result stops
    the jobs not finished (none writes after it returns on a cluster; local processes finish
    the file they are on).

    Parameters
    ----------
    settings : Settings
    jobs : list of Job
    workers : int
        Local worker processes (``--jobs``); above 1 they are spawned, not forked, so that no
        thread pool of a parent library is inherited.
    scheduler : str, optional
        A Dask scheduler (:mod:`featurewarp_cli.app.scheduler`); the jobs are then yielded as
        they finish, locally in order. Local paths are sent to the workers absolute.
    verbose : bool
        Let Dask's log lines through.

    Returns
    -------
    iterator of (int, Job, str or None, dict or None, float), with ``close()``

    Notes
    -----
    ``settings.max_memory`` is the command's: ``--jobs N`` and ``local:N`` give each of their N
    processes an Nth of it (so whether a file fits does not depend on how many are left); a
    remote cluster's workers each have their own machine and get all of it. The files written
    are byte-identical in every mode.
    """
    if not jobs:
        return (outcome for outcome in ())
    from .scheduler import local_workers                    # imports no Dask

    share = workers if scheduler is None else local_workers(scheduler)
    if share > 1 and settings.max_memory is not None:       # one budget for the whole command
        settings = replace(settings, max_memory=settings.max_memory // share)
    workers = max(1, min(workers, len(jobs)))
    if workers > 1 or scheduler is not None:
        _check_shared(jobs, "--scheduler" if scheduler is not None else "--jobs")
    if scheduler is not None:
        from .cluster_run import ClusterRun

        return ClusterRun(settings, jobs, scheduler, [_absolute(job) for job in jobs], verbose)
    if workers == 1:
        return ((i, job, *timed_job(settings, job)) for i, job in enumerate(jobs))
    return _in_processes(settings, jobs, workers)


def _in_processes(settings: Settings, jobs: list[Job], workers: int):
    """:func:`run_jobs` in ``workers`` local processes; closing it cancels the files not started."""
    from concurrent.futures import ProcessPoolExecutor
    from multiprocessing import get_context

    pool = ProcessPoolExecutor(workers, mp_context=get_context("spawn"), initializer=_worker_setup)
    try:
        outcomes = pool.map(timed_job, [settings] * len(jobs), jobs)
        yield from ((i, job, *outcome) for i, (job, outcome) in enumerate(zip(jobs, outcomes)))
    finally:
        pool.shutdown(wait=True, cancel_futures=True)


def _absolute(job: Job) -> Job:
    """``job`` with its local paths absolute (URLs as they are): a Dask worker resolves a relative
    path against its own working folder, which need not be the command's."""
    def located(path):
        return path if path is None or urls.is_url(path) else os.path.abspath(path)

    return Job(located(job.input), located(job.output), located(job.mask))


def _check_shared(jobs: list[Job], param: str) -> None:
    """Usage error when a job names a ``memory://`` URL: other processes do not see this one's."""
    for job in jobs:
        for path in (job.input, job.mask, job.output):
            if urls.is_url(path) and urls.protocol(path) == "memory":
                raise WarpError(f"{path}: memory:// lives in this process only; other processes do not see "
                                "it (use --jobs 1 without --scheduler)", param, usage=True)


def run_batch(settings: Settings, jobs: list[Job], workers: int = 1):
    """Run ``jobs`` locally, yielding (job, error, summary) in the order of ``jobs``
    (see :func:`run_jobs`)."""
    for _, job, error, summary, _ in run_jobs(settings, jobs, workers):
        yield job, error, summary


def summary_record(index: int, job: Job, status: str, seconds: float = 0.0, summary: dict | None = None,
                   error: str | None = None, settings: str | None = None) -> dict:
    """One line of the JSON-lines summary (``--summary``).

    Parameters
    ----------
    index : int
        The job's place in the batch.
    job : Job
    status : {'ok', 'failed', 'skipped'}
    seconds : float
    summary : dict, optional
        :func:`featurewarp_cli.app.report.summary` of a written file (its warnings and notes are kept).
    error : str, optional
    settings : str, optional
        The :func:`featurewarp_cli.app.resume.settings_stamp` its output was (or is known to have
        been) made with. ``dir`` is the folder the paths as given are relative to (``--resume``
        reads them there, from whichever folder it is run).

    Returns
    -------
    dict
    """
    return {"job": index, "input": job.input, "mask": job.mask, "output": job.output, "dir": os.getcwd(),
            "status": status, "seconds": round(seconds, 4), "warnings": list(summary["warnings"]) if summary else [],
            "notes": list(summary.get("notes", [])) if summary else [], "error": error, "settings": settings}

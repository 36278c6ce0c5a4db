"""Batch jobs whose input, mask or output is an fsspec URL (``s3://bucket/a.jpg``, ``memory://``).

The job runs exactly as a local one (:func:`featurewarp_cli.app.batch.run_job`, the same
bytes out) on local copies in a temporary folder: each URL read is copied there whole, the
output is written there, and only a complete output is put to its URL
(:func:`featurewarp_cli.io.urls.put`: all or nothing). Messages name the URLs, never the
copies. ``--resume`` compares the stores' modification times where they report them; where
one does not, the job runs again.

The copies wait in a folder named ``featurewarp-HOST-PID-*`` in the temporary folder, removed
when the job ends, by the command's SIGINT and SIGTERM handlers (for itself and the batch
workers it stops: :func:`remove_copies`), and, where a process was killed outright (SIGKILL,
the kernel's out-of-memory killer), by the next URL job on that machine once the folder is a
minute old (:func:`remove_stale`).
"""

from __future__ import annotations

import glob
import os
import re
import shutil
import socket
import tempfile
import time

from ..io import urls
from ..io.limits import size_text


def has_url(job) -> bool:
    """Whether any of the job's files is a URL (plain paths never reach this module)."""
    return urls.is_url(job.input) or urls.is_url(job.output) or urls.is_url(job.mask)


def run_url_job(settings, job, run_local) -> tuple[str | None, dict | None]:
    """``run_local(settings, job)`` on local copies of the job's URLs; the output put to its
    URL when written. Returns (error or None, summary or None) naming the URLs; never raises."""
    from .batch import Job

    remove_stale()
    folder = tempfile.mkdtemp(prefix=_folder_prefix(os.getpid()))
    try:
        copies = {}
        for url, role in ((job.input, "input"), (job.mask, "mask"), (job.output, "output")):
            if urls.is_url(url):
                os.mkdir(os.path.join(folder, role))
                copies[url] = os.path.join(folder, role, urls.basename(url) or role)
        error = _fetch(settings, job, copies)
        summary = None
        if error is None:
            local = Job(copies.get(job.input, job.input), copies.get(job.output, job.output),
                        copies.get(job.mask, job.mask))
            error, summary = run_local(settings, local)
        if error is None and job.output in copies:
            try:
                with open(copies[job.output], "rb") as file:
                    urls.put(job.output, file.read())
            except (OSError, ValueError, NotImplementedError) as err:
                error, summary = f"cannot write {job.output}: {_reason(err)}", None
    finally:
        shutil.rmtree(folder, ignore_errors=True)
    return named(error, copies), named(summary, copies)


#: Seconds before a folder of copies whose process is gone is removed by another process.
STALE_SECONDS = 60
_swept = False


def _folder_prefix(pid: int | str) -> str:
    """``featurewarp-HOST-PID-``: the name of process ``pid``'s folders of copies starts so."""
    return f"featurewarp-{re.sub(r'[^A-Za-z0-9.]', '_', socket.gethostname())[:64]}-{pid}-"


def _folders(pid: int | str | None = None) -> list[str]:
    """This machine's folders of copies: process ``pid``'s, or every process's."""
    prefix = glob.escape(_folder_prefix("@")).replace("@", "*" if pid is None else str(pid))
    return glob.glob(os.path.join(glob.escape(tempfile.gettempdir()), prefix + "*"))


def remove_copies(pids) -> None:
    """Remove the folders of copies of the processes ``pids`` (signal handlers: this process and
    the batch workers it has stopped)."""
    for pid in pids:
        for folder in _folders(pid):
            shutil.rmtree(folder, ignore_errors=True)


def remove_stale() -> None:
    """Once per process: remove this machine's folders of copies whose process is gone and that
    are older than STALE_SECONDS (a worker killed with SIGKILL leaves its copies behind)."""
    global _swept
    if _swept:
        return
    _swept = True
    start = len(_folder_prefix("")) - 1
    for folder in _folders():
        pid = os.path.basename(folder)[start:].partition("-")[0]
        try:
            os.kill(int(pid), 0)
            continue                                   # its process runs
        except ProcessLookupError:
            pass
        except (ValueError, OverflowError, OSError):  # another user's, or not a pid
            continue
        try:
            if time.time() - os.stat(folder).st_mtime >= STALE_SECONDS:
                shutil.rmtree(folder, ignore_errors=True)
        except OSError:
            pass


def _fetch(settings, job, copies: dict) -> str | None:
    """Copy the job's input and mask URLs into ``copies``; the error, or None. A missing mask is
    left to the local run, which names it as the mask (a missing input is named here)."""
    for url in (job.input, job.mask):
        if url not in copies:
            continue
        try:
            if not urls.isfile(url):
                if url == job.input:
                    return f"{url} does not exist"
                continue
            if settings.max_memory is not None and urls.size(url) > settings.max_memory:
                return (f"{url} is {size_text(urls.size(url), settings.max_memory)}, above the memory limit of "
                        f"{size_text(settings.max_memory)} (--max-memory)")
            with open(copies[url], "wb") as file:
                file.write(urls.read(url))
        except (OSError, ValueError, NotImplementedError) as err:
            return f"cannot read {url}: {_reason(err)}"
    return None


def _reason(err: Exception) -> str:
    return getattr(err, "strerror", None) or str(err) or type(err).__name__


def named(value, copies: dict):
    """``value`` (a message, or a summary: its input, output and warnings) with each local
    copy's path replaced by its URL."""
    if isinstance(value, dict):
        return {**value, "input": named(value["input"], copies), "output": named(value["output"], copies),
                "warnings": [named(warning, copies) for warning in value["warnings"]]}
    for url, path in copies.items():
        value = value.replace(path, url) if value else value
    return value


def url_up_to_date(job) -> bool:
    """``--resume`` for a job with URLs: its output exists and is strictly newer than its input
    and mask, by the times their stores report (False where one reports none)."""
    written = _modified(job.output)
    if written is None:
        return False
    return all((stamp := _modified(path)) is not None and stamp < written for path in (job.input, job.mask) if path)


def _modified(path: str) -> float | None:
    try:
        return urls.modified(path) if urls.is_url(path) else os.stat(path).st_mtime
    except (OSError, ValueError):
        return None

"""``featurewarp batch --scheduler``, stopped: nothing of the run is written after the command has
exited, and the summary names every file on disk (second review, findings 1 and 2)."""

from __future__ import annotations

import os
import signal
import subprocess
import time
import uuid

import pytest

from featurewarp_cli.app import batch, cluster_run
from featurewarp_cli.app.cluster import NotWritten, cluster_job, stop_flag
from test_cluster import cluster, featurewarp, fresh_env, make_inputs, summary_lines, wait_for  # noqa: F401


def _on_workers():
    """Functions for ``Client.run`` (built here so that Dask sends them by value): set or unset the
    workers' stage delay; the keys of the jobs writing on a worker now (the write gate's state)."""
    def set_delay(value):
        import os

        from featurewarp_cli.io import write

        if value is None:
            os.environ.pop(write.STAGE_DELAY_VARIABLE, None)
        else:
            os.environ[write.STAGE_DELAY_VARIABLE] = value

    def writing():
        from featurewarp_cli.app import cluster

        with cluster._GATE:
            return [entry[0] for entry in cluster._LAST_WRITER.values() if entry[1]]

    return set_delay, writing


@pytest.fixture
def client(cluster):  # noqa: F811
    from distributed import Client

    with Client(cluster.scheduler_address, set_as_default=False) as connected:
        yield connected
        connected.run(_on_workers()[0], None, on_error="return")


def writing_now(client) -> list:
    """The keys of the jobs that the cluster's workers are writing now."""
    return [key for keys in client.run(_on_workers()[1], on_error="return").values() if isinstance(keys, list)
            for key in keys]


def until(condition, seconds: float = 60) -> None:
    """Wait for ``condition()`` (asked every 50 ms: each asks every worker)."""
    wait_for(lambda: condition() or time.sleep(0.05), seconds)


def slow_writes(client, seconds: float) -> None:
    """Every write on the workers waits ``seconds`` with its file staged, before linking it."""
    client.run(_on_workers()[0], str(seconds))


def test_a_worker_that_joins_after_the_stop_writes_nothing(tmp_path, cluster, client):  # noqa: F811
    """The stop was a flag on each worker the command reached: a worker that joined after it
    (adaptive scaling, a nanny's restart) ran a queued job and wrote its file after the command
    had exited. The flag is now on the scheduler, and read before each write."""
    inputs = make_inputs(tmp_path / "in", 4)
    out = tmp_path / "out"
    out.mkdir()
    jobs = batch.plan(inputs, str(out))
    settings, run_id = batch.Settings("swirl", params={"angle": 120}), f"test-{uuid.uuid4().hex}"
    assert client.submit(cluster_job, settings, jobs[0], run_id, pure=False).result()[0] is None
    from distributed import Event

    Event(stop_flag(run_id), client=client).set()          # no worker is told
    old = set(client.scheduler_info()["workers"])
    cluster.scale(3)
    try:
        client.wait_for_workers(3, timeout=60)
        joined, = set(client.scheduler_info()["workers"]) - old
        futures = [client.submit(cluster_job, settings, job, run_id, pure=False, workers=[address])
                   for job, address in zip(jobs[1:], [joined, *old])]
        errors = [future.result()[0] for future in futures]
    finally:
        cluster.scale(2)
        wait_for(lambda: len(client.scheduler_info()["workers"]) == 2)
    assert all("the batch was stopped before this file was written" in error for error in errors), errors
    assert all(isinstance(error, NotWritten) for error in errors), errors   # not a failure of the file
    assert os.listdir(out) == ["img00.png"]


def test_a_scheduler_the_gate_cannot_ask_fails_the_job_clearly(tmp_path, cluster, client, monkeypatch):  # noqa: F811
    """A write stage whose question to the scheduler fails writes nothing, and says why (writing
    anyway could put a file in place after a stop no one would hear of)."""
    def unreachable(*args, **kwargs):
        raise OSError("the scheduler is unreachable")

    monkeypatch.setitem(cluster.scheduler.handlers, "event_is_set", unreachable)
    inputs = make_inputs(tmp_path / "in", 1)
    out = tmp_path / "out"
    out.mkdir()
    job, = batch.plan(inputs, str(out))
    error = client.submit(cluster_job, batch.Settings("swirl"), job, "test-run", pure=False).result()[0]
    assert error.startswith("not written: the Dask scheduler did not answer whether the batch goes on (OSError"), error
    assert os.listdir(out) == []


class _Arrived:
    """A finished future for :meth:`ClusterRun._arrived`: its key and the job's result."""

    status = "finished"

    def __init__(self, key: str, error):
        self.key, self.error = key, error

    def result(self):
        return cluster_run.__version__, "tcp://worker", (self.error, None, 0.5)


def test_after_a_signal_a_job_that_refused_to_write_is_unfinished_not_failed():
    """Under load, a job reached its write stage after the signal's stop: its refusal came back as
    a result, and the stopping command printed it as a failed file (and put it in the summary).
    It is left unfinished, as a job that never ran; a job that failed on its own is still said."""
    run = cluster_run.ClusterRun.__new__(cluster_run.ClusterRun)
    run.warned, run.made_by = set(), {}
    run.futures = [_Arrived("a", None), _Arrived("b", NotWritten("RunStopped: the batch was stopped")),
                   _Arrived("c", "c.png: not a picture")]
    run.unfinished = {0, 1, 2}
    jobs = [batch.Job(f"{name}.png", f"out/{name}.png", None) for name in "abc"]
    arrived = list(run._arrived(jobs, jobs, {"a": 0, "b": 1, "c": 2}))
    assert [(i, error) for i, _, error, _, _ in arrived] == [(0, None), (2, "c.png: not a picture")]
    assert run.unfinished == {1}


def _close_while_writing(tmp_path, cluster, client):  # noqa: F811
    """A run of 6 slow-writing files on 2 workers, closed after its first result while a later file
    (the third or fourth: a whole write ahead of it) is being written: the files on disk when
    close returned."""
    inputs = make_inputs(tmp_path / "in", 6)
    out = tmp_path / "out"
    out.mkdir()
    jobs = batch.plan(inputs, str(out))
    run = cluster_run.ClusterRun(batch.Settings("swirl", params={"angle": 120}), jobs, cluster.scheduler_address, jobs)
    try:
        assert next(run)[2] is None
        until(lambda: any(not key.endswith(("-job-0", "-job-1")) for key in writing_now(client)))
    finally:
        run.close()
    return sorted(os.listdir(out))


def test_a_write_longer_than_the_results_wait_is_waited_for(tmp_path, cluster, client, monkeypatch):  # noqa: F811
    """A write that took longer than the stop's fixed wait (10 s) went on after the command had
    exited: now the command waits while a worker says it is writing. (Here the wait is 0.25 s and
    each write 1.25 s: a write still runs a second after the wait, as with 0.5 and 1.5 s.)"""
    monkeypatch.setattr(cluster_run, "STOP_WAIT", 0.25)
    slow_writes(client, 1.25)
    at_close = _close_while_writing(tmp_path, cluster, client)
    assert writing_now(client) == []                   # nothing being written, and nothing will start
    assert 2 <= len(at_close) < 6 and sorted(os.listdir(tmp_path / "out")) == at_close


def test_a_write_longer_than_the_write_wait_is_named(tmp_path, cluster, client, monkeypatch, capsys):  # noqa: F811
    """Past WRITE_WAIT (0.2 s) the command stops waiting, and names the files that may still appear
    (each write takes 2 s: the stop, some 0.3 s from the write's start, ends long before it)."""
    monkeypatch.setattr(cluster_run, "WRITE_WAIT", 0.2)
    slow_writes(client, 2)
    at_close = _close_while_writing(tmp_path, cluster, client)
    said = capsys.readouterr().err
    assert "still being written on the Dask workers when the batch stopped, and may still appear" in said, said
    until(lambda: not writing_now(client))
    late = set(os.listdir(tmp_path / "out")) - set(at_close)
    assert late and all(str(tmp_path / "out" / name) in said for name in late), (late, said)


def test_a_signal_stops_the_cluster_jobs_and_the_summary_keeps_what_finished(tmp_path, client):
    """SIGINT: the jobs running on the workers went on writing after the command had exited, and
    the files finished before the signal were missing from the summary. The signal comes while a
    file is being written (each write takes 2 s; the signal comes within some 0.1 s of its start),
    and the command waits for it."""
    slow_writes(client, 2)
    inputs = make_inputs(tmp_path / "in", 12, size=(160, 120))
    out = tmp_path / "out"
    process = subprocess.Popen(featurewarp("batch", "swirl", *inputs, "--out-dir", out, "--angle", "120",
                                           "--scheduler", client.scheduler.address, "--summary", tmp_path / "s.jsonl"),
                               stderr=subprocess.PIPE, env=fresh_env())
    try:
        until(lambda: writing_now(client))
        process.send_signal(signal.SIGINT)
        _, stderr = process.communicate(timeout=60)
    finally:
        process.kill()
    at_exit = sorted(os.listdir(out))
    assert writing_now(client) == []                   # nothing being written, and nothing will start
    said = [line for line in stderr.decode().splitlines() if not line.startswith("featurewarp: waiting while")]
    assert (process.returncode, said) == (130, ["featurewarp: stopped by SIGINT"]), stderr
    assert sorted(os.listdir(out)) == at_exit and 1 <= len(at_exit) < 12
    lines = summary_lines(tmp_path / "s.jsonl")
    assert sorted(os.path.basename(line["output"]) for line in lines) == at_exit
    assert {line["status"] for line in lines} == {"ok"}


def test_a_file_found_on_disk_after_a_stop_is_stamped_unknown_where_another_version_ran():
    """A file whose result never came back (found on disk after a stop) took the command's
    version in its --summary stamp even where a worker of another featurewarp had run: --resume
    would then keep it for good. Its version is ``unknown`` there (the stamp matches nothing)."""
    run = cluster_run.ClusterRun.__new__(cluster_run.ClusterRun)
    run.futures, run.made_by, run.warned = [_Arrived("a", None), _Arrived("b", None)], {"a": "9.9.9"}, set()
    assert (run.version_of(0), run.version_of(1)) == ("9.9.9", None)       # no other version seen: this one's
    run.warned = {"tcp://worker"}
    assert (run.version_of(0), run.version_of(1)) == ("9.9.9", "unknown")

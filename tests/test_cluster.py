"""``featurewarp batch --scheduler``: the same batch on a Dask cluster (issue 25, item 1)."""

from __future__ import annotations

import contextlib
import io
import json
import logging
import os
import signal
import socket
import sys
import threading
import time
from http.server import BaseHTTPRequestHandler, ThreadingHTTPServer

import cv2
import numpy as np
import pytest
from click.testing import CliRunner

import featurewarp_cli
from featurewarp_cli.app import batch
from featurewarp_cli.cli.main import cli
from test_cli import Runner

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
SAMPLES = os.path.join(ROOT, "samples")
#: The connect timeout the tests give (the command's is 20 s): an address that refuses is given up
#: at 0.5 s (it gets a second less than the whole, at least 0.5), one that never answers at 1.5 s,
#: the same second apart as with 2 s, where the refusal took 1 s and the silence 2 s.
CONNECT_TIMEOUT = 1.5


@pytest.fixture(scope="module")
def cluster():
    from distributed import LocalCluster

    local = LocalCluster(n_workers=2, threads_per_worker=1, processes=True, dashboard_address=None)
    yield local
    local.close()


def make_inputs(folder, count: int, size=(96, 72)):
    """``count`` small images (the shapes sample, each shifted) with their masks."""
    image = cv2.resize(cv2.imread(os.path.join(SAMPLES, "shapes.png")), size, interpolation=cv2.INTER_AREA)
    mask = cv2.resize(cv2.imread(os.path.join(SAMPLES, "shapes_mask.png"), 0), size,
                      interpolation=cv2.INTER_NEAREST)
    os.makedirs(folder, exist_ok=True)
    paths = []
    for i in range(count):
        path = os.path.join(folder, f"img{i:02d}.png")
        cv2.imwrite(path, np.roll(image, 2 * i, axis=1))
        cv2.imwrite(os.path.join(folder, f"img{i:02d}_mask.png"), np.roll(mask, 2 * i, axis=1))
        paths.append(path)
    return paths


@contextlib.contextmanager
def dask_log():
    """What Dask's log handler writes while the block runs. Outside pytest, Dask gives its logger
    a handler on stderr that keeps the records to itself; under pytest (whose handlers the root
    logger has) it gives none, so one is put in its place here."""
    logger = logging.getLogger("distributed")
    caught = io.StringIO()
    handler, propagate = logging.StreamHandler(caught), logger.propagate
    logger.addHandler(handler)
    logger.propagate = False
    try:
        yield caught
    finally:
        logger.removeHandler(handler)
        logger.propagate = propagate


def summary_lines(path):
    with open(path) as f:
        return [json.loads(line) for line in f]


def test_a_killed_worker_costs_nothing(tmp_path, cluster):
    """40 jobs on 2 workers, one killed mid-run: every output written once, the same bytes as the
    local batch, the summary complete, exit 0, and none of Dask's log lines ("Restarting worker")
    on stderr."""
    from distributed import Client

    inputs = make_inputs(tmp_path / "in", 40)
    local_dir, cluster_dir = tmp_path / "local", tmp_path / "cluster"
    local_dir.mkdir()
    cluster_dir.mkdir()
    settings = batch.Settings("swirl", params={"angle": 120})
    jobs = batch.plan(inputs, str(local_dir))
    assert [error for _, error, _ in batch.run_batch(settings, jobs)] == [None] * 40

    with Client(cluster.scheduler_address) as client:
        pids = list(client.run(os.getpid).values())
    killed = []

    def kill_one_worker():
        deadline = time.monotonic() + 60
        while time.monotonic() < deadline and len(os.listdir(cluster_dir)) < 4:
            time.sleep(0.01)
        os.kill(pids[0], signal.SIGKILL)
        killed.append(len(os.listdir(cluster_dir)))

    killer = threading.Thread(target=kill_one_worker)
    killer.start()
    with dask_log() as logged:
        result = CliRunner().invoke(cli, ["batch", "swirl", *inputs, "--out-dir", str(cluster_dir), "--angle", "120",
                                          "--scheduler", cluster.scheduler_address,
                                          "--summary", str(tmp_path / "summary.jsonl")])
    killer.join()
    assert result.exit_code == 0, result.output
    said = logged.getvalue()                   # this process's nanny, as the worker died mid-run:
    assert "killed by signal 9" not in said and "Restarting worker" not in said, said
    assert killed and killed[0] < 40, killed                 # the worker died mid-run
    assert sorted(os.listdir(cluster_dir)) == sorted(os.listdir(local_dir))       # nothing half-written
    for name in os.listdir(local_dir):
        assert (cluster_dir / name).read_bytes() == (local_dir / name).read_bytes(), name
    lines = summary_lines(tmp_path / "summary.jsonl")
    assert sorted(line["job"] for line in lines) == list(range(40))
    assert {line["status"] for line in lines} == {"ok"}
    assert all(line["seconds"] > 0 and line["error"] is None for line in lines)
    assert {line["output"] for line in lines} == {job.output.replace(str(local_dir), str(cluster_dir))
                                                 for job in jobs}


def test_summary_and_resume_locally(tmp_path):
    """--summary: one line per file (a failed one with its error); --resume skips what is up to date."""
    inputs = make_inputs(tmp_path / "in", 3)
    os.remove(tmp_path / "in" / "img01_mask.png")
    out = tmp_path / "out"
    out.mkdir()
    args = ["batch", "swirl", *inputs, "--out-dir", str(out), "--summary", str(tmp_path / "s.jsonl")]
    first = CliRunner().invoke(cli, args)
    assert first.exit_code == 1 and "1 of 3 files failed" in first.output
    lines = {line["job"]: line for line in summary_lines(tmp_path / "s.jsonl")}
    assert [lines[i]["status"] for i in range(3)] == ["ok", "failed", "ok"]
    assert "img01_mask.png" in lines[1]["error"]
    again = CliRunner().invoke(cli, args + ["--resume"])
    lines = {line["job"]: line for line in summary_lines(tmp_path / "s.jsonl")}
    assert [lines[i]["status"] for i in range(3)] == ["skipped", "failed", "skipped"]
    assert again.exit_code == 1
    os.utime(inputs[0], ns=(time.time_ns() + 10**9,) * 2)        # the input changed after its output
    CliRunner().invoke(cli, args + ["--resume"])
    lines = {line["job"]: line for line in summary_lines(tmp_path / "s.jsonl")}
    assert lines[0]["status"] == "ok" and lines[2]["status"] == "skipped"


@pytest.mark.parametrize("scheduler,code,words", [
    ("local:0", 2, "local:N"),
    ("local:many", 2, "local:N"),
    ("missing-scheduler.json", 2, "no such scheduler file"),
    ("tcp://127.0.0.1:9", 1, "cannot reach the Dask scheduler"),
])
def test_bad_schedulers_are_one_line_errors(tmp_path, monkeypatch, scheduler, code, words):
    from featurewarp_cli.app import scheduler as scheduler_module

    monkeypatch.setattr(scheduler_module, "CONNECT_TIMEOUT", CONNECT_TIMEOUT)
    inputs = make_inputs(tmp_path / "in", 1)
    result = CliRunner().invoke(cli, ["batch", "swirl", *inputs, "--out-dir", str(tmp_path), "--scheduler", scheduler])
    assert result.exit_code == code, result.output
    assert words in result.output and "--scheduler" in result.output
    assert "Traceback" not in result.output


def test_a_missing_or_folder_input_fails_alone_and_is_named_as_the_input(tmp_path):
    inputs = make_inputs(tmp_path / "in", 1)
    (tmp_path / "folder").mkdir()
    out = tmp_path / "out"
    out.mkdir()
    result = CliRunner().invoke(cli, ["batch", "swirl", inputs[0], str(tmp_path / "gone.png"), str(tmp_path / "folder"),
                                      "--out-dir", str(out)])
    assert result.exit_code == 1 and "2 of 3 files failed" in result.output
    assert "gone.png does not exist" in result.output and "gone_mask" not in result.output
    assert "folder is a folder, not a file" in result.output
    assert sorted(os.listdir(out)) == ["img00.png"]


def test_the_memory_budget_is_the_whole_batchs(tmp_path):
    """--max-memory is shared by the --jobs processes: a budget one job fits in, split two ways,
    refuses the jobs (and says so), where one process at a time warps them all. (Two processes,
    not four: each is a fresh Python, spawned; 3M fits a job, 1.5M does not.)"""
    inputs = make_inputs(tmp_path / "in", 4)
    args = ["batch", "swirl", *inputs, "--out-dir", str(tmp_path / "out"), "--max-memory", "3M"]
    assert CliRunner().invoke(cli, args).exit_code == 0
    split = CliRunner().invoke(cli, args + ["--jobs", "2", "--out-dir", str(tmp_path / "out2")])
    assert split.exit_code == 1 and "--max-memory" in split.output


def featurewarp(*args) -> list[str]:
    """The command line of ``featurewarp ARGS`` in a fresh process, from this source tree."""
    return [sys.executable, "-m", "featurewarp_cli", *map(str, args)]


def fresh_env() -> dict:
    return {**os.environ, "PYTHONPATH": ROOT}


def wait_for(condition, seconds: float = 60) -> None:
    deadline = time.monotonic() + seconds
    while not condition():
        assert time.monotonic() < deadline, "waited too long"
        time.sleep(0.005)


def invoke(*args):
    """``featurewarp batch swirl ARGS`` as the console script runs it (one-line errors on stderr)."""
    return Runner()("batch", "swirl", *args)


def all_jobs_gone(cluster) -> None:
    """Wait until no task of a featurewarp run is left on the scheduler nor on a worker (queued,
    running, or cancelled and still running): no file of a run can be written after that. (A
    fixed wait instead gave a job still running a second or so to show itself.)"""
    from distributed import Client

    def on_workers(dask_worker):            # nested: Dask sends it by value
        return [str(key) for key in dask_worker.state.tasks if str(key).startswith("featurewarp-")]

    def on_scheduler(dask_scheduler):
        return [str(key) for key in dask_scheduler.tasks if str(key).startswith("featurewarp-")]

    with Client(cluster.scheduler_address, set_as_default=False) as client:
        wait_for(lambda: not client.run_on_scheduler(on_scheduler)
                 and not any(client.run(on_workers, on_error="return").values()) or time.sleep(0.02))


def test_relative_paths_are_resolved_where_the_command_runs(tmp_path, cluster, monkeypatch):
    """The workers' working folder is not the command's: relative INPUT, masks and --out-dir are
    sent absolute (they failed, or were written into the worker's folder with status ok), and
    messages and the summary name them as given."""
    make_inputs(tmp_path / "in", 2)
    os.rename(tmp_path / "in" / "img01_mask.png", tmp_path / "in" / "other_mask.png")
    monkeypatch.chdir(tmp_path)
    result = invoke("in/img00.png", "in/img01.png", "--out-dir", "rel_out", "--angle", "120",
                    "--scheduler", cluster.scheduler_address, "--summary", "s.jsonl")
    assert result.code == 1, result.stderr
    assert os.listdir(tmp_path / "rel_out") == ["img00.png"]
    assert "featurewarp: error: in/img01.png: --mask: in/img01_mask.png does not exist" in result.stderr
    lines = {line["job"]: line for line in summary_lines(tmp_path / "s.jsonl")}
    assert (lines[0]["input"], lines[0]["mask"], lines[0]["output"], lines[0]["status"]) == (
        "in/img00.png", "in/img00_mask.png", "rel_out/img00.png", "ok")
    assert lines[1]["error"] == "--mask: in/img01_mask.png does not exist"


class _SilentHTTP(BaseHTTPRequestHandler):
    def log_message(self, *args):
        pass


@pytest.fixture
def not_schedulers():
    """Addresses that answer but are no Dask scheduler: an HTTP server, and a service that speaks
    first (as SSH does)."""
    http = ThreadingHTTPServer(("127.0.0.1", 0), _SilentHTTP)
    banner = socket.create_server(("127.0.0.1", 0))

    def greet():
        while True:
            try:
                peer, _ = banner.accept()
            except OSError:
                return
            peer.sendall(b"SSH-2.0-OpenSSH_9.6p1\r\n")
            threading.Timer(5, peer.close).start()

    threading.Thread(target=http.serve_forever, args=(0.05,), daemon=True).start()     # shutdown() within 50 ms
    threading.Thread(target=greet, daemon=True).start()
    yield {"http": f"tcp://127.0.0.1:{http.server_address[1]}", "banner": f"127.0.0.1:{banner.getsockname()[1]}"}
    http.shutdown()
    banner.close()


def test_what_is_not_a_scheduler_fails_in_one_line_within_the_timeout(tmp_path, monkeypatch, cluster, not_schedulers):
    """The dashboard's port (an HTTP server) kept the command waiting forever; an SSH banner was read
    as a frame length (a MemoryError); a worker's address is not its scheduler's."""
    from distributed import Client

    from featurewarp_cli.app import scheduler as scheduler_module

    monkeypatch.setattr(scheduler_module, "CONNECT_TIMEOUT", CONNECT_TIMEOUT)
    inputs = make_inputs(tmp_path / "in", 1)
    with Client(cluster.scheduler_address, set_as_default=False) as client:
        worker = next(iter(client.scheduler_info()["workers"]))
    cases = [(not_schedulers["http"], "is not a Dask scheduler"), (not_schedulers["banner"], "is not a Dask scheduler"),
             (worker, "is a Dask worker, not the scheduler")]
    for address, words in cases:
        results = []
        started = time.monotonic()
        args = ["batch", "swirl", *map(str, inputs), "--out-dir", str(tmp_path / "out"), "--scheduler", address]
        attempt = threading.Thread(target=lambda: results.append(CliRunner().invoke(cli, args)), daemon=True)
        attempt.start()
        attempt.join(15)
        assert results, f"{address}: still waiting after 15 s"
        assert time.monotonic() - started < 15          # the 20 s connect timeout is not waited out
        assert results[0].exit_code == 1 and words in results[0].output, results[0].output
        assert results[0].output.count("\n") == 1 and address in results[0].output


@pytest.mark.parametrize("content, words", [
    ("{}", "is not a Dask scheduler file"),
    ("", "is not a Dask scheduler file"),
    ('{"address": "tls://127.0.0.1:1"}', "tls:// needs Dask's TLS settings"),
    ('{"address": "ucx://127.0.0.1:1"}', "ucx:// is not supported"),
    ('{"address": "tcp://"}', "is not a scheduler address"),
])
def test_malformed_scheduler_files_are_usage_errors(tmp_path, content, words):
    (tmp_path / "bad.json").write_text(content)
    inputs = make_inputs(tmp_path / "in", 1)
    result = invoke(*inputs, "--out-dir", tmp_path / "out", "--scheduler", tmp_path / "bad.json")
    assert result.code == 2 and words in result.stderr and result.stderr.count("\n") == 1, result.stderr
    assert "Error" not in result.stderr.replace("Invalid value", "")       # no exception's name


@pytest.mark.parametrize("value, words", [
    ("tls://127.0.0.1:1", "tls:// needs Dask's TLS settings"),
    ("ucx://127.0.0.1:1", "ucx:// is not supported"),
    ("tcp://", "is not a scheduler address"),
    ("", "names no scheduler"),
    ("sched_noext", "no such scheduler file"),
    ("{tmp}", "is a folder, not a scheduler file"),
])
def test_malformed_scheduler_values_are_usage_errors_before_anything_is_written(tmp_path, value, words):
    """Every value that cannot name a scheduler is exit 2 (a malformed address was exit 1), and no
    --out-dir is created."""
    inputs = make_inputs(tmp_path / "in", 1)
    result = invoke(*inputs, "--out-dir", tmp_path / "out", "--scheduler", value.replace("{tmp}", str(tmp_path)))
    assert result.code == 2 and words in result.stderr and result.stderr.count("\n") == 1, result.stderr
    assert not (tmp_path / "out").exists()


def test_a_scheduler_file_is_known_by_its_content_not_its_name(tmp_path, cluster):
    inputs = make_inputs(tmp_path / "in", 1)
    for name in ("sched.info", "SCHED.JSON"):
        (tmp_path / name).write_text(json.dumps({"type": "Scheduler", "address": cluster.scheduler_address}))
        result = invoke(*inputs, "--out-dir", tmp_path / name.replace(".", "-"), "--scheduler", tmp_path / name)
        assert result.code == 0, result.stderr


@pytest.mark.parametrize("scheduler", ["local:0", "tcp://127.0.0.1:9", "memory"])
def test_a_run_that_cannot_start_leaves_the_summary_as_it_was(tmp_path, monkeypatch, cluster, scheduler):
    """The summary was emptied before --scheduler was checked or the cluster reached."""
    from featurewarp_cli.app import scheduler as scheduler_module

    monkeypatch.setattr(scheduler_module, "CONNECT_TIMEOUT", CONNECT_TIMEOUT)
    summary = tmp_path / "keep.jsonl"
    summary.write_text('{"job": 0, "status": "failed"}\n' * 3)
    inputs = make_inputs(tmp_path / "in", 2)
    if scheduler == "memory":
        inputs, scheduler = ["memory://featurewarp-test/a.png"], cluster.scheduler_address
    result = invoke(*inputs, "--out-dir", tmp_path / "out", "--scheduler", scheduler, "--summary", summary)
    assert result.code in (1, 2) and "--scheduler" in result.stderr, result.stderr
    assert summary.read_text() == '{"job": 0, "status": "failed"}\n' * 3


def test_jobs_and_scheduler_exclude_each_other(tmp_path, cluster):
    inputs = make_inputs(tmp_path / "in", 1)
    for jobs in ("4", "1"):
        result = invoke(*inputs, "--out-dir", tmp_path / "out", "--scheduler", cluster.scheduler_address, "-j", jobs)
        assert result.code == 2 and "--jobs and --scheduler exclude each other" in result.stderr
    assert not (tmp_path / "out").exists()


def test_a_lost_scheduler_is_one_line_and_the_summary_matches_the_disk(tmp_path, cluster, capfd, monkeypatch):
    """The connection to the scheduler cut mid-run: Dask's traceback and one FutureCancelledError
    line per file (internal keys, a literal \\n) were printed, and files on disk were 'failed'.
    (The writes begun before the cut are given 1 s, not the command's 2: writing a 640 x 480 PNG
    takes well under 0.1 s; nothing is written once every job of the run is gone from the cluster.)"""
    from distributed import Client

    from featurewarp_cli.app import cluster_run

    monkeypatch.setattr(cluster_run, "LOST_GRACE", 1.0)
    inputs = make_inputs(tmp_path / "in", 12, size=(640, 480))
    out = tmp_path / "out"

    def cut_the_connection():
        wait_for(lambda: out.is_dir() and len(os.listdir(out)) >= 1)
        for client in list(Client._instances):
            if client.status == "running" and client.scheduler.address == cluster.scheduler_address:
                client.loop.add_callback(client.scheduler_comm.comm.abort)

    cutter = threading.Thread(target=cut_the_connection)
    cutter.start()
    result = invoke(*inputs, "--out-dir", out, "--angle", "120", "--scheduler", cluster.scheduler_address,
                    "--summary", tmp_path / "s.jsonl")
    cutter.join()
    at_exit = sorted(os.listdir(out))
    all_jobs_gone(cluster)
    assert result.code == 1
    assert result.stderr.startswith("featurewarp: error: lost the connection to the Dask scheduler at ")
    assert result.stderr.count("\n") == 1 and "files not finished" in result.stderr, result.stderr
    assert "Traceback" not in capfd.readouterr().err
    assert sorted(os.listdir(out)) == at_exit and len(at_exit) < 12
    lines = summary_lines(tmp_path / "s.jsonl")
    assert sorted(line["job"] for line in lines) == list(range(12))
    written = {os.path.basename(line["output"]) for line in lines if line["status"] == "ok"}
    assert written == set(at_exit)
    assert {line["error"] for line in lines if line["status"] == "failed"} == {
        "not finished: the connection to the Dask scheduler was lost"}


def test_a_scheduler_without_workers_is_said_once_and_waited_for(tmp_path, monkeypatch):
    """A scheduler whose workers are still queued kept the command waiting in silence. (A scheduler
    in this process, with no worker until one thread worker joins, a second after the command has
    said it waits (at most 10 s on): no process is started.)"""
    from distributed import LocalCluster

    from featurewarp_cli import stages
    from featurewarp_cli.app import scheduler as scheduler_module

    monkeypatch.setattr(scheduler_module, "WORKERS_NOTICE", 0.3)
    said, notice = threading.Event(), stages.notice

    def noticed(text):
        notice(text)
        if text.startswith("waiting for workers"):
            said.set()

    def join_when_said():                    # a second after the notice: the command must go on waiting
        said.wait(10)
        time.sleep(1.0)
        empty.scale(1)

    monkeypatch.setattr(stages, "notice", noticed)
    inputs = make_inputs(tmp_path / "in", 1)
    with LocalCluster(n_workers=0, processes=False, protocol="tcp://", host="127.0.0.1", dashboard_address=None,
                      scheduler_kwargs={"dashboard_address": "127.0.0.1:0"}) as empty:
        joiner = threading.Thread(target=join_when_said)
        joiner.start()
        result = invoke(*inputs, "--out-dir", tmp_path / "out", "--scheduler", empty.scheduler_address)
        joiner.join()
    assert result.code == 0, result.stderr
    assert result.stderr == (f"featurewarp: waiting for workers on {empty.scheduler_address}: the Dask scheduler "
                             "has none yet (Ctrl-C stops)\n")
    assert os.listdir(tmp_path / "out") == ["img00.png"]


def test_local_n_starts_no_dashboard_and_silences_dask(tmp_path, cluster, monkeypatch):
    """local:N's scheduler served a dashboard on 8787 (another port, with a three-line warning, when
    8787 was taken), and its workers' log lines reached stderr. (The local cluster is recorded and
    stood in for by the module's cluster.)"""
    import dask
    import distributed

    from featurewarp_cli.app import scheduler as scheduler_module

    seen = {}

    class Recorder:
        def __init__(self, **options):
            seen.update(options, routes=dask.config.get("distributed.scheduler.http.routes"))
            self.scheduler_address = cluster.scheduler_address

        def close(self, timeout=None):
            seen["closed"] = True

    def client_of(local, **options):
        return distributed.Client(local.scheduler_address, **options)

    stand_in = type(distributed)("distributed")
    stand_in.__dict__.update(vars(distributed), LocalCluster=Recorder, Client=client_of)
    monkeypatch.setattr(scheduler_module, "distributed_module", lambda: stand_in)
    inputs = make_inputs(tmp_path / "in", 2)
    result = invoke(*inputs, "--out-dir", tmp_path / "out", "--scheduler", "local:2")
    assert (result.code, result.stderr) == (0, ""), result.stderr
    assert seen["dashboard_address"] is None and seen["routes"] == []
    assert seen["scheduler_kwargs"]["dashboard_address"].endswith(":0")      # no fixed port to be taken
    assert seen["silence_logs"] > logging.CRITICAL and seen["n_workers"] == 2 and seen["closed"]


def test_a_summary_that_cannot_be_written_stops_the_cluster_jobs(tmp_path, cluster):
    """--summary /dev/full: an anonymous OSError, and the jobs already sent went on writing (none
    writes after the command: the files once every job of the run is gone are those at its exit)."""
    inputs = make_inputs(tmp_path / "in", 12, size=(640, 480))
    out = tmp_path / "out"
    result = invoke(*inputs, "--out-dir", out, "--angle", "120", "--scheduler", cluster.scheduler_address,
                    "--summary", "/dev/full")
    at_exit = sorted(os.listdir(out))
    all_jobs_gone(cluster)
    assert result.code == 1
    assert result.stderr == ("featurewarp: error: --summary: cannot write /dev/full (No space left on device); "
                             "the batch was stopped\n")
    assert sorted(os.listdir(out)) == at_exit and len(at_exit) < 12


def test_workers_with_another_featurewarp_version_are_named(tmp_path, cluster, monkeypatch):
    """Jobs went to workers of another version without a word (other bytes, silently)."""
    from featurewarp_cli.app import cluster_run

    monkeypatch.setattr(cluster_run, "__version__", "9.9.9")
    inputs = make_inputs(tmp_path / "in", 2)
    result = invoke(*inputs, "--out-dir", tmp_path / "out", "--scheduler", cluster.scheduler_address)
    assert result.code == 0
    warning, = result.stderr.splitlines()
    assert warning.startswith("featurewarp: warning: 2 Dask worker(s) run another featurewarp than this "
                              "command's 9.9.9, and may write other bytes: tcp://"), warning
    assert f"({featurewarp_cli.__version__})" in warning


def test_outputs_of_workers_with_another_version_are_not_stamped_with_the_commands(tmp_path, cluster, monkeypatch):
    """A worker of another featurewarp made the file, but --summary recorded the command's settings
    stamp (which holds the version): --resume then skipped those outputs for good, though an
    upgrade is documented to warp everything once more."""
    from featurewarp_cli.app import cluster_run

    monkeypatch.setattr(cluster_run, "__version__", "9.9.9")
    monkeypatch.setattr(featurewarp_cli, "__version__", "9.9.9")     # the command's; the workers run the real one
    inputs = make_inputs(tmp_path / "in", 2)
    args = [*inputs, "--out-dir", tmp_path / "out", "--summary", tmp_path / "s.jsonl"]
    assert invoke(*args, "--scheduler", cluster.scheduler_address).code == 0
    again = invoke(*args, "--resume")                               # the command's own version, locally
    assert again.code == 0
    assert "warping 2 up-to-date output(s) again" in again.stderr and "(other settings)" in again.stderr
    assert [line["status"] for line in summary_lines(tmp_path / "s.jsonl")] == ["ok", "ok"]


def test_a_workers_error_names_the_output_folder_as_given():
    """An --out-dir the workers could not write was named by the absolute path sent to them
    ("OUTPUT: directory /abs/roout is not writable"), where the README says messages name paths
    as given."""
    from featurewarp_cli.app.batch import Job
    from featurewarp_cli.app.cluster_run import _renamed

    given, sent = Job("in/a.png", "roout/a.png", None), Job("/w/in/a.png", "/w/roout/a.png", None)
    error = "OUTPUT: directory /w/roout is not writable (Read-only file system)"
    assert _renamed((error, None, 0.0), given, sent)[0] == "OUTPUT: directory roout is not writable (Read-only file system)"

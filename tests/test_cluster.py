"""``featurewarp batch --scheduler``: the same batch on a Dask cluster (issue 25, item 1)."""

from __future__ import annotations

import json
import os
import signal
import threading
import time

import cv2
import numpy as np
import pytest
from click.testing import CliRunner

from featurewarp_cli.app import batch
from featurewarp_cli.cli.main import cli

SAMPLES = os.path.join(os.path.dirname(__file__), os.pardir, "samples")


@pytest.fixture(scope="module")
def cluster():
    from distributed import LocalCluster

    local = LocalCluster(n_workers=2, threads_per_worker=1, processes=True, dashboard_address=None)
    yield local
    local.close()


def make_inputs(folder, count: int):
    """``count`` small images (the shapes sample, each shifted) with their masks."""
    image = cv2.resize(cv2.imread(os.path.join(SAMPLES, "shapes.png")), (96, 72), interpolation=cv2.INTER_AREA)
    mask = cv2.resize(cv2.imread(os.path.join(SAMPLES, "shapes_mask.png"), 0), (96, 72),
                      interpolation=cv2.INTER_NEAREST)
    os.makedirs(folder, exist_ok=True)
    paths = []
    for i in range(count):
        path = os.path.join(folder, f"img{i:02d}.png")
        cv2.imwrite(path, np.roll(image, 2 * i, axis=1))
        cv2.imwrite(os.path.join(folder, f"img{i:02d}_mask.png"), np.roll(mask, 2 * i, axis=1))
        paths.append(path)
    return paths


def summary_lines(path):
    with open(path) as f:
        return [json.loads(line) for line in f]


def test_a_killed_worker_costs_nothing(tmp_path, cluster):
    """40 jobs on 2 workers, one killed mid-run: every output written once, the same bytes as the
    local batch, the summary complete, exit 0."""
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
    result = CliRunner().invoke(cli, ["batch", "swirl", *inputs, "--out-dir", str(cluster_dir), "--angle", "120",
                                      "--scheduler", cluster.scheduler_address,
                                      "--summary", str(tmp_path / "summary.jsonl")])
    killer.join()
    assert result.exit_code == 0, result.output
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
    from featurewarp_cli.app import cluster as cluster_module

    monkeypatch.setattr(cluster_module, "CONNECT_TIMEOUT", 2)
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
    """--max-memory is shared by the --jobs processes: a budget one job fits in, split four ways,
    refuses the jobs (and says so), where one process at a time warps them all."""
    inputs = make_inputs(tmp_path / "in", 4)
    args = ["batch", "swirl", *inputs, "--out-dir", str(tmp_path / "out"), "--max-memory", "3M"]
    assert CliRunner().invoke(cli, args).exit_code == 0
    split = CliRunner().invoke(cli, args + ["--jobs", "4", "--out-dir", str(tmp_path / "out4")])
    assert split.exit_code == 1 and "--max-memory" in split.output

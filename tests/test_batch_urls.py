"""``featurewarp batch`` with fsspec URLs (issue 25 item 1): inputs, masks and outputs as
``memory://`` (in this process) and ``file://`` URLs give the local batch's bytes, write all or
nothing, resume by the stores' times, and fail in one line naming what to install."""

from __future__ import annotations

import importlib.util
import json
import os
import signal
import subprocess
import sys
import tempfile
import time
import uuid

import fsspec
import numpy as np
import pytest

from featurewarp_cli.app import batch
from featurewarp_cli.io import urls
from test_cli import runner, save, scene, square_mask, textured  # noqa: F401  (fixture)

MEMORY = fsspec.filesystem("memory")


@pytest.fixture
def bucket(tmp_path):
    """Two images with masks, in tmp_path/photos and under memory://<fresh bucket>/photos."""
    folder = tmp_path / "photos"
    folder.mkdir()
    for name in ("a.png", "b.jpg"):
        scene(folder, name)
    root = f"fw-{uuid.uuid4().hex[:8]}"
    for name in os.listdir(folder):
        MEMORY.pipe_file(f"/{root}/photos/{name}", (folder / name).read_bytes())
    yield root
    MEMORY.rm(f"/{root}", recursive=True)


def local_batch(runner, tmp_path) -> dict[str, bytes]:
    out = tmp_path / "local-out"
    run = runner("batch", "swirl", tmp_path / "photos" / "a.png", tmp_path / "photos" / "b.jpg", "-o", out,
                 "--angle", "60")
    assert run.code == 0, run.stderr
    return {name: (out / name).read_bytes() for name in os.listdir(out)}


def test_memory_urls_give_the_local_batch_bytes_and_resume(runner, tmp_path, bucket):
    expected = local_batch(runner, tmp_path)
    summary = tmp_path / "summary.jsonl"
    run = runner("batch", "swirl", f"memory://{bucket}/photos/*", "-o", f"memory://{bucket}/out", "--angle", "60",
                 "--summary", summary)
    assert run.code == 0, run.stderr
    assert sorted(MEMORY.ls(f"/{bucket}/out", detail=False)) == [f"/{bucket}/out/a.png", f"/{bucket}/out/b.jpg"]
    assert {name: MEMORY.cat_file(f"/{bucket}/out/{name}") for name in expected} == expected
    lines = [json.loads(line) for line in summary.read_text().splitlines()]
    assert [(line["input"], line["mask"], line["output"], line["status"]) for line in lines] == [
        (f"memory://{bucket}/photos/a.png", f"memory://{bucket}/photos/a_mask.png", f"memory://{bucket}/out/a.png",
         "ok"),
        (f"memory://{bucket}/photos/b.jpg", f"memory://{bucket}/photos/b_mask.png", f"memory://{bucket}/out/b.jpg",
         "ok")]
    MEMORY.pipe_file(f"/{bucket}/photos/b.jpg", (tmp_path / "photos" / "b.jpg").read_bytes())   # newer than its output
    again = runner("batch", "swirl", f"memory://{bucket}/photos/*", "-o", f"memory://{bucket}/out", "--angle", "60",
                   "--resume", "--summary", summary)
    assert again.code == 0, again.stderr
    assert [json.loads(line)["status"] for line in summary.read_text().splitlines()] == ["skipped", "ok"]


def test_file_urls_are_local_paths(runner, tmp_path, bucket):
    expected = local_batch(runner, tmp_path)
    photos = (tmp_path / "photos").as_uri()
    run = runner("batch", "swirl", f"{photos}/a.png", f"{photos}/b.jpg", "-o", (tmp_path / "url-out").as_uri(),
                 "--angle", "60")
    assert run.code == 0, run.stderr
    assert {name: (tmp_path / "url-out" / name).read_bytes() for name in expected} == expected
    assert batch.plan([f"{photos}/a.png"], (tmp_path / "o").as_uri()) == [
        batch.Job(str(tmp_path / "photos" / "a.png"), str(tmp_path / "o" / "a.png"),
                  str(tmp_path / "photos" / "a_mask.png"))]


def test_a_local_input_to_a_url_output_and_back(runner, tmp_path, bucket):
    expected = local_batch(runner, tmp_path)
    run = runner("batch", "swirl", tmp_path / "photos" / "a.png", "-o", f"memory://{bucket}/mixed", "--angle", "60")
    assert run.code == 0 and MEMORY.cat_file(f"/{bucket}/mixed/a.png") == expected["a.png"]
    run = runner("batch", "swirl", f"memory://{bucket}/photos/a.png", "-o", tmp_path / "back", "--angle", "60")
    assert run.code == 0 and (tmp_path / "back" / "a.png").read_bytes() == expected["a.png"]


def test_a_failed_job_writes_nothing_and_names_the_url(runner, tmp_path, bucket):
    MEMORY.pipe_file(f"/{bucket}/bad/x.png", b"not an image")
    MEMORY.pipe_file(f"/{bucket}/bad/x_mask.png", (tmp_path / "photos" / "a_mask.png").read_bytes())
    MEMORY.pipe_file(f"/{bucket}/bad/y.png", (tmp_path / "photos" / "a.png").read_bytes())
    run = runner("batch", "swirl", f"memory://{bucket}/bad/x.png", f"memory://{bucket}/bad/y.png",
                 f"memory://{bucket}/bad/none.png", "-o", f"memory://{bucket}/bad-out")
    assert run.code == 1 and run.lines[-1].endswith("3 of 3 files failed")
    assert run.lines[0].endswith(f"memory://{bucket}/bad/x.png cannot be decoded (corrupt, truncated or not a "
                                 "supported image)")
    assert "featurewarp-" not in run.stderr and "/tmp" not in run.stderr                # no local copy named
    assert f"--mask: memory://{bucket}/bad/y_mask.png does not exist" in run.lines[1]
    assert run.lines[2].endswith(f"memory://{bucket}/bad/none.png does not exist")
    assert not MEMORY.exists(f"/{bucket}/bad-out") or MEMORY.ls(f"/{bucket}/bad-out") == []


@pytest.mark.parametrize("args, message", [
    (["zzz://b/a.png", "-o", "{tmp}/o"], "zzz://b/a.png: unknown protocol zzz:// (not one fsspec knows)"),
    (["memory://{bucket}/photos/*.tif", "-o", "{tmp}/o"], "memory://{bucket}/photos/*.tif matches nothing"),
    (["{tmp}/photos/a.png", "-o", "sftp://host/out"], 'sftp:// needs paramiko: pip install paramiko'),
    (["memory://{bucket}/photos/a.png", "memory://{bucket}/photos/b.jpg", "-o", "{tmp}/o", "-j", "2"],
     "memory:// lives in this process only"),
])
def test_url_usage_errors_are_one_line(runner, tmp_path, bucket, args, message):
    if "sftp" in message and importlib.util.find_spec("paramiko"):
        pytest.skip("paramiko is installed here")
    fill = {"tmp": str(tmp_path), "bucket": bucket}
    run = runner("batch", "swirl", *[a.format(**fill) for a in args])
    assert run.code == 2 and len(run.lines) == 1 and message.format(**fill) in run.stderr, run.stderr


def test_a_missing_backend_names_the_package_to_install():
    if importlib.util.find_spec("s3fs"):
        pytest.skip("s3fs is installed here")
    with pytest.raises(ValueError, match=r"^s3:// needs s3fs: pip install s3fs$"):
        urls.filesystem("s3://bucket/a.jpg")


def test_paths_are_not_urls_and_never_reach_fsspec(runner, tmp_path, monkeypatch):
    for path in ("a.png", "/x/y.png", "./s3:/x.png", "C:\\x\\y.png", "png:out.png", "-"):
        assert not urls.is_url(path), path
    for url in ("s3://b/k.jpg", "memory://x", "file:///tmp/a.png", "simplecache::s3://b/k"):
        assert urls.is_url(url), url

    def no_fsspec(*args):
        raise AssertionError("a plain path reached fsspec")

    monkeypatch.setattr(urls, "filesystem", no_fsspec)
    folder = tmp_path / "photos"
    folder.mkdir()
    scene(folder, "a.png")
    run = runner("batch", "swirl", folder / "a.png", "-o", tmp_path / "out", "--resume")
    assert run.code == 0 and (tmp_path / "out" / "a.png").exists()


def test_put_is_whole_or_moved_into_place(tmp_path, monkeypatch):
    """file:// (no atomic put): a hidden temporary key moved onto the target, removed on failure."""
    target = (tmp_path / "o.png").as_uri()
    urls.put(target, b"complete")
    assert os.listdir(tmp_path) == ["o.png"] and (tmp_path / "o.png").read_bytes() == b"complete"
    fs = urls.filesystem(target)[0]

    def broken_move(*args, **kwargs):
        raise OSError(5, "Input/output error")

    monkeypatch.setattr(type(fs), "mv", broken_move)
    with pytest.raises(OSError):
        urls.put(target, b"half")
    assert os.listdir(tmp_path) == ["o.png"] and (tmp_path / "o.png").read_bytes() == b"complete"


def test_resume_without_times_runs_again(tmp_path, bucket, monkeypatch):
    job = batch.Job(f"memory://{bucket}/photos/a.png", f"memory://{bucket}/out/a.png", None)
    MEMORY.pipe_file(f"/{bucket}/out/a.png", b"x")
    assert batch.up_to_date(job)
    monkeypatch.setattr(urls, "modified", lambda url: None)                # a store that does not say
    assert not batch.up_to_date(job)


ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))


@pytest.mark.parametrize("jobs", ["1", "2"])
def test_a_signal_leaves_no_copies_of_url_inputs(tmp_path, jobs):
    """SIGINT while URL jobs run: each left its copies of the photo and mask in /tmp/featurewarp-*
    (the command and its --jobs workers exit at once)."""
    (tmp_path / "photos").mkdir()
    for i in range(6):                                  # big enough that a job lasts a while
        save(tmp_path / "photos" / f"p{i}.png", np.roll(textured((640, 480)), 7 * i, axis=1))
        save(tmp_path / "photos" / f"p{i}_mask.png", square_mask((640, 480)))
    temp = tmp_path / "tmp"
    temp.mkdir()
    process = subprocess.Popen([sys.executable, "-m", "featurewarp_cli", "batch", "swirl",
                                f"simplecache::{(tmp_path / 'photos').as_uri()}/*.png", "-o", str(tmp_path / "out"),
                                "--angle", "120", "-j", jobs], stderr=subprocess.PIPE,
                               env={**os.environ, "TMPDIR": str(temp), "PYTHONPATH": ROOT})

    def copies():
        return [name for name in os.listdir(temp) if name.startswith("featurewarp-")]

    try:
        deadline = time.monotonic() + 60
        while not copies():
            assert time.monotonic() < deadline and process.poll() is None, "no job started"
            time.sleep(0.002)
        process.send_signal(signal.SIGINT)
        _, stderr = process.communicate(timeout=60)
    finally:
        process.kill()
    assert (process.returncode, stderr) == (130, b"featurewarp: stopped by SIGINT\n")
    assert copies() == []


def test_copies_a_killed_process_left_are_removed_by_the_next_url_job(runner, tmp_path, bucket, monkeypatch):
    """A worker killed with SIGKILL leaves its copies; the next URL job on the machine removes those
    of processes that are gone, once a minute old (a folder of a live process, or a young one, stays)."""
    from featurewarp_cli.app import remote

    temp = tmp_path / "tmp"
    temp.mkdir()
    monkeypatch.setattr(tempfile, "tempdir", str(temp))
    monkeypatch.setattr(remote, "_swept", False)
    gone = int(subprocess.run([sys.executable, "-c", "import os; print(os.getpid())"], capture_output=True,
                              check=True).stdout)
    folders = {name: temp / (remote._folder_prefix(pid) + "x1") for name, pid in
               (("stale", gone), ("live", os.getpid()))}
    folders["young"] = temp / (remote._folder_prefix(gone) + "x2")
    for name, folder in folders.items():
        (folder / "input").mkdir(parents=True)
        (folder / "input" / "a.png").write_bytes(b"private photo")
        if name != "young":
            os.utime(folder, (time.time() - 120,) * 2)
    run = runner("batch", "swirl", f"memory://{bucket}/photos/a.png", "-o", tmp_path / "out", "--angle", "60")
    assert run.code == 0, run.stderr
    assert sorted(os.listdir(temp)) == sorted(folders[name].name for name in ("live", "young"))

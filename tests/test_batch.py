"""``featurewarp batch``: naming, masks, failures, progress, and --jobs giving identical files."""

from __future__ import annotations

import os
import pty
import subprocess
import sys

import numpy as np
import pytest

from featurewarp_cli.app import batch
from test_cli import listing, runner, save, scene, square_mask, textured  # noqa: F401  (fixture)


@pytest.fixture
def photos(tmp_path):
    """Three images with masks in tmp_path/photos (one jpg), and an empty tmp_path/out."""
    folder = tmp_path / "photos"
    folder.mkdir()
    (tmp_path / "out").mkdir()
    for name in ("a.png", "b.png", "c.jpg"):
        scene(folder, name)
    return folder


def names(folder) -> list[str]:
    return sorted(os.listdir(folder))


def test_batch_warps_every_input_with_its_mask(runner, photos, tmp_path):
    inputs = sorted(str(p) for p in photos.iterdir())           # masks included, as a glob gives them
    run = runner("batch", "swirl", *inputs, "--out-dir", tmp_path / "out", "--angle", "45")
    assert (run.code, run.stderr, run.stdout) == (0, "", b"")
    assert names(tmp_path / "out") == ["a.png", "b.png", "c.jpg"]
    single = runner("warp", "swirl", photos / "a.png", tmp_path / "a.png", "-m", photos / "a_mask.png",
                    "--angle", "45")
    assert single.code == 0
    assert (tmp_path / "a.png").read_bytes() == (tmp_path / "out" / "a.png").read_bytes()


def test_suffix_and_format(runner, photos, tmp_path):
    run = runner("batch", "stretch", photos / "a.png", photos / "c.jpg", "-o", tmp_path / "out",
                 "--suffix", "_wide", "--format", "webp", "--sx", "2")
    assert run.code == 0, run.stderr
    assert names(tmp_path / "out") == ["a_wide.webp", "c_wide.webp"]


def test_failures_are_one_line_each_and_the_rest_is_written(runner, photos, tmp_path):
    (photos / "broken.png").write_bytes(b"not a png")
    save(photos / "broken_mask.png", square_mask())
    save(photos / "lonely.png", textured())                      # no lonely_mask.png
    files = [photos / n for n in ("a.png", "broken.png", "lonely.png", "b.png")]
    run = runner("batch", "swirl", *files, "-o", tmp_path / "out")
    assert run.code == 1
    assert len(run.lines) == 3 and "Traceback" not in run.stderr
    assert "broken.png" in run.lines[0] and "cannot be decoded" in run.lines[0]
    assert "lonely.png" in run.lines[1] and "lonely_mask.png does not exist" in run.lines[1]
    assert run.lines[2] == "featurewarp: error: 2 of 4 files failed"
    assert names(tmp_path / "out") == ["a.png", "b.png"]


def test_mask_pattern_relative_to_each_input_or_absolute(runner, tmp_path):
    for sub in ("x", "y"):
        (tmp_path / sub).mkdir()
        save(tmp_path / sub / f"{sub}.png", textured())
        save(tmp_path / sub / f"masks-{sub}.png", square_mask())
    (tmp_path / "out").mkdir()
    run = runner("batch", "bulge", tmp_path / "x" / "x.png", tmp_path / "y" / "y.png", "-o", tmp_path / "out",
                 "--mask-pattern", "masks-{stem}.png")
    assert run.code == 0, run.stderr
    shared = save(tmp_path / "one_mask.png", np.zeros((36, 48), np.uint8))
    run = runner("batch", "bulge", tmp_path / "x" / "x.png", "-o", tmp_path / "out", "--suffix", "-abs",
                 "--mask-pattern", shared, "-v")
    assert run.code == 0 and "plain warp" in run.stderr            # the all-black absolute mask was used


def test_plain_mode_needs_no_masks(runner, tmp_path):
    src = save(tmp_path / "lone.png", textured())
    (tmp_path / "out").mkdir()
    assert runner("batch", "arc", src, "-o", tmp_path / "out", "--mode", "plain").code == 0


@pytest.mark.parametrize("args, words", [
    (["--out-dir", "{tmp}/a-file/out"], ["--out-dir", "cannot create"]),
    (["--out-dir", "{tmp}/out", "--mask-pattern", "{nope}.png"], ["--mask-pattern", "nope"]),
    (["--out-dir", "{tmp}/out", "--mask-pattern", "{stem.__class__}"], ["--mask-pattern", "only field"]),
    (["--out-dir", "{tmp}/out", "--mask-pattern", "{stem:>99999999}"], ["--mask-pattern", "only field"]),
    (["--out-dir", "{tmp}/out", "--jobs", "0"], ["--jobs", "out of range (1 <= N <= 1024)"]),
    (["--out-dir", "{tmp}/out", "--angle", "inf"], ["--angle", "finite"]),
    (["--out-dir", "{tmp}/out", "--background", "transparent", "--format", "bmp"], []),
    (["--out-dir", "{tmp}/out", "--suffix", "/x"], ["--suffix", "holds no '/'"]),     # each file failed
], ids=["out-dir under a file", "bad pattern", "attribute in pattern", "format spec in pattern", "no jobs",
        "inf angle", "transparent bmp", "suffix with a slash"])
def test_usage_errors(runner, photos, tmp_path, args, words):
    (tmp_path / "a-file").write_text("")
    run = runner("batch", "swirl", photos / "a.png", *[a.replace("{tmp}", str(tmp_path)) for a in args])
    if not words:                              # a per-file problem: every file fails, exit 1
        assert run.code == 1 and "no alpha" in run.stderr
        return
    assert run.code == 2 and len(run.lines) == 1
    for word in words:
        assert word in run.stderr
    assert names(tmp_path / "out") == []


def test_two_inputs_writing_the_same_output(runner, tmp_path):
    for sub in ("x", "y"):
        (tmp_path / sub).mkdir()
        save(tmp_path / sub / "a.png", textured())
    (tmp_path / "out").mkdir()
    run = runner("batch", "swirl", tmp_path / "x" / "a.png", tmp_path / "y" / "a.png", "-o", tmp_path / "out",
                 "--mode", "plain")
    assert run.code == 2 and "would both write" in run.stderr and names(tmp_path / "out") == []


def test_a_batch_never_replaces_a_file_it_reads_nor_its_summary(runner, photos, tmp_path):
    """``--summary`` naming an input or a mask overwrote it with JSON; an --out-dir that is the
    input's folder replaced the originals (and ``--resume`` then warped the warp again)."""
    before = {name: (photos / name).read_bytes() for name in names(photos)}
    for summary in (photos / "a.png", photos / "a_mask.png", tmp_path / "out" / "a.png"):
        run = runner("batch", "swirl", photos / "a.png", "-o", tmp_path / "out", "--summary", summary)
        assert run.code == 2 and "--summary" in run.stderr and "overwritten" in run.stderr, run.stderr
    (tmp_path / "links").mkdir()
    for name in ("a.png", "a_mask.png"):          # a hard link of one is that file: it was truncated
        summary = tmp_path / "links" / f"{name}.jsonl"
        os.link(photos / name, summary)
        run = runner("batch", "swirl", photos / "a.png", "-o", tmp_path / "out", "--summary", summary)
        assert run.code == 2 and "is also read by this batch" in run.stderr, run.stderr
    run = runner("batch", "swirl", photos / "a.png", "-o", photos)
    assert run.code == 2 and "replacing its own input" in run.stderr, run.stderr
    assert {name: (photos / name).read_bytes() for name in names(photos)} == before
    assert names(tmp_path / "out") == []
    run = runner("batch", "swirl", photos / "a_mask.png", "-o", tmp_path / "out", "--summary", photos / "a_mask.png")
    assert run.code == 2 and "--summary" in run.stderr and (photos / "a_mask.png").read_bytes() == before["a_mask.png"]
    run = runner("batch", "swirl", photos / "a_mask.png", "-o", tmp_path / "out")
    assert run.code == 2 and "no input left to warp" in run.stderr
    run = runner("batch", "swirl", photos / "a.png", "-o", photos, "--suffix", "_sw")
    assert run.code == 0 and "a_sw.png" in names(photos)


def test_files_named_as_masks_and_inputs_listed_twice(runner, photos, tmp_path):
    """A folder's other masks (``x_body_mask.png``) failed a ``photos/*.png`` batch as photos
    without masks; an input given twice was refused with advice (--suffix) that cannot help."""
    save(photos / "a_body_mask.png", np.zeros((40, 60), np.uint8))
    run = runner("batch", "swirl", *sorted(photos.iterdir()), photos / "a.png", "-o", tmp_path / "out")
    assert run.code == 0 and run.stderr.startswith("featurewarp: skipped 1 input(s) named as masks"), run.stderr
    assert "a_body_mask.png" in run.stderr and len(run.lines) == 1
    assert names(tmp_path / "out") == ["a.png", "b.png", "c.jpg"]
    scene(photos, "gas_mask.png")                        # a photo named like a mask, with its own mask
    run = runner("batch", "swirl", photos / "gas_mask.png", "-o", tmp_path / "gas")
    assert run.code == 0 and names(tmp_path / "gas") == ["gas_mask.png"], run.stderr
    for sub in ("x", "y"):
        (tmp_path / sub).mkdir()
        save(tmp_path / sub / "d.png", textured())
    run = runner("batch", "swirl", tmp_path / "x" / "d.png", tmp_path / "y" / "d.png", "-o", tmp_path / "new",
                 "--suffix", "_s", "--mode", "plain")
    assert run.code == 2 and "rename one" in run.stderr and not (tmp_path / "new").exists(), run.stderr


def test_jobs_give_byte_identical_files(photos, tmp_path):
    """Every output format, serial in this process against two spawned worker processes."""
    settings = batch.Settings("bulge", {"strength": 0.8}, background="#204060")
    results = {}
    for workers in (1, 2):
        out = tmp_path / f"out{workers}"
        out.mkdir()
        jobs = [batch.Job(str(photos / name), str(out / f"{name[0]}.{fmt}"), str(photos / f"{name[0]}_mask.png"))
                for name in ("a.png", "c.jpg") for fmt in ("png", "jpg", "webp", "tiff", "bmp")]
        assert [error for _, error, _ in batch.run_batch(settings, jobs, workers)] == [None] * len(jobs)
        results[workers] = listing(out)
    assert results[1] == results[2] and len(results[1]) == 10


def test_progress_bar_only_on_a_terminal(photos, tmp_path):
    args = [sys.executable, "-m", "featurewarp_cli", "batch", "swirl", str(photos / "a.png"),
            str(photos / "b.png"), "-o", str(tmp_path / "out")]
    piped = subprocess.run(args, capture_output=True, timeout=120)
    assert (piped.returncode, piped.stderr) == (0, b"")
    leader, follower = pty.openpty()
    try:
        on_tty = subprocess.run(args, stdout=subprocess.PIPE, stderr=follower, timeout=120)
        os.close(follower)
        shown = os.read(leader, 65536)
    finally:
        os.close(leader)
    assert on_tty.returncode == 0 and b"warping" in shown and on_tty.stdout == b""


def test_plan_skips_masks_and_names_outputs(tmp_path):
    jobs = batch.plan(["p/a.png", "p/a_mask.png", "q/b.jpg"], str(tmp_path), "-w", "png")
    assert [(j.input, os.path.basename(j.output), j.mask) for j in jobs] == [
        ("p/a.png", "a-w.png", "p/a_mask.png"), ("q/b.jpg", "b-w.png", "q/b_mask.png")]
    assert batch.plan(["a.png"], str(tmp_path), mask_pattern=None)[0].mask is None


def test_run_job_never_raises(tmp_path):
    job = batch.Job(str(tmp_path / "missing.png"), str(tmp_path / "o.png"), None)
    error, summary = batch.run_job(batch.Settings("swirl"), job)
    assert "does not exist" in error and summary is None


def test_a_summary_that_cannot_be_written_is_refused_before_the_out_dir_is_made(runner, photos, tmp_path):
    """The usage error came after --out-dir had been created (an empty folder left behind)."""
    run = runner("batch", "swirl", photos / "a.png", "-o", tmp_path / "new", "--summary", tmp_path / "no" / "s.jsonl")
    assert run.code == 2 and "--summary" in run.stderr and "does not exist" in run.stderr, run.stderr
    assert not (tmp_path / "new").exists()


def test_a_quoted_pattern_is_expanded_as_the_shell_would(runner, photos, tmp_path):
    """``batch swirl 'photos/*.png'`` (quoted past the shell, or past its limit on arguments)
    said the pattern did not exist; URLs were expanded, local paths not."""
    run = runner("batch", "swirl", photos / "*.png", "-o", tmp_path / "out")
    assert run.code == 0 and names(tmp_path / "out") == ["a.png", "b.png"], run.stderr     # masks skipped
    run = runner("batch", "swirl", photos / "*.tif", "-o", tmp_path / "out")
    assert run.code == 2 and "matches no file" in run.stderr


def test_a_missing_out_dir_is_created(runner, photos, tmp_path):
    run = runner("batch", "swirl", photos / "a.png", "-o", tmp_path / "new" / "deeper", "--mode", "plain")
    assert run.code == 0 and names(tmp_path / "new" / "deeper") == ["a.png"]


def test_a_batch_reads_no_stdin_and_names_a_failed_file_once(runner, photos, tmp_path):
    """'-' was looked for as a file ('-: - does not exist'); a missing input was named twice."""
    run = runner("batch", "swirl", "-", "-o", tmp_path / "out", input=(photos / "a.png").read_bytes())
    assert run.code == 2 and len(run.lines) == 1 and "a batch reads no stdin" in run.stderr, run.stderr
    run = runner("batch", "swirl", photos / "a.png", photos / "ghost.png", "-o", tmp_path / "out")
    assert run.code == 1
    assert run.lines == [f"featurewarp: error: {photos / 'ghost.png'} does not exist",
                         "featurewarp: error: 1 of 2 files failed"]


def test_a_summary_that_cannot_be_written_is_named_and_stops_the_batch(runner, photos, tmp_path):
    """--summary /dev/full: 'OSError: [Errno 28] No space left on device', naming no file."""
    run = runner("batch", "swirl", photos / "a.png", photos / "b.png", photos / "c.jpg", "-o", tmp_path / "out",
                 "--summary", "/dev/full")
    assert run.code == 1
    assert run.lines == ["featurewarp: error: --summary: cannot write /dev/full (No space left on device); the batch "
                         "was stopped"]
    assert names(tmp_path / "out") == ["a.png"]


def test_resume_warps_again_what_other_settings_made(runner, photos, tmp_path):
    """--resume skipped outputs made with other settings (a 300-degree rigid swirl stayed as the
    90-degree result, CI findings 9): each --summary line records a stamp of the settings, and
    --resume skips an up-to-date output only where the summary it reads records it with these
    settings, input and mask; without a summary it says that it could not check."""
    import json

    out, summary = tmp_path / "out", tmp_path / "s.jsonl"
    files = [photos / "a.png", photos / "b.png"]

    def lines():
        return [json.loads(line) for line in summary.read_text().splitlines()]

    first = runner("batch", "swirl", *files, "-o", out, "--angle", "300", "--mode", "rigid", "--summary", summary)
    assert first.code == 0, first.stderr
    stamps = {line["settings"] for line in lines()}
    assert len(stamps) == 1 and next(iter(stamps)).startswith("sha256:")
    again = runner("batch", "swirl", photos / "a.png", "-o", out, "--angle", "90", "--resume", "--summary", summary)
    assert again.code == 0 and again.lines == [
        f"featurewarp: --resume: warping 1 up-to-date output(s) again, which {summary} does not record as made "
        f"with these settings, input and mask: {out / 'a.png'} (other settings)"]
    assert [(line["status"], line["settings"] in stamps) for line in lines()] == [("ok", False)]
    fresh = runner("batch", "swirl", photos / "a.png", "-o", tmp_path / "fresh", "--angle", "90")
    assert fresh.code == 0 and (out / "a.png").read_bytes() == (tmp_path / "fresh" / "a.png").read_bytes()
    same = runner("batch", "swirl", photos / "a.png", "-o", out, "--angle", "90", "--resume", "--summary", summary)
    assert (same.code, same.stderr, [line["status"] for line in lines()]) == (0, "", ["skipped"])
    unchecked = runner("batch", "swirl", *files, "-o", out, "--angle", "90", "--resume")
    assert unchecked.code == 0 and len(unchecked.lines) == 1
    assert unchecked.lines[0].startswith("featurewarp: warning: --resume skipped 2 output(s) by their times alone")
    older = {key: value for key, value in lines()[0].items() if key != "settings"}      # an earlier featurewarp's
    summary.write_text(json.dumps(older) + "\n")
    run = runner("batch", "swirl", photos / "a.png", "-o", out, "--angle", "90", "--resume", "--summary", summary)
    assert run.code == 0 and "warping 1 up-to-date output(s) again" in run.stderr


def test_a_strict_refusal_keeps_its_warnings_in_the_summary(tmp_path):
    """A file that --strict refused had "warnings": [] in its --summary line, the warning that
    caused it only inside "error" (smoke trial 4)."""
    import json
    import shutil

    from test_cli import Runner

    from pathlib import Path

    samples = Path(__file__).resolve().parent.parent / "samples"
    for name in ("closeup.png", "closeup_mask.png"):
        shutil.copy(samples / name, tmp_path / name)
    run = Runner()("batch", "swirl", tmp_path / "closeup.png", "--out-dir", tmp_path / "out", "--angle", "180",
                   "--strict", "--summary", tmp_path / "s.jsonl")
    line = json.loads((tmp_path / "s.jsonl").read_text().splitlines()[0])
    assert run.code == 1 and line["status"] == "failed" and "--strict" in line["error"]
    assert line["warnings"] and line["warnings"][0] in line["error"]

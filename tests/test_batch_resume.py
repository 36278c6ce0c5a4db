"""``batch --resume`` against its ``--summary`` (review of the app, findings 3 and 4): relative
paths are read in the folder of the run that wrote them, the message says what differs, and the
settings stamp is of the values' meaning (and the version), not of their spelling."""

from __future__ import annotations

import json

import pytest
from test_cli import runner, scene  # noqa: F401  (runner: a fixture)

from featurewarp_cli.app.pipeline import Settings
from featurewarp_cli.app.resume import settings_stamp


def test_resume_reads_the_summarys_paths_where_its_run_was(runner, tmp_path, monkeypatch):
    """Run again from another folder, the same files, mask and settings were warped again, the
    message blaming 'these settings, input and mask'."""
    (tmp_path / "in").mkdir()
    scene(tmp_path / "in", "a.png")
    monkeypatch.chdir(tmp_path)
    first = runner("batch", "swirl", "in/a.png", "-o", "out", "--mask-pattern", "{stem}_mask.png",
                   "--summary", "s.jsonl")
    assert first.code == 0, first.stderr
    monkeypatch.chdir(tmp_path / "in")
    again = runner("batch", "swirl", "a.png", "-o", "../out", "--mask-pattern", "{stem}_mask.png",
                   "--summary", "../s.jsonl", "--resume")
    assert (again.code, again.stderr) == (0, ""), again.stderr
    lines = [json.loads(line) for line in (tmp_path / "s.jsonl").read_text().splitlines()]
    assert [(line["status"], line["input"], line["dir"]) for line in lines] == [("skipped", "a.png", str(tmp_path / "in"))]
    other = runner("batch", "swirl", "a.png", "-o", "../out", "--mask-pattern", "{stem}_mask.png",
                   "--summary", "../s.jsonl", "--resume", "--angle", "30")
    assert other.code == 0 and other.stderr.rstrip().endswith("../out/a.png (other settings)"), other.stderr


def test_resume_says_which_of_input_and_mask_differs(runner, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    scene(tmp_path, "a.png")
    scene(tmp_path, "b.png")
    assert runner("batch", "swirl", "a.png", "-o", "out", "--mask-pattern", "{stem}_mask.png",
                  "--summary", "s.jsonl").code == 0
    lines = (tmp_path / "s.jsonl").read_text()
    (tmp_path / "s.jsonl").write_text(lines.replace('"a_mask.png"', '"b_mask.png"'))
    run = runner("batch", "swirl", "a.png", "-o", "out", "--mask-pattern", "{stem}_mask.png",
                 "--summary", "s.jsonl", "--resume")
    assert run.stderr.rstrip().endswith("out/a.png (other mask)"), run.stderr


@pytest.mark.parametrize("one, other", [
    ({"fmt": "jpg"}, {"fmt": "jpeg"}),
    ({"background": "white"}, {"background": "#FFF"}),
    ({"background": "white"}, {"background": " WHITE"}),
    ({}, {"params": {"center": "50%,50%"}}),
    ({"params": {"angle": 90.0}}, {"params": {"angle": 9e1}}),
    ({}, {"strict": True}),
])
def test_the_stamp_is_of_what_the_options_mean(one, other):
    """jpg and jpeg, white and #FFF, --center 50%,50% and none (the same bytes) stamped apart, and
    --strict, which only refuses, changed the stamp: a --resume re-warped everything."""
    assert settings_stamp(Settings("swirl", **one)) == settings_stamp(Settings("swirl", **other))


@pytest.mark.parametrize("one, other", [
    ({"fmt": "jpg"}, {"fmt": "png"}), ({"background": "white"}, {"background": "#FFE"}),
    ({}, {"params": {"center": "50%,51%"}}), ({}, {"params": {"angle": 90.001}}), ({}, {"mode": "rigid"}),
])
def test_the_stamp_still_tells_other_outputs_apart(one, other):
    assert settings_stamp(Settings("swirl", **one)) != settings_stamp(Settings("swirl", **other))


def test_the_stamp_has_the_version(monkeypatch):
    """After an upgrade that changes output bytes, --resume kept the old outputs."""
    import featurewarp_cli

    before = settings_stamp(Settings("swirl"))
    monkeypatch.setattr(featurewarp_cli, "__version__", "99.0.0")
    assert settings_stamp(Settings("swirl")) != before

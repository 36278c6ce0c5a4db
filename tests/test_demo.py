"""Issue 25 item 6: ``make demo`` shows the tool at its best, without a warning line but
those of the features a curved border cuts (the Makefile says why): they give way to keep the
warp's outline (issue 22 item 1), and the tool names them and nothing else.

The commands are the Makefile's own (``make -n demo``), run in this process through click's
``CliRunner`` at full size: the settings that keep every feature depend on the picture, so a
smaller copy would not check them. The quick start's commands are checked where
tests/test_readme.py runs them.
"""

from __future__ import annotations

import re
import shlex
import subprocess
from pathlib import Path

import pytest
from click.testing import CliRunner

from featurewarp_cli.cli.main import cli

ROOT = Path(__file__).resolve().parent.parent


def demo_commands() -> list[list[str]]:
    """The arguments of each ``featurewarp warp`` command of ``make demo``, as make expands them."""
    text = subprocess.run(["make", "-n", "-B", "-C", str(ROOT), "demo"], capture_output=True, text=True,
                          check=True).stdout
    lines = text.replace("\\\n", " ").splitlines()
    return [shlex.split(line)[1:] for line in lines if "featurewarp warp " in line]


def test_the_demo_warps_every_sample_with_every_preset():
    from featurewarp_cli import plugins

    made = {(args[1], Path(args[2]).stem) for args in demo_commands()}
    assert made == {(preset, sample) for preset in plugins.BUILTIN for sample in ("astronaut", "coins", "shapes")}


def given_way(said: list[str]) -> set[int]:
    """The features a warning says were cut by a border they could not follow."""
    found = set()
    for line in said:
        match = re.search(r"features? ([\d, ]+?) cut by a border that no similarity", line)
        if match:
            found |= {int(k) for k in match.group(1).split(",")}
    return found


def about_given_way(line: str, features: set[int]) -> bool:
    """Whether a warning line is one of what a feature that gave way to the border brings."""
    if "cut by a border that no similarity" in line:
        return True
    match = re.search(r"feature (\d+) \(\d+ quads\) not kept", line)
    if match:
        return int(match.group(1)) in features
    match = re.search(r"features? ([\d, ]+) moved towards the plain warp", line)
    return bool(match) and {int(k) for k in match.group(1).split(",")} <= features


@pytest.mark.slow
def test_the_demo_prints_no_warning(tmp_path, monkeypatch):
    """Every demo command exits 0 and says nothing but, for a frame-cut feature under a preset
    that curves the border, that it gave way (about 5 s of CPU for the 42 warps)."""
    monkeypatch.chdir(ROOT)
    noisy = []
    for args in demo_commands():
        args[3] = str(tmp_path / Path(args[3]).name)
        run = CliRunner().invoke(cli, args)
        said = [line for line in run.output.splitlines() if line.strip()]
        features = given_way(said)
        other = [line for line in said if not about_given_way(line, features)]
        if run.exit_code != 0 or other or (said and args[1] in ("stretch", "swirl", "bulge")):
            noisy.append(f"featurewarp {shlex.join(args)}: exit {run.exit_code}\n{run.output[:600]}")
    assert not noisy, "\n".join(noisy)

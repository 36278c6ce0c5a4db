"""Issue 25 item 6: ``make demo`` shows the tool at its best, without a warning line (the
Makefile says which settings and masks, and why).

The commands are the Makefile's own (``make -n demo``), run in this process through click's
``CliRunner`` at full size: the settings that keep every feature depend on the picture, so a
smaller copy would not check them. The quick start's commands are checked where
tests/test_readme.py runs them.
"""

from __future__ import annotations

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


@pytest.mark.slow
def test_the_demo_prints_no_warning(tmp_path, monkeypatch):
    """Every demo command exits 0 and prints nothing (about 5 s of CPU for the 42 warps)."""
    monkeypatch.chdir(ROOT)
    noisy = []
    for args in demo_commands():
        args[3] = str(tmp_path / Path(args[3]).name)
        run = CliRunner().invoke(cli, args)
        if run.exit_code != 0 or run.output.strip():
            noisy.append(f"featurewarp {shlex.join(args)}: exit {run.exit_code}\n{run.output[:600]}")
    assert not noisy, "\n".join(noisy)

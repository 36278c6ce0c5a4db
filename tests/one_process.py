"""Many command lines in one fresh process, for checks that need a process of their own (its
peak memory) but not one per case: Python starts and imports once instead of once per case.

Each command runs through the console script's entry point, ``featurewarp_cli.cli.main.main``,
with file descriptor 2 sent to a file of its own, so that its stderr holds what C libraries
write there too. What is reported for each: exit code, stderr, seconds, and the process's peak
resident memory so far (it only grows, so it bounds every command up to this one). The peak is
Linux's VmHWM, not ``ru_maxrss``: that one keeps the resident size of the process that forked
this one (a test worker's hundreds of MB), which exec does not reset.

    outcomes = run_commands([["warp", "stretch", "in.png", "out.png"], ...])
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import tempfile
import time
from dataclasses import dataclass


@dataclass
class Outcome:
    """One command's exit code, stderr text, seconds and the process's peak bytes after it."""

    returncode: int
    stderr: str
    seconds: float
    peak: int


def run_commands(commands: list[list[str]], timeout: float = 300, env: dict | None = None) -> list[Outcome]:
    """Run ``commands`` (argument lists without the program name) one after another in one new
    Python process (with environment ``env``, or this one's); their outcomes in the same order."""
    with tempfile.TemporaryDirectory() as folder:
        orders, results = os.path.join(folder, "commands.json"), os.path.join(folder, "outcomes.json")
        with open(orders, "w") as f:
            json.dump([[str(arg) for arg in command] for command in commands], f)
        run = subprocess.run([sys.executable, __file__, orders, results], capture_output=True, text=True,
                             timeout=timeout, env=env)
        assert run.returncode == 0, run.stderr[-3000:]
        with open(results) as f:
            return [Outcome(**outcome) for outcome in json.load(f)]


def peak_bytes() -> int:
    """This process's peak resident memory since it was started (VmHWM)."""
    with open("/proc/self/status") as status:
        for line in status:
            if line.startswith("VmHWM:"):
                return int(line.split()[1]) * 1024
    raise RuntimeError("no VmHWM in /proc/self/status")


def run_one(args: list[str]) -> dict:
    """Run one command in this process (fd 2 captured); its outcome as a dict."""
    from featurewarp_cli.cli.main import main

    with tempfile.TemporaryFile() as err:
        sys.stderr.flush()
        saved = os.dup(2)
        os.dup2(err.fileno(), 2)
        started = time.perf_counter()
        try:
            main(args)
            code = 0
        except SystemExit as exit_:
            code = exit_.code if isinstance(exit_.code, int) else 1
        finally:
            seconds = time.perf_counter() - started
            sys.stderr.flush()
            os.dup2(saved, 2)
            os.close(saved)
        err.seek(0)
        stderr = err.read().decode(errors="replace")
    return {"returncode": code, "stderr": stderr, "seconds": seconds, "peak": peak_bytes()}


if __name__ == "__main__":
    with open(sys.argv[1]) as f:
        todo = json.load(f)
    outcomes = [run_one(args) for args in todo]
    with open(sys.argv[2], "w") as f:
        json.dump(outcomes, f)

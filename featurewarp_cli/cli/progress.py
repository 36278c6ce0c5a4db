"""The progress line: in a terminal, a run that lasts more than a second says what it is doing.

``featurewarp: guard 2.4 s`` on stderr, redrawn in place as the stages go by (grid, factor,
guard, render, write: see :mod:`featurewarp_cli.stages`) and erased at the end. Nothing
is drawn when stderr is not a terminal, or with ``-q``.
"""

from __future__ import annotations

import contextlib
import sys
import threading
import time

import click

from .. import stages

#: Seconds before the line appears, and between redraws.
DELAY = 1.0
INTERVAL = 0.2


class ProgressLine:
    """Draws the current stage and the elapsed time on stderr from a background thread."""

    def __init__(self, stream=None):
        self.stream = stream or sys.stderr
        self.stage = "load"
        self.start = time.monotonic()
        self.drawn = False
        self.done = threading.Event()
        self.lock = threading.Lock()
        self.thread = threading.Thread(target=self._run, name="featurewarp-progress", daemon=True)

    def enter(self, name: str) -> None:
        self.stage = name

    def _run(self) -> None:
        if self.done.wait(DELAY):
            return
        while not self.done.is_set():
            with self.lock:
                if not self.done.is_set():
                    self._write(f"\rfeaturewarp: {self.stage} {time.monotonic() - self.start:.1f} s\033[K")
                    self.drawn = True
            self.done.wait(INTERVAL)

    def _write(self, text: str) -> None:
        try:
            self.stream.write(text)
            self.stream.flush()
        except (OSError, ValueError):
            self.done.set()

    def close(self) -> None:
        with self.lock:
            self.done.set()
            if self.drawn:
                self._write("\r\033[K")


@contextlib.contextmanager
def progress_line(quiet: bool):
    """Show the progress line while the block runs (in a terminal, unless ``quiet``)."""
    if quiet or sys.stderr is None or not sys.stderr.isatty():
        yield None
        return
    line = ProgressLine()
    stages.listen(line.enter)
    line.thread.start()
    try:
        yield line
    finally:
        stages.forget(line.enter)
        line.close()


def say(line: str) -> None:
    """One line on stderr, whatever the message holds (a file name with a newline stays on
    one line) and even when stderr is closed."""
    try:
        click.echo(line.replace("\r", "\\r").replace("\n", "\\n"), err=True)
    except (OSError, ValueError, AttributeError):
        pass

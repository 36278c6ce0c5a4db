"""Which stage a run is in, for a progress line: the engine and the pipeline announce their
stages here; a listener (the command line's progress line) hears them. Imports nothing."""

from __future__ import annotations

_listeners: list = []


def enter(name: str) -> None:
    """Announce that the stage ``name`` (grid, factor, solve, guard, render, write ...) begins."""
    for listener in _listeners:
        listener(name)


def listen(listener) -> None:
    """Call ``listener(name)`` at every stage."""
    _listeners.append(listener)


def forget(listener) -> None:
    """Stop calling ``listener``."""
    if listener in _listeners:
        _listeners.remove(listener)

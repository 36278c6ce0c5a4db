"""Which stage a run is in, for a progress line: the engine and the pipeline announce their
stages here; a listener (the command line's progress line) hears them. Also the one switch
for notices (``-q``). Imports nothing at module level."""

from __future__ import annotations

_listeners: list = []
_current = [None]


def enter(name: str) -> None:
    """Announce that the stage ``name`` (grid, factor, solve, guard, render, write ...) begins."""
    _current[0] = name
    for listener in _listeners:
        listener(name)


class within:
    """``with within(name, after):`` the stage ``name`` for the block, then the one it
    interrupted again (a factorization that the fold guard's release asks for is not the rest
    of the guard), or the one ``after`` maps it to (the grid's factorization: the solve)."""

    def __init__(self, name: str, after: dict | None = None):
        self.name, self.after, self.before = name, after or {}, None

    def __enter__(self):
        self.before = _current[0]
        enter(self.name)

    def __exit__(self, *exc):
        if self.before is not None:
            enter(self.after.get(self.before, self.before))


def listen(listener) -> None:
    """Call ``listener(name)`` at every stage."""
    _listeners.append(listener)


def forget(listener) -> None:
    """Stop calling ``listener``."""
    if listener in _listeners:
        _listeners.remove(listener)


#: Set by ``-q``: notices (one-time remarks such as a slower fallback) are not printed.
quiet = False


#: Notices given with ``once`` during this command (the command line clears it after each).
said: set = set()


def notice(text: str, once: bool = False) -> None:
    """Print a one-line notice on stderr (``featurewarp: text``) unless ``-q`` was given; with
    ``once``, only the first time in a command (a batch's files share an option's notice)."""
    import sys

    if quiet or sys.stderr is None or (once and text in said):
        return
    said.add(text)
    try:
        sys.stderr.write(f"featurewarp: {text}\n")
    except (OSError, ValueError):
        pass

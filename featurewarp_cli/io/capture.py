"""What C libraries (libpng, libjpeg, libtiff) print on stderr, collected instead of shown."""

from __future__ import annotations

import contextlib
import os
import sys
import tempfile
import threading


#: One capture at a time in the process: fd 2 is the process's, and two threads' captures that
#: ended out of order left stderr pointing at a deleted capture for good (an editor's /mask
#: decode beside an Export's). Reentrant: a capture inside a capture of the same thread.
_ONE_AT_A_TIME = threading.RLock()


@contextlib.contextmanager
def captured_stderr():
    """Collect what is printed on file descriptor 2 while the block runs (one block at a time
    in the process).

    Yields a list that holds the printed lines once the block has finished. Our own
    notices (lines starting with ``featurewarp:``, which another thread may print
    meanwhile) are shown afterwards instead of being collected.
    """
    with _ONE_AT_A_TIME:
        with _captured() as lines:
            yield lines


@contextlib.contextmanager
def _captured():
    lines: list[str] = []
    if sys.stderr is not None:
        sys.stderr.flush()                                          # our own messages stay visible
    try:
        saved = os.dup(2)
    except OSError:                                                 # no stderr at all
        yield lines
        return
    with _scratch() as tmp:
        _SAVED.append(saved)
        os.dup2(tmp.fileno(), 2)
        try:
            yield lines
        finally:
            os.dup2(saved, 2)
            _SAVED.remove(saved)
            os.close(saved)
            tmp.seek(0)
            printed = [line for line in tmp.read().decode(errors="replace").splitlines() if line.strip()]
            ours = [line for line in printed if line.startswith("featurewarp:")]
            if ours and sys.stderr is not None:
                sys.stderr.write("".join(line + "\n" for line in ours))
            lines.extend(line for line in printed if not line.startswith("featurewarp:"))


#: The descriptors stderr was saved to by the captures running now (fd 2 is the process's, so
#: one list for every thread): the first is the real stderr.
_SAVED: list[int] = []


def real_stderr() -> int:
    """The descriptor of the real stderr, also while a capture holds fd 2 (a signal handler's
    "stopped by SIGINT" written to fd 2 then went into the capture and was lost)."""
    return _SAVED[0] if _SAVED else 2


def _scratch():
    """A file in memory (Linux ``memfd_create``: no temporary directory needed, none may be
    writable), else a temporary file."""
    try:
        return os.fdopen(os.memfd_create("featurewarp-stderr", os.MFD_CLOEXEC), "w+b")
    except (AttributeError, OSError):
        return tempfile.TemporaryFile()

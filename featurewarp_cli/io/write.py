"""Writing outputs: atomically to a file, or to stdout; and the check that a path can be written."""

from __future__ import annotations

import os
import sys
import tempfile


def write_atomic(path: str, data: bytes) -> None:
    """Write ``data`` to ``path`` through a temporary file in the same directory.

    A failure at any point leaves no partial file and leaves an existing ``path`` untouched.
    """
    directory = os.path.dirname(os.path.abspath(path))
    fd, tmp = tempfile.mkstemp(prefix=".featurewarp-", suffix=".tmp", dir=directory)
    try:
        with os.fdopen(fd, "wb") as fh:
            fh.write(data)
        if os.path.exists(path):
            os.chmod(tmp, os.stat(path).st_mode & 0o777)
        else:
            umask = os.umask(0)
            os.umask(umask)
            os.chmod(tmp, 0o666 & ~umask)
        os.replace(tmp, path)
    except BaseException:
        if os.path.exists(tmp):
            os.unlink(tmp)
        raise


def write_output(path: str, data: bytes) -> None:
    """Write ``data`` to stdout for ``-``, else atomically to ``path``."""
    if path == "-":
        sys.stdout.buffer.write(data)
        sys.stdout.buffer.flush()
    else:
        write_atomic(path, data)


def check_writable(path: str) -> None:
    """Raise ValueError unless a file ``path`` can be created (its directory exists and is writable).

    Writability is probed by creating and removing a temporary file, which is
    also right for root and for read-only file systems.
    """
    directory = os.path.dirname(os.path.abspath(path))
    if not os.path.isdir(directory):
        raise ValueError(f"directory {directory} does not exist")
    if os.path.isdir(path):
        raise ValueError(f"{path} is a directory")
    try:
        tempfile.TemporaryFile(dir=directory).close()
    except OSError as err:
        raise ValueError(f"directory {directory} is not writable ({err.strerror or err})") from None

"""Writing outputs: staged, then all put in place together; through links; to devices and stdout.

A command's outputs (image, report, grid) are first *staged*: each one's bytes are
written where they can wait without being seen. Only when every output was staged
are they *committed*, one after another; any failure before that discards them all,
so every file that existed stays as it was (all or nothing).

Where an output goes, by what its path is now:

- a regular file, or nothing yet: replaced atomically. The bytes wait in an unnamed file
  (``O_TMPFILE``) beside the target, so an interrupted run leaves nothing, even under SIGKILL;
  at commit it gets a hidden name and is renamed over the target (else, or beyond
  :data:`OPEN_STAGED` outputs, a hidden file removed on failure, SIGTERM and SIGINT). A file
  holding these bytes stays (inode, owner; its time set to now); one nobody may write (``chmod
  a-w``) is refused, even for root. A symbolic link is followed: its target is replaced.
- ``/dev/stdout``, ``/dev/stderr``, ``/dev/fd/N``, ``/proc/self/fd/N``: this process's own
  descriptor, written where it stands (a shell's ``>> log`` appends, ``> file`` is not
  truncated again): it is never opened anew, which would truncate or replace the file the
  shell redirected it to (:func:`descriptor_of`).
- anything else that exists (a FIFO, a character device such as ``/dev/null`` or a
  terminal): opened and written directly, never replaced.
- ``-``: standard output.
"""

from __future__ import annotations

import contextlib
import errno
import fcntl
import io
import os
import re
import signal
import stat
import sys
import tempfile
from dataclasses import dataclass

#: Prefix of the hidden names of files waiting to be renamed into place.
TEMP_PREFIX = ".featurewarp-"


@dataclass
class Staged:
    """One output's bytes, ready to be put in place by :func:`commit`.

    Attributes
    ----------
    path : str
        Where the output goes, as the user named it.
    kind : {'file', 'direct', 'descriptor', 'stdout'}
        Replaced atomically; written directly (device, FIFO); written to this process's
        ``descriptor`` (``/dev/stderr``, ``/dev/fd/N``); standard output.
    target : str
        The file to replace (``path`` with symbolic links followed), for ``file``.
    fd : int or None
        The unnamed file holding the bytes (``O_TMPFILE``), for ``file``.
    temp : str or None
        The hidden temporary file holding them where ``O_TMPFILE`` is not available.
    data : bytes or None
        The bytes themselves (for ``file``: to leave a target that holds them in place).
    descriptor : int or None
        This process's descriptor the bytes go to, for ``descriptor`` (never closed here).
    """

    path: str
    kind: str
    target: str = ""
    fd: int | None = None
    temp: str | None = None
    data: bytes | None = None
    descriptor: int | None = None


def _mode_for(target: str) -> int:
    """Permissions for a replaced file: the old file's, else 0666 less the umask."""
    try:
        return os.stat(target).st_mode & 0o777
    except FileNotFoundError:
        umask = os.umask(0)
        os.umask(umask)
        return 0o666 & ~umask


def _write_all(fd: int, data: bytes) -> None:
    """All of ``data`` to ``fd``, waiting while it would block: an inherited descriptor may have
    been left non-blocking by the shell or a parent (node, some CI runners), and its file
    description is theirs too, so it is not changed."""
    import select

    view, waiting = memoryview(data), None
    while view:
        try:
            view = view[os.write(fd, view):]
        except BlockingIOError:
            if waiting is None:               # poll, not select: any descriptor number
                waiting = select.poll()
                waiting.register(fd, select.POLLOUT)
            waiting.poll()


def _write_stream(stream, data: bytes) -> None:
    """All of ``data`` to a binary stream, then flushed: unbuffered (``PYTHONUNBUFFERED``), stdout
    is a raw file whose ``write`` may take part of it (a full disk, a pipe closed early) and
    returns how much; the rest is written until that raises, so nothing is cut short silently."""
    view = memoryview(data)
    while view:
        written = stream.write(view)
        if not written:                   # None: a non-blocking stream that would block
            raise OSError(errno.EAGAIN, "standard output would block")
        view = view[written:]
    stream.flush()


def _stage_file(path: str, target: str, data: bytes, named: bool = False) -> Staged:
    """The bytes of a regular-file output in an unnamed file (else, or when ``named``, a hidden
    closed one) beside ``target``."""
    directory = os.path.dirname(target) or "."
    mode = _mode_for(target)
    try:
        fd = None if named else os.open(directory, os.O_TMPFILE | os.O_WRONLY | os.O_CLOEXEC, mode)
    except (AttributeError, OSError):
        fd = None
    if fd is not None:
        try:
            _write_all(fd, data)
            os.fchmod(fd, mode)
        except BaseException:
            os.close(fd)
            raise
        return Staged(path, "file", target, fd=fd, data=data)
    handle, temp = _pending_mkstemp(directory, ".tmp")
    try:
        _write_all(handle, data)
        os.fchmod(handle, mode)
    except BaseException:
        os.close(handle)
        os.unlink(temp)
        _PENDING.discard(temp)
        raise
    os.close(handle)
    return Staged(path, "file", target, temp=temp, data=data)


#: Seconds to wait after staging each output (tests use it to signal a run mid-write): a
#: number above 0 and at most :data:`STAGE_DELAY_MAX`; any other value is ignored.
STAGE_DELAY_VARIABLE = "FEATUREWARP_TEST_STAGE_DELAY"
STAGE_DELAY_MAX = 3600.0


def stage(path: str, data: bytes, named: bool = False) -> Staged:
    """Get ``data`` ready to go to ``path`` (see the module's docstring; ``named``: a regular
    file waits in a hidden named file, closed, not in an open unnamed one); OSError on failure."""
    staged = _stage(path, data, named)
    if stage_delay():
        __import__("time").sleep(stage_delay())
    return staged


def stage_delay() -> float:
    """The test hook's delay (:data:`STAGE_DELAY_VARIABLE`) in seconds; 0 where unset or unusable."""
    try:
        delay = float(os.environ.get(STAGE_DELAY_VARIABLE, "") or 0.0)
    except ValueError:
        return 0.0
    return delay if 0.0 < delay <= STAGE_DELAY_MAX else 0.0


def descriptor_of(path: str) -> int | None:
    """The descriptor of this process that ``path`` names: 1 for ``-`` and ``/dev/stdout``, 2 for
    ``/dev/stderr``, N for ``/dev/fd/N`` and ``/proc/self/fd/N`` (or this process's id for
    self); None for any other path."""
    if path == "-":
        return 1
    name = os.path.abspath(path)
    streams = {"/dev/stdin": 0, "/dev/stdout": 1, "/dev/stderr": 2}
    if name in streams:
        return streams[name]
    parts = name.split("/")
    own = ("self", "thread-self", str(os.getpid()))
    number = parts[-1] if re.fullmatch(r"0|[1-9][0-9]{0,8}", parts[-1]) else None   # as the kernel names them
    if number and (parts[1:-1] == ["dev", "fd"] or (len(parts) == 5 and parts[1] == "proc" and parts[2] in own
                                                    and parts[3] == "fd")):
        return int(number)
    return None


def _stage(path: str, data: bytes, named: bool = False) -> Staged:
    if path == "-":
        return Staged(path, "stdout", data=data)
    descriptor = descriptor_of(path)
    if descriptor is not None:
        return Staged(path, "descriptor", data=data, descriptor=descriptor)
    mode = _mode_of(path)
    if mode is not None and not stat.S_ISREG(mode):
        if stat.S_ISDIR(mode):
            raise IsADirectoryError(21, "Is a directory", path)
        return Staged(path, "direct", path, data=data)
    if mode is not None and read_only(mode):          # checked before the work too (check_writable)
        raise PermissionError(errno.EACCES, f"read-only file (mode {stat.S_IMODE(mode):o}): not replaced", path)
    return _stage_file(path, _replaced(path), data, named)


def read_only(mode: int) -> bool:
    """Whether ``mode`` (``st_mode``) is a regular file nobody may write (``chmod a-w``): such a file
    is never replaced, not even by root, whom :func:`os.access` lets write anything."""
    return stat.S_ISREG(mode) and not mode & 0o222


def _mode_of(path: str) -> int | None:
    """``st_mode`` of what ``path`` names, links followed (None: nothing there yet)."""
    with contextlib.suppress(FileNotFoundError, NotADirectoryError):
        return os.stat(path).st_mode
    return None


def _replaced(path: str) -> str:
    """The file an atomic write of ``path`` replaces: a link's target (the link stays)."""
    return os.path.realpath(path) if os.path.islink(path) else os.path.abspath(path)


def commit(outputs: list[Staged]) -> None:
    """Put every staged output in place (OSError naming the file on failure; the rest are discarded):
    streams (devices, FIFOs, stdout) first, files last, so ``/dev/full`` leaves every file as it was;
    SIGINT and SIGTERM wait while files are linked (one between two left an image new, its report old)."""
    held = None
    try:
        for output in sorted(outputs, key=lambda o: o.kind == "file"):
            if output.kind == "file" and held is None:
                held = signal.pthread_sigmask(signal.SIG_BLOCK, {signal.SIGINT, signal.SIGTERM})
            _commit_one(output)
    finally:
        discard(outputs)
        if held is not None:
            signal.pthread_sigmask(signal.SIG_SETMASK, held)


def _write_stdout(data: bytes) -> None:
    """``data`` to standard output; an OSError names ``stdout`` (not another output of the command)."""
    try:
        stream, fd = sys.stdout.buffer, None
        sys.stdout.flush()
        with contextlib.suppress(io.UnsupportedOperation):   # no descriptor (a test's BytesIO): the stream
            fd = stream.fileno()              # a descriptor: written whole, waiting if non-blocking
        _write_stream(stream, data) if fd is None else _write_all(fd, data)
    except (AttributeError, ValueError):
        raise OSError(9, "standard output is closed", "stdout") from None
    except OSError as err:                    # flushing what was printed before, too
        raise OSError(err.errno, err.strerror, "stdout") from None


#: Seconds to wait for a process to open a FIFO output for reading before giving up.
FIFO_WAIT = 10.0


def _write_direct(path: str, data: bytes) -> None:
    """Write to an existing device or FIFO (a FIFO with no reader: an error after :data:`FIFO_WAIT`)."""
    try:
        mode = _mode_of(path)
        fd = _open_fifo(path) if mode is not None and stat.S_ISFIFO(mode) else \
            os.open(path, os.O_WRONLY | os.O_CLOEXEC)
        try:
            _write_all(fd, data)
        finally:
            os.close(fd)
    except OSError as err:
        raise OSError(err.errno, err.strerror, path) from None


def _open_fifo(path: str) -> int:
    """A blocking write descriptor of a FIFO, once a reader has it open (ENXIO after the wait)."""
    import time

    deadline = time.monotonic() + FIFO_WAIT
    while True:
        try:
            fd = os.open(path, os.O_WRONLY | os.O_NONBLOCK | os.O_CLOEXEC)
        except OSError as err:
            if err.errno != errno.ENXIO:
                raise
            if time.monotonic() > deadline:
                raise OSError(errno.ENXIO, f"no process reads this FIFO (waited {FIFO_WAIT:g} s)", path) from None
            time.sleep(0.05)
            continue
        os.set_blocking(fd, True)
        return fd


def _commit_one(output: Staged) -> None:
    if output.kind == "stdout":
        _write_stdout(output.data)
    elif output.kind == "direct":
        _write_direct(output.target, output.data)
    elif output.kind == "descriptor":
        for stream in (sys.stdout, sys.stderr):          # what Python buffered for it goes first
            if stream is not None and not stream.closed:
                stream.flush()
        try:
            _write_all(output.descriptor, output.data)
        except OSError as err:
            raise OSError(err.errno, err.strerror, output.path) from None
    else:
        try:
            if not (_holds(output.target, output.data) and _touched(output.target)):
                _put_in_place(output)
        except OSError as err:                  # named as the output, not as the hidden staging file
            raise OSError(err.errno, err.strerror, output.path) from None


def _touched(path: str) -> bool:
    """Whether ``path``'s times could be set to now (a file of another owner's may refuse)."""
    try:
        os.utime(path)
    except OSError:
        return False
    return True


def _holds(path: str, data: bytes) -> bool:
    """Whether ``path`` is a regular file holding exactly ``data`` (read only when the sizes agree),
    so that a rerun leaves an unchanged output in place: hard links, the inode and the owner stay;
    its time is set to now (left alone, make would find the rule's target older than the input
    that changed and run it again on every call)."""
    try:
        fd = os.open(path, os.O_RDONLY | os.O_NONBLOCK | os.O_CLOEXEC)
    except OSError:
        return False
    try:
        info = os.fstat(fd)
        if not stat.S_ISREG(info.st_mode) or info.st_size != len(data):
            return False
        view, done = memoryview(data), 0
        while done < len(data):
            piece = os.read(fd, 1 << 20)
            if not piece or piece != view[done:done + len(piece)]:
                return False
            done += len(piece)
        return not os.read(fd, 1)
    except OSError:
        return False
    finally:
        os.close(fd)


def _put_in_place(output: Staged) -> None:
    """Rename a staged file output (an unnamed file linked first, or a named temporary) onto its target."""
    if output.fd is not None:
        temp = os.path.join(os.path.dirname(output.target), f"{TEMP_PREFIX}{os.getpid()}-{id(output)}.tmp")
        _PENDING.add(temp)
        try:
            _link_unnamed(output.fd, temp)
            os.replace(temp, output.target)
        finally:
            remove_quietly(temp)
            _PENDING.discard(temp)
    else:
        os.replace(output.temp, output.target)
        _PENDING.discard(output.temp)
        output.temp = None


#: linkat(2) flags and the "current directory" file descriptor (Linux).
_AT_FDCWD, _AT_SYMLINK_FOLLOW = -100, 0x400


def _link_unnamed(fd: int, path: str) -> None:
    """Give the unnamed file ``fd`` the name ``path``: linkat through /proc/self/fd, following
    the link (``os.link`` does not follow it on Linux and fails with EXDEV)."""
    import ctypes

    libc = ctypes.CDLL(None, use_errno=True)
    if libc.linkat(_AT_FDCWD, f"/proc/self/fd/{fd}".encode(), _AT_FDCWD, os.fsencode(path), _AT_SYMLINK_FOLLOW):
        error = ctypes.get_errno()
        raise OSError(error, os.strerror(error), path)


def discard(outputs: list[Staged]) -> None:
    """Drop what was staged and not committed (idempotent)."""
    for output in outputs:
        if output.fd is not None:
            os.close(output.fd)
            output.fd = None
        if output.temp is not None:
            remove_quietly(output.temp)
            _PENDING.discard(output.temp)
            output.temp = None


#: Outputs of one command beyond which each waits in a closed hidden file instead of an open
#: unnamed one (a 1100-frame sequence ran out of descriptors under ``ulimit -n 1024``).
OPEN_STAGED = 256


def write_outputs(items: list[tuple[str, bytes]]) -> None:
    """Stage every (path, bytes), then commit them all; nothing changes if staging fails."""
    staged, named = [], len(items) > OPEN_STAGED
    try:
        for path, data in items:
            staged.append(stage(path, data, named))
    except BaseException:
        discard(staged)
        raise
    commit(staged)


def write_atomic(path: str, data: bytes) -> None:
    """Write one output (see :func:`stage`): a failure leaves an existing ``path`` untouched."""
    write_outputs([(path, data)])


def remove_quietly(path: str) -> None:
    """Remove ``path`` if it is there."""
    with contextlib.suppress(OSError):
        os.unlink(path)


#: Hidden temporary files that exist right now (removed by :func:`remove_pending` on a signal).
_PENDING: set[str] = set()


def _pending_mkstemp(directory: str, suffix: str) -> tuple[int, str]:
    """:func:`tempfile.mkstemp` in ``directory``, its path in :data:`_PENDING` before a signal can
    come between the two (SIGINT and SIGTERM are held for them): the handlers remove only what
    is pending, and a file staged while Ctrl-C came (registered after it was written) was left."""
    held = signal.pthread_sigmask(signal.SIG_BLOCK, {signal.SIGINT, signal.SIGTERM})
    try:
        fd, path = tempfile.mkstemp(prefix=TEMP_PREFIX, suffix=suffix, dir=directory)
        _PENDING.add(path)
    finally:
        signal.pthread_sigmask(signal.SIG_SETMASK, held)
    return fd, path


def remove_pending() -> None:
    """Remove every hidden temporary file this process has not put in place (signal handlers)."""
    for path in list(_PENDING):
        remove_quietly(path)
    _PENDING.clear()


@contextlib.contextmanager
def temporary_file(directory: str, suffix: str = ""):
    """The path of a new hidden temporary file in ``directory`` (for an encoder that writes only to
    a named file), removed on leaving and by the signal handlers (:func:`remove_pending`)."""
    fd, path = _pending_mkstemp(directory, suffix)
    os.close(fd)
    try:
        yield path
    finally:
        remove_quietly(path)
        _PENDING.discard(path)


def _check_name_length(path: str) -> None:
    """ValueError naming the part of ``path`` longer than the file system takes (255 bytes a
    name, 4096 a path on Linux), with a long path shortened in the message."""
    shown = path if len(path) <= 120 else f"{path[:60]}...{path[-40:]}"
    encoded = os.fsencode(path)
    if len(encoded) >= 4096:
        raise ValueError(f"{shown}: path too long ({len(encoded)} bytes; at most 4095)")
    longest = max((os.fsencode(part) for part in path.split(os.sep)), key=len)
    if len(longest) > 255:
        raise ValueError(f"{shown}: file name too long ({len(longest)} bytes; at most 255)")


def check_writable(path: str) -> None:
    """Raise ValueError unless ``path`` can be written: a file that can be created or replaced in
    an existing, writable folder, or an existing device, FIFO or link to one.

    Writability of a folder is probed by creating and removing a temporary file, which is
    also right for root and for read-only file systems.
    """
    descriptor = descriptor_of(path)
    if descriptor is not None:
        try:
            flags = fcntl.fcntl(descriptor, fcntl.F_GETFL)
        except OSError:
            raise ValueError(f"{path}: descriptor {descriptor} is not open") from None
        if flags & os.O_ACCMODE == os.O_RDONLY:
            raise ValueError(f"{path}: descriptor {descriptor} is not open for writing")
        return
    _check_name_length(path)
    mode = _mode_of(path)
    if mode is not None and stat.S_ISDIR(mode):
        raise ValueError(f"{path} is a directory")
    if mode is not None and read_only(mode):                    # root too: os.access lets root write anything
        raise ValueError(f"{path} is read-only (mode {stat.S_IMODE(mode):o}): not replaced; chmod u+w it or "
                         "give another name")
    if mode is not None and not os.access(path, os.W_OK):       # a read-only file is not replaced, as cp would not
        raise ValueError(f"{path} is not writable by you (read-only, or another user's): give another name")
    if mode is not None and not stat.S_ISREG(mode):
        return
    directory = os.path.dirname(_replaced(path))
    if not os.path.isdir(directory):
        raise ValueError(f"directory {directory} does not exist")
    try:
        tempfile.TemporaryFile(dir=directory).close()
    except OSError as err:
        raise ValueError(f"directory {directory} is not writable ({err.strerror or err})") from None

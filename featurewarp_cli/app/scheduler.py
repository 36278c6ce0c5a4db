"""The Dask scheduler that ``featurewarp batch --scheduler VALUE`` names, and a client of it.

VALUE is ``local:N`` (a local cluster of N worker processes, started and stopped by the
command), an address (``tcp://host:8786``, ``host:8786``, ``tls://``, ``ws://``, ``wss://``),
or a scheduler file as ``dask scheduler --scheduler-file`` writes it (any name: an existing
file is read as one). :func:`resolve` checks VALUE before anything is read or written: a
value that cannot name a scheduler is a usage error (exit 2). :func:`connect` then asks the
scheduler who it is, within :data:`CONNECT_TIMEOUT` seconds: a scheduler that cannot be
reached, or a server that is not a Dask scheduler (the dashboard's port, an SSH or HTTP
server), fails the command in one line (exit 1). A scheduler without workers is waited for,
as a cluster whose workers are still queued needs: after :data:`WORKERS_NOTICE` seconds the
command says so once on stderr, and Ctrl-C or SIGTERM stops it.
"""

from __future__ import annotations

import json
import logging
import os
from dataclasses import dataclass

from .pipeline import WarpError

#: ``--scheduler local:N`` starts a local cluster of N single-threaded worker processes.
LOCAL_PREFIX = "local:"
#: Dask settings of the workers ``local:N`` starts: no statistical profiler sampling the
#: solve's thread every 10 ms (it holds the GIL; a few % of a batch). Workers started by
#: hand take the same from ``DASK_DISTRIBUTED__WORKER__PROFILE__ENABLED=False``. The
#: scheduler's HTTP server, which Dask always starts, serves nothing (no dashboard).
LOCAL_CONFIG = {"distributed.worker.profile.enabled": False, "distributed.scheduler.http.routes": []}
#: Seconds to wait for a scheduler to answer.
CONNECT_TIMEOUT = 20
#: Seconds a scheduler without workers is given before the command says it waits for them.
WORKERS_NOTICE = 3
#: Protocols featurewarp connects with (``tls`` and ``wss`` with Dask's TLS settings).
PROTOCOLS = ("tcp", "tls", "ws", "wss")
ENCRYPTED = ("tls", "wss")
#: Largest scheduler file read (Dask's are a few hundred bytes).
FILE_BYTES = 1 << 20


@dataclass(frozen=True)
class Target:
    """What ``--scheduler`` names.

    Attributes
    ----------
    value : str
        As given (messages name it).
    local : int
        N of ``local:N``; 0 for a remote scheduler.
    address : str or None
        A remote scheduler's address (from the scheduler file when ``value`` is one).
    """

    value: str
    local: int = 0
    address: str | None = None


def distributed_module():
    """The ``distributed`` module, or a usage error that says how to install it."""
    try:
        import distributed
    except ImportError:
        raise WarpError("needs Dask: pip install 'featurewarp[dask]' (dask.distributed)", "--scheduler",
                        usage=True) from None
    return distributed


def local_workers(scheduler: str) -> int:
    """N of ``local:N``: the processes on this machine that share its memory (0 when N is not
    a whole number); 1 for any other scheduler (its workers have machines of their own)."""
    if not scheduler.startswith(LOCAL_PREFIX):
        return 1
    count = scheduler[len(LOCAL_PREFIX):]
    return int(count) if count.isdigit() else 0


def _usage(message: str) -> WarpError:
    return WarpError(message, "--scheduler", usage=True)


def resolve(value: str) -> Target:
    """What ``--scheduler VALUE`` names; a usage error for a value that cannot name a scheduler.

    Parameters
    ----------
    value : str
        ``local:N``, an address, or the path of a scheduler file.

    Returns
    -------
    Target

    Raises
    ------
    WarpError
        Dask missing, ``local:N`` outside 1..1024, a malformed address or a protocol featurewarp
        cannot use, a scheduler file that is missing or holds no address (all usage errors).
    """
    distributed_module()
    if not value.strip():
        raise _usage("an empty value names no scheduler (tcp://HOST:PORT, a scheduler file or local:N)")
    if value.startswith(LOCAL_PREFIX):
        count = local_workers(value)
        if not 1 <= count <= 1024:
            raise _usage(f"{value!r}: local:N takes a number of workers from 1 to 1024")
        return Target(value, local=count)
    if "://" not in value and os.path.lexists(value):
        return Target(value, address=_checked(_address_in_file(value), f" (in the scheduler file {value})"))
    if "://" not in value and (value.lower().endswith(".json") or ":" not in value):
        raise _usage(f"{value}: no such scheduler file (nor an address: tcp://HOST:PORT)")
    return Target(value, address=_checked(value))


def _address_in_file(path: str) -> str:
    """The scheduler address a scheduler file holds (its JSON ``address``)."""
    if os.path.isdir(path):
        raise _usage(f"{path} is a folder, not a scheduler file")
    try:
        with open(path, "rb") as file:
            text = file.read(FILE_BYTES)
    except OSError as err:
        raise _usage(f"cannot read the scheduler file {path} ({err.strerror or err})") from None
    try:
        info = json.loads(text)
    except ValueError:
        info = None
    address = info.get("address") if isinstance(info, dict) else None
    if not isinstance(address, str) or not address:
        raise _usage(f"{path} is not a Dask scheduler file (no JSON 'address' in it, as 'dask scheduler "
                     "--scheduler-file' writes)")
    return address


def _checked(address: str, where: str = "") -> str:
    """``address`` if featurewarp can connect to it; a usage error if not (``where``: the scheduler
    file it came from, for the message)."""
    from distributed.comm.addressing import parse_address, parse_host_port

    try:
        protocol, location = parse_address(address, strict=False)
        port = parse_host_port(location)[1]
    except (ValueError, TypeError):
        port, protocol = None, None
    if not isinstance(port, int) or not 0 < port < 65536:
        raise _usage(f"{address!r}{where} is not a scheduler address: give tcp://HOST:PORT, a scheduler file "
                     "or local:N")
    if protocol not in PROTOCOLS:
        raise _usage(f"{address!r}{where}: {protocol}:// is not supported; use tcp://, tls://, ws:// or wss://")
    if protocol in ENCRYPTED and _connection_args().get("ssl_context") is None:
        raise _usage(f"{address!r}{where}: {protocol}:// needs Dask's TLS settings (distributed.comm.tls: "
                     "ca-file, client.cert and client.key, e.g. DASK_DISTRIBUTED__COMM__TLS__CA_FILE)")
    return address


def _connection_args() -> dict:
    from distributed.security import Security

    return Security().get_connection_args("client")


async def _identity(address: str, timeout: float):
    """The answer to ``identity``: its ``type`` says what the server is (``Scheduler``, ``Worker``)."""
    from distributed.comm import connect as open_comm

    comm = await open_comm(address, timeout=timeout, **_connection_args())
    try:
        await comm.write({"op": "identity", "reply": True})      # a worker answers it too
        return await comm.read()
    finally:
        comm.abort()


def identify(target: Target, timeout: float | None = None) -> dict:
    """Ask the scheduler at ``target.address`` who it is, within ``timeout`` seconds overall.

    Dask's own connect waits for a handshake without a time limit: a server that listens but is
    not a Dask scheduler (the dashboard's port, any HTTP server) kept the command waiting forever.

    Returns
    -------
    dict
        The scheduler's identity (``n_workers`` among its keys).

    Raises
    ------
    WarpError
        The scheduler cannot be reached, or what answers is not a Dask scheduler (exit 1).
    """
    import asyncio

    timeout = CONNECT_TIMEOUT if timeout is None else timeout
    shown = target.value if target.address == target.value else f"{target.address} (from {target.value})"
    try:
        # the connection is given a second less than the whole, so that an unreachable
        # scheduler is told apart from a server that takes the connection and never answers
        reply = asyncio.run(asyncio.wait_for(_identity(target.address, max(0.5, timeout - 1)), timeout))
    except asyncio.TimeoutError:
        raise WarpError(f"{shown} is not a Dask scheduler: it took the connection but gave no answer in "
                        f"{timeout:g} s (the dashboard's port, often 8787, is not the scheduler's, often 8786)",
                        "--scheduler") from None
    except OSError as err:
        if not str(err).startswith("Timed out trying to connect"):
            raise WarpError(f"{shown} is not a Dask scheduler: it closed the connection", "--scheduler") from None
        raise WarpError(f"cannot reach the Dask scheduler at {shown} ({_reason(err, timeout)})",
                        "--scheduler") from None
    except Exception:                       # a service that speaks first: its bytes read as a frame length
        raise WarpError(f"{shown} is not a Dask scheduler: it answered in another protocol",
                        "--scheduler") from None
    kind = reply.get("type") if isinstance(reply, dict) else None
    if kind != "Scheduler":
        what = "a Dask worker, not the scheduler" if kind == "Worker" else "not a Dask scheduler"
        raise WarpError(f"{shown} is {what}", "--scheduler")
    return reply


def _reason(err: OSError, timeout: float) -> str:
    """Why Dask could not connect: the system's words (Connection refused, Name or service not
    known) from the errors behind its own, else that nothing answered."""
    reason, seen = f"nothing answered in {timeout:g} s", set()
    while err is not None and id(err) not in seen:
        seen.add(id(err))
        if getattr(err, "strerror", None):
            reason = err.strerror
        err = err.__cause__ or err.__context__
    return reason


def connect(target: Target, verbose: bool = False):
    """A ``distributed.Client`` of ``target``'s scheduler with at least one worker, and the local
    cluster it started (or None).

    Parameters
    ----------
    target : Target
        From :func:`resolve`.
    verbose : bool
        Let the local cluster's Dask log lines through (else they are silenced).

    Returns
    -------
    (distributed.Client, distributed.LocalCluster or None)

    Raises
    ------
    WarpError
        As :func:`identify`.
    """
    distributed = distributed_module()
    if target.local:
        import dask

        with dask.config.set(LOCAL_CONFIG):
            cluster = distributed.LocalCluster(
                n_workers=target.local, threads_per_worker=1, processes=True, dashboard_address=None,
                scheduler_kwargs={"dashboard_address": "127.0.0.1:0"},    # Dask's HTTP server: no fixed port
                silence_logs=logging.WARNING if verbose else logging.CRITICAL + 1)
        return distributed.Client(cluster, set_as_default=False), cluster
    identity = identify(target)
    try:
        client = distributed.Client(target.address, timeout=CONNECT_TIMEOUT, set_as_default=False)
    except (OSError, TimeoutError) as err:
        raise WarpError(f"cannot reach the Dask scheduler at {target.value} ({err})", "--scheduler") from None
    if not identity.get("n_workers"):
        _wait_for_workers(client, target)
    return client, None


def _wait_for_workers(client, target: Target) -> None:
    """Wait for the scheduler's first worker: a short while in silence, then saying so once."""
    from .. import stages

    try:
        client.wait_for_workers(1, timeout=WORKERS_NOTICE)
        return
    except TimeoutError:                      # asyncio's too, from Python 3.11
        pass
    stages.notice(f"waiting for workers on {target.value}: the Dask scheduler has none yet (Ctrl-C stops)")
    client.wait_for_workers(1)

"""Listening: TCP and Unix listeners, and the accept loop every server of aiortu runs.

[`serve_listener`][aiortu.transport.serve_listener] is the one accept loop of the Modbus TCP
server, the RTU-over-TCP server, the gateway and its metrics responder. What it decides:

- **A limit.** At most `ConnectionLimit.max_connections` connections at once; one over the
  limit is closed at once and counted, and the refusals of one burst are logged once (until a
  connection closes), as a warning at most once in `WARNING_INTERVAL` seconds and at debug
  level in between: a client that opens and closes connections at the limit costs counts, not
  log lines.
- **Back-pressure from the first byte.** anyio's asyncio backend leaves an accepted TCP
  connection reading until its first `receive()` waits, so a client that streams requests
  before then fills the process without bound. The loop pauses reading on the transport right
  after `accept()`, as anyio's own `connect_tcp` does: from then on bytes are read only while
  the server asks for them, and TCP holds the client back.
- **Running out of file descriptors.** An `accept()` that fails (EMFILE, ENFILE, ENOBUFS,
  ENOMEM) backs off (10 ms, doubling to 1 s) and is logged once until a connection is
  accepted again (a warning at most once in `WARNING_INTERVAL`): the listener survives, the
  pending client waits in the backlog.
- **A client gone before it was served** (reset in the backlog: no peer address) is closed
  and not counted.
- **TLS.** A listener with a handshake ([`TlsListener`][aiortu.transport.TlsListener]) is
  accepted from by the same loop, with the same limit and back-off, and each connection's
  handshake runs in its task: a connection counts against the limit from its accept, so that
  clients that never finish their handshake hold at most `max_connections` descriptors.
"""

from __future__ import annotations

import asyncio
import errno
import grp
import logging
import math
import os
import socket
import stat
from collections.abc import Awaitable, Callable
from dataclasses import dataclass, field
from typing import Any, Final, Protocol, runtime_checkable

import anyio
import anyio.abc
from anyio.abc import SocketStream
from anyio.streams.stapled import MultiListener

from aiortu._log import get_logger
from aiortu.errors import InvalidValue, PortBusy, PortError, PortNotFound, PortPermissionDenied

__all__ = (
    "AcceptCounters",
    "ConnectionCounters",
    "ConnectionLimit",
    "UnixAddress",
    "after_handshake",
    "listen_tcp",
    "listen_unix",
    "listening_address",
    "parse_unix_url",
    "peer_address",
    "remove_socket",
    "serve_listener",
    "write_now",
)

_log = get_logger(__name__)

UNIX_PREFIX: Final = "unix:"
"""What starts a Unix socket listen URL."""

_ACCEPT_ERRORS = frozenset({errno.EMFILE, errno.ENFILE, errno.ENOBUFS, errno.ENOMEM})
WARNING_INTERVAL: Final = 60.0
"""The fewest seconds between two warnings of one kind from one accept loop (refusals over the
limit, failed accepts); those in between are logged at debug level."""
_FIRST_BACK_OFF = 0.01
_LAST_BACK_OFF = 1.0
_GONE = (anyio.EndOfStream, anyio.BrokenResourceError, anyio.ClosedResourceError)

Handler = Callable[[anyio.abc.ByteStream], Awaitable[object]]


@runtime_checkable
class _Handshaking(Protocol):
    """A listener whose connections need a handshake before they are served (TLS)."""

    listener: anyio.abc.Listener[Any]

    async def handshake(self, stream: anyio.abc.ByteStream) -> anyio.abc.ByteStream | None: ...


class ConnectionCounters(Protocol):
    """The counters a server's accept loop keeps (the server's own counters record)."""

    connections_accepted: int
    """Connections served."""
    connections_refused: int
    """Connections closed at once because the most allowed were open."""


@dataclass(slots=True)
class AcceptCounters:
    """[`ConnectionCounters`][aiortu.transport.ConnectionCounters] for a server with no
    record of its own."""

    connections_accepted: int = 0
    """Connections served."""
    connections_refused: int = 0
    """Connections closed at once because the most allowed were open."""


@dataclass(slots=True)
class ConnectionLimit:
    """The connections a server takes at once, and where its accept loop counts them.

    `name` starts the loop's log lines ("Modbus TCP", "gateway")."""

    name: str
    max_connections: int
    """Connections served at once; more are closed at once."""
    counters: ConnectionCounters = field(default_factory=AcceptCounters)
    """Where accepted and refused connections are counted."""
    open: int = 0
    """Connections open now."""
    accept_failures: int = 0
    """`accept()` calls that failed (out of file descriptors, or of memory)."""
    refusing: bool = False
    """Whether a refusal was logged since the last connection closed."""
    warned: dict[str, float] = field(default_factory=dict)
    """When a warning of each kind was last logged (the event loop's clock)."""

    def level(self, kind: str) -> int:
        """The level to log a `kind` of trouble at now: a warning at most once in
        `WARNING_INTERVAL` seconds, else debug."""
        now = anyio.current_time()
        if now - self.warned.get(kind, -math.inf) < WARNING_INTERVAL:
            return logging.DEBUG
        self.warned[kind] = now
        return logging.WARNING


async def serve_listener(
    listener: anyio.abc.Listener[anyio.abc.ByteStream],
    handler: Handler,
    limit: ConnectionLimit,
) -> None:
    """Accept connections from `listener` and run `handler` on each in a task of its own, within
    `limit`, until cancelled (see the module docstring). `handler` owns the stream; it is closed
    after it returns, and an exception it raises is logged and ends that connection only.

    anyio's TCP listener (one socket per address family) gets an accept loop per socket; a
    listener without `accept()` is served through its own `serve()`, with the limit; one with a
    handshake is accepted from as the listener it wraps, each handshake in its connection's task.
    """
    accepting = listener
    if isinstance(listener, _Handshaking):
        accepting, handler = listener.listener, after_handshake(listener, handler)
    async with listener, anyio.create_task_group() as tasks:
        if isinstance(accepting, MultiListener):
            for each in accepting.listeners:
                tasks.start_soon(_accept_loop, each, handler, limit, tasks)
        elif isinstance(accepting, anyio.abc.SocketListener):
            await _accept_loop(accepting, handler, limit, tasks)
        else:

            async def admitted(stream: anyio.abc.ByteStream) -> None:
                if _admit(stream, limit):
                    await _serve_one(handler, stream, limit)
                else:
                    await _close(stream)

            await accepting.serve(admitted)


async def _accept_loop(
    listener: anyio.abc.Listener[anyio.abc.ByteStream],
    handler: Handler,
    limit: ConnectionLimit,
    tasks: anyio.abc.TaskGroup,
) -> None:
    assert isinstance(listener, anyio.abc.SocketListener)
    back_off = 0.0
    while True:
        try:
            stream = await listener.accept()
        except (OSError, anyio.BrokenResourceError) as error:
            back_off = await _accept_failed(limit, error, back_off)
            continue
        back_off = 0.0
        if _admit(stream, limit):
            tasks.start_soon(_serve_one, handler, stream, limit)
        else:
            await _close(stream)


def after_handshake(listener: _Handshaking, handler: Handler) -> Handler:
    """`handler`, called with the secured stream once `listener`'s handshake on an accepted
    stream succeeds (a failed one is `listener`'s to tell and close)."""

    async def secured(stream: anyio.abc.ByteStream) -> None:
        secure = await listener.handshake(stream)
        if secure is not None:
            await handler(secure)

    return secured


def _admit(stream: anyio.abc.ByteStream, limit: ConnectionLimit) -> bool:
    """Whether to serve `stream` (counted open if so): the limit has room, the client is there."""
    _hold_back(stream)
    if limit.open >= limit.max_connections:
        _refuse(limit, stream)
        return False
    if not _connected(stream):
        return False
    limit.open += 1
    limit.counters.connections_accepted += 1
    return True


async def _serve_one(
    handler: Handler, stream: anyio.abc.ByteStream, limit: ConnectionLimit
) -> None:
    try:
        await handler(stream)
    except Exception:
        # One connection's failure never ends the others, nor the server.
        _log.exception("%s: serving %s failed; connection closed", limit.name, peer_address(stream))
    finally:
        limit.open -= 1
        limit.refusing = False
        await _close(stream)


async def _accept_failed(limit: ConnectionLimit, error: BaseException, back_off: float) -> float:
    """Back off after a failed `accept()`; return the next back-off. Errors other than running
    out of descriptors or memory end the loop."""
    cause = error if isinstance(error, OSError) else error.__cause__
    if not isinstance(cause, OSError) or cause.errno not in _ACCEPT_ERRORS:
        raise error
    limit.accept_failures += 1
    if not back_off:
        _log.log(
            limit.level("accept"),
            "%s: cannot accept a connection: %s; retrying (logged once until one is accepted)",
            limit.name,
            cause.strerror or cause,
        )
    back_off = min(_LAST_BACK_OFF, back_off * 2 or _FIRST_BACK_OFF)
    await anyio.sleep(back_off)
    return back_off


def _refuse(limit: ConnectionLimit, stream: anyio.abc.ByteStream) -> None:
    limit.counters.connections_refused += 1
    if not limit.refusing:
        limit.refusing = True
        _log.log(
            limit.level("refusal"),
            "%s: %d connections open, the most allowed; closing %s (logged once until one closes)",
            limit.name,
            limit.open,
            peer_address(stream),
        )


def _hold_back(stream: anyio.abc.ByteStream) -> None:
    """Pause reading on an accepted asyncio TCP stream until its first `receive()` (see the
    module docstring); streams of other kinds read only when asked already."""
    transport = getattr(stream, "_transport", None)
    if isinstance(transport, asyncio.Transport) and not transport.is_closing():
        transport.pause_reading()


def write_now(stream: anyio.abc.ByteStream, data: bytes) -> bool:
    """Write `data` to `stream` at once, without a task switch, where the stream is an accepted
    asyncio TCP stream whose transport holds nothing unsent; False (nothing written) elsewhere,
    for the caller to `await stream.send(data)`.

    anyio's `send()` ends with an event-loop turn even when the kernel took every byte; a
    server that answers a request per turn pays for it on every reply. What the kernel does
    not take stays in the transport's buffer, and the next `write_now` then declines: the
    caller's `send()` waits for it to drain, so back-pressure holds as with `send()`. A
    stream with a `write_now` of its own (a pushed server connection) is asked by it."""
    own = getattr(stream, "write_now", None)
    if own is not None:
        return bool(own(data))
    transport = getattr(stream, "_transport", None)
    if (
        isinstance(transport, asyncio.WriteTransport)
        and not transport.is_closing()
        and not transport.get_write_buffer_size()
    ):
        transport.write(data)
        return True
    return False


def _connected(stream: anyio.abc.ByteStream) -> bool:
    """Whether the client is still there (a TCP client reset in the backlog has no peer)."""
    try:
        raw = stream.extra(anyio.abc.SocketAttribute.raw_socket, None)
        if raw is not None and raw.family in (socket.AF_INET, socket.AF_INET6):
            raw.getpeername()
    except OSError:
        return False
    return True


async def _close(stream: anyio.abc.ByteStream) -> None:
    try:
        await stream.aclose()
    except (*_GONE, OSError):
        pass


def peer_address(stream: anyio.abc.ByteStream) -> str:
    """The address of the peer at the other end of `stream` (`host:port`), for logs; "a
    client" where the stream has no remote address (a Unix socket, an in-memory stream)."""
    try:
        address = stream.extra(anyio.abc.SocketAttribute.remote_address, None)
    except OSError:
        return "a client"
    if isinstance(address, tuple):
        return f"{address[0]}:{address[1]}"
    return "a client"


def listening_address(listener: anyio.abc.Listener[anyio.abc.ByteStream]) -> tuple[str, int] | None:
    """The host and port `listener` listens on, when it is a TCP listener."""
    address = listener.extra(anyio.abc.SocketAttribute.local_address, None)
    if isinstance(address, tuple):
        return (str(address[0]), int(address[1]))
    return None


# -- TCP ------------------------------------------------------------------------------


async def listen_tcp(
    host: str, port: int, *, url: str | None = None
) -> anyio.abc.Listener[SocketStream]:
    """Listen on `host`:`port` (0: a free port the system picks) and return the listener.

    Its connections have Nagle's algorithm off (anyio does that for accepted sockets). `url` names
    the listener in errors. Raises [`PortBusy`][aiortu.errors.PortBusy] when the port is taken,
    [`PortPermissionDenied`][aiortu.errors.PortPermissionDenied] when it needs privileges (below
    1024), and [`PortNotFound`][aiortu.errors.PortNotFound] for an address that is not this
    machine's.
    """
    where = url or f"{host}:{port}"
    try:
        return await anyio.create_tcp_listener(local_host=host, local_port=port)
    except socket.gaierror as exc:
        raise PortNotFound(where, f"unknown host {host!r} ({exc.strerror})") from exc
    except OSError as exc:
        raise _tcp_error(where, exc) from exc


def _tcp_error(where: str, exc: OSError) -> PortError:
    if exc.errno == errno.EADDRINUSE:
        return PortBusy(where, "the port is in use by another program")
    if exc.errno == errno.EACCES:
        return PortPermissionDenied(where, "ports below 1024 need privileges; try 1502")
    if exc.errno == errno.EADDRNOTAVAIL:
        return PortNotFound(where, "that address is not one of this machine's")
    return PortNotFound(where, f"cannot listen: {exc.strerror or exc}")


# -- Unix sockets ---------------------------------------------------------------------


@dataclass(frozen=True, slots=True)
class UnixAddress:
    """A `unix:PATH?mode=0660&group=NAME` listen URL: the socket path, and the file mode and
    group to give the socket (None: the process's defaults)."""

    path: str
    mode: int | None = None
    group: str | None = None


_UNIX_FORM = "unix:PATH[?mode=0660&group=NAME]"


def parse_unix_url(url: str) -> UnixAddress | None:
    """The address of a `unix:PATH` listen URL, None for another URL. Raises
    [`InvalidValue`][aiortu.errors.InvalidValue] for a missing path or a bad option."""
    if not url.startswith(UNIX_PREFIX):
        return None
    path, _, query = url[len(UNIX_PREFIX) :].partition("?")
    if not path or "\0" in path:
        raise InvalidValue("listen", url, _UNIX_FORM, "the socket path is missing")
    options: dict[str, str] = {}
    for pair in query.split("&") if query else ():
        name, equals, value = pair.partition("=")
        if name not in ("mode", "group") or not equals or not value or name in options:
            raise InvalidValue("listen", url, _UNIX_FORM, f"unknown or repeated option {pair!r}")
        options[name] = value
    mode = options.get("mode")
    if mode is not None and not (len(mode) <= 4 and set(mode) <= set("01234567")):
        raise InvalidValue("listen", url, _UNIX_FORM, f"mode {mode!r} is not octal, as 0660")
    return UnixAddress(path, None if mode is None else int(mode, 8), options.get("group"))


def _in_use(path: str) -> bool:
    """Whether a program listens on the socket `path` (anyio replaces any socket file there,
    a stale one left by a server that was killed, but a live one must stay)."""
    try:
        if not stat.S_ISSOCK(os.stat(path).st_mode):
            return False
    except OSError:
        return False
    with socket.socket(socket.AF_UNIX, socket.SOCK_STREAM) as probe:
        try:
            probe.connect(path)
        except OSError:
            return False
    return True


async def listen_unix(address: UnixAddress, url: str) -> anyio.abc.Listener[anyio.abc.ByteStream]:
    """Listen on the Unix socket `address.path`, replacing a stale socket file there, with the
    mode and group `address` gives.

    Raises [`PortBusy`][aiortu.errors.PortBusy] when a program listens on it or another file
    is in the way, [`PortPermissionDenied`][aiortu.errors.PortPermissionDenied] (also for a group
    that cannot be set), and [`PortNotFound`][aiortu.errors.PortNotFound] (no such directory, no
    such group)."""
    if _in_use(address.path):
        raise PortBusy(url, "a program listens on that socket")
    gid = -1 if address.group is None else _group_id(address.group, url)
    try:
        listener = await anyio.create_unix_listener(address.path)
    except OSError as exc:
        raise _unix_error(url, exc) from exc
    try:
        if address.mode is not None:
            os.chmod(address.path, address.mode)
        if gid != -1:
            os.chown(address.path, -1, gid)
    except OSError as exc:
        await listener.aclose()
        remove_socket(address.path)
        why = f"cannot set the socket's mode or group: {exc.strerror}"
        raise PortPermissionDenied(url, why) from exc
    return listener


def _group_id(group: str, url: str) -> int:
    try:
        return int(group) if group.isdigit() else grp.getgrnam(group).gr_gid
    except KeyError:
        raise PortNotFound(url, f"no group named {group!r}") from None


def _unix_error(url: str, exc: OSError) -> PortError:
    if exc.errno == errno.EADDRINUSE:
        return PortBusy(url, "a file that is not a socket is in the way")
    if exc.errno == errno.EACCES:
        return PortPermissionDenied(url, "no permission to create the socket there")
    if exc.errno == errno.ENOENT:
        return PortNotFound(url, "the socket's directory does not exist")
    return PortNotFound(url, f"cannot listen: {exc.strerror or exc}")


def remove_socket(path: str) -> None:
    """Remove the socket file `path` a server created (gone already: nothing to do)."""
    try:
        if stat.S_ISSOCK(os.stat(path).st_mode):
            os.unlink(path)
    except OSError:
        pass

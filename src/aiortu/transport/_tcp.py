"""RTU over TCP: the raw RTU frames over a TCP connection, for serial device servers.

A serial device server (a "serial-to-Ethernet" box in transparent mode) relays the bytes
of a TCP connection to its serial port and back. The frames travel exactly as on the wire,
unit address and CRC included, with no MBAP header: this is not Modbus TCP.

[`open_rtu_over_tcp`][aiortu.transport.open_rtu_over_tcp] returns anyio's TCP stream, with Nagle's
algorithm off because RTU frames are small and every millisecond of delay adds to each transaction.
It runs on any anyio backend.

Errors while connecting are [`PortNotFound`][aiortu.errors.PortNotFound], whatever the cause
(unknown host, connection refused, unreachable network, or no answer within
`connect_timeout`), with a message that says which host and port and why: for the caller
they all mean the same thing, that there is no device server at that address now, and
that trying again later may work. While running, anyio's stream raises
`anyio.EndOfStream` from `receive()` when the server closes the connection and
`anyio.BrokenResourceError` when it is reset; the link turns both into
[`ConnectionLost`][aiortu.errors.ConnectionLost].
"""

from __future__ import annotations

import asyncio
import socket
from collections.abc import Iterator
from contextlib import contextmanager

import anyio
import anyio.abc
from anyio.abc import SocketAttribute, SocketStream

from aiortu.errors import InvalidValue, PortNotFound
from aiortu.transport._url import format_tcp_url

__all__ = ("connect_protocol", "format_tcp_url", "open_rtu_over_tcp", "open_tcp_connection")


def _leaf_errors(exc: BaseException) -> list[BaseException]:
    if isinstance(exc, BaseExceptionGroup):
        return [leaf for inner in exc.exceptions for leaf in _leaf_errors(inner)]
    return [exc]


def _describe_failure(exc: OSError) -> str:
    """Why a connection failed, from the errors of every address that was tried."""
    # anyio wraps the errors of all the addresses it tried in one OSError.
    causes = _leaf_errors(exc.__cause__) if exc.__cause__ is not None else [exc]
    if all(isinstance(cause, ConnectionRefusedError) for cause in causes):
        return "connection refused: nothing listens on that port"
    return "cannot connect: " + "; ".join(str(cause) for cause in causes)


async def open_rtu_over_tcp(host: str, port: int, *, connect_timeout: float = 5.0) -> SocketStream:
    """Connect to the serial device server at `host`:`port` and return the connection.

    Raises [`PortNotFound`][aiortu.errors.PortNotFound] when the host is unknown, the connection
    is refused or fails, or nothing answers within `connect_timeout` seconds, and
    [`InvalidValue`][aiortu.errors.InvalidValue] for a port outside 1..65535 or a timeout that
    is not positive.
    """
    return await open_tcp_connection(host, port, connect_timeout=connect_timeout)


async def open_tcp_connection(
    host: str, port: int, *, connect_timeout: float = 5.0, scheme: str = "rtu+tcp"
) -> SocketStream:
    """Connect to `host`:`port` with Nagle's algorithm off, as
    [`open_rtu_over_tcp`][aiortu.transport.open_rtu_over_tcp] describes; errors name the server
    as `scheme://host:port`."""
    with _connecting(host, port, connect_timeout, scheme):
        stream = await anyio.connect_tcp(host, port)
    try:
        sock = stream.extra(SocketAttribute.raw_socket)
        sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
    except BaseException:
        await stream.aclose()
        raise
    return stream


async def connect_protocol(
    host: str,
    port: int,
    protocol: asyncio.BaseProtocol,
    *,
    connect_timeout: float,
    scheme: str,
) -> asyncio.Transport:
    """Connect `protocol` to `host`:`port` on asyncio's own transport (Nagle's algorithm off,
    as asyncio sets it), with the checks and errors of
    [`open_rtu_over_tcp`][aiortu.transport.open_rtu_over_tcp]; asyncio only."""
    with _connecting(host, port, connect_timeout, scheme):
        transport = await _first_connection(host, port, protocol)
    return transport


async def _first_connection(
    host: str, port: int, protocol: asyncio.BaseProtocol
) -> asyncio.Transport:
    """`protocol` on a connection to the first of `host`'s addresses that takes one, each tried
    in turn (anyio's `connect_tcp` races them); when none does, an `OSError` caused by each
    address's error, as anyio raises it, for `_describe_failure`."""
    loop = asyncio.get_running_loop()
    failures: list[OSError] = []
    for family, kind, proto, _, address in await anyio.getaddrinfo(
        host, port, type=socket.SOCK_STREAM
    ):
        sock = socket.socket(family, kind, proto)
        try:
            sock.setblocking(False)
            await loop.sock_connect(sock, address)
        except OSError as error:
            sock.close()
            failures.append(error)
            continue
        except BaseException:
            sock.close()
            raise
        transport, _ = await loop.create_connection(lambda: protocol, sock=sock)
        return transport
    raise OSError("all connection attempts failed") from ExceptionGroup("", failures)


@contextmanager
def _connecting(host: str, port: int, connect_timeout: float, scheme: str) -> Iterator[None]:
    """Check the port and the timeout, bound the connection's time by the timeout, and turn
    its failures into [`PortNotFound`][aiortu.errors.PortNotFound] naming
    `scheme://host:port`."""
    if isinstance(port, bool) or not isinstance(port, int) or not 1 <= port <= 65535:
        raise InvalidValue("port", port, range(1, 65536))
    if not connect_timeout > 0:
        raise InvalidValue("connect_timeout", connect_timeout, "a positive number of seconds")
    where = format_tcp_url(host, port, scheme)
    try:
        with anyio.fail_after(connect_timeout):
            yield
    except TimeoutError:
        raise PortNotFound(
            where, f"no answer within {connect_timeout:g} s (host down or filtered?)"
        ) from None
    except socket.gaierror as exc:
        raise PortNotFound(where, f"unknown host {host!r} ({exc.strerror})") from exc
    except OSError as exc:
        raise PortNotFound(where, _describe_failure(exc)) from exc

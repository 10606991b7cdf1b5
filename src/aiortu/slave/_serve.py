"""`serve`: open a port or a URL, or listen on one, and serve units for an `async with`."""

from __future__ import annotations

import inspect
from collections.abc import AsyncIterator, Callable, Mapping
from contextlib import asynccontextmanager
from typing import Any

import anyio
import anyio.abc

from aiortu.core.model import AsyncDataStore, DataStore
from aiortu.core.rtu import TimingMode
from aiortu.core.serial import LineSettings
from aiortu.errors import InvalidValue
from aiortu.slave._dispatch import TraceCallback
from aiortu.slave._handlers import Handler
from aiortu.slave._rtu_over_tcp import RtuOverTcpServer
from aiortu.slave._slave import Slave
from aiortu.slave._tcp_server import ModbusTcpServer
from aiortu.slave._tls_server import ModbusTlsServer
from aiortu.slave._udp_server import ModbusUdpServer
from aiortu.transport import (
    ASCII_TCP_SCHEME,
    MODBUS_TCP_SCHEME,
    MODBUS_UDP_SCHEME,
    TCP_SCHEME,
    TLS_SCHEME,
    ListenAddress,
    listen_tcp,
    open_stream,
    parse_listen_url,
)

__all__ = ("Server", "serve")


Server = Slave | ModbusTcpServer | RtuOverTcpServer
"""What [`serve`][aiortu.slave.serve] yields: a [`Slave`][aiortu.slave.Slave] on a port, a server on
a listen URL."""

_WILDCARDS = frozenset({"0.0.0.0", "::"})


def _listen_address(port_or_url: str, listen: bool | None) -> ListenAddress | None:
    """Where `port_or_url` listens, or None when it is a port to open (see serve)."""
    scheme = port_or_url.partition("://")[0].lower() if "://" in port_or_url else ""
    if scheme in (MODBUS_TCP_SCHEME, MODBUS_UDP_SCHEME, TLS_SCHEME):
        return parse_listen_url(port_or_url, (scheme,))
    if scheme in (TCP_SCHEME, ASCII_TCP_SCHEME):
        address = parse_listen_url(port_or_url, (scheme,))
        if listen or (listen is None and (address.port == 0 or address.host in _WILDCARDS)):
            return address
        return None
    if listen:
        raise InvalidValue(
            "port",
            port_or_url,
            "tcp://host:port, rtu+tcp://host:port or ascii+tcp://host:port",
            "only a URL listens",
        )
    return None


_SERVERS: dict[str, type[ModbusTcpServer | ModbusUdpServer]] = {
    MODBUS_TCP_SCHEME: ModbusTcpServer,
    MODBUS_UDP_SCHEME: ModbusUdpServer,
    TLS_SCHEME: ModbusTlsServer,
}
"""The server of each listener's scheme but RTU and ASCII over TCP (`RtuOverTcpServer`)."""

_GIVEN_BY_SERVE = frozenset({"units", "settings", "timing", "handlers", "trace"})


def _options(server: type) -> set[str]:
    """The options `server` takes: its keywords, and Modbus TCP's where it passes the rest on
    (`**options`)."""
    parameters = inspect.signature(server).parameters.values()
    names = {p.name for p in parameters if p.kind in (p.KEYWORD_ONLY, p.POSITIONAL_OR_KEYWORD)}
    if any(p.kind is p.VAR_KEYWORD for p in parameters):
        names |= _options(ModbusTcpServer)
    return names - _GIVEN_BY_SERVE


def _refuse_unknown(port_or_url: str, server: type, options: Mapping[str, Any]) -> None:
    """A `TypeError` in one sentence for an option the listener's server does not take (a TLS
    certificate given for `tcp://`), before anything is opened."""
    taken = _options(server)
    unknown = sorted(set(options) - taken)
    if unknown:
        raise TypeError(
            f"{port_or_url}: {server.__name__} takes no option {', '.join(unknown)} "
            f"(it takes {', '.join(sorted(taken))})"
        )


@asynccontextmanager
async def _running(
    server: ModbusTcpServer | RtuOverTcpServer, address: ListenAddress, url: str
) -> AsyncIterator[None]:
    """Listen on `address` and run `server` for the duration of the `async with`."""
    listener = await listen_tcp(address.host, address.port, url=url)
    group = anyio.create_task_group()
    await group.__aenter__()
    try:
        await group.start(server.serve, listener)
        yield
    finally:
        group.cancel_scope.cancel()
        # The body's own exception propagates as it is, not wrapped in an ExceptionGroup.
        await group.__aexit__(None, None, None)


@asynccontextmanager
async def serve(
    port_or_url: str,
    units: Mapping[int, DataStore | AsyncDataStore],
    *,
    baudrate: int = 19200,
    parity: str = "E",
    stopbits: float = 1,
    bytesize: int = 8,
    frame_gap: float | None = None,
    timing: TimingMode | str = TimingMode.TOLERANT,
    handlers: Mapping[int, Handler] | None = None,
    trace: TraceCallback | None = None,
    listen: bool | None = None,
    **options: Any,
) -> AsyncIterator[Server]:
    """Open `port_or_url`, or listen on it, and serve `units` for the duration of the
    `async with`.

    - A serial device path, or `rtu+tcp://host:port` to connect to a serial device server: yields
      the running [`Slave`][aiortu.slave.Slave]. The line settings are the spec's 19200 8E1 by
      default; `options` go to [`aiortu.transport.open_stream`][aiortu.transport.open_stream]
      (`exclusive`, `rs485`, `local_echo`, `connect_timeout`, and `framing="ascii"` for Modbus
      ASCII; `ascii+tcp://host:port` connects in ASCII).
    - `tcp://host:port`: listens for Modbus TCP and yields the running
      [`ModbusTcpServer`][aiortu.slave.ModbusTcpServer]; `options` go to it
      (`max_connections`, `idle_timeout`, `unit_aliases`, `answer_unknown_units`,
      `serial_line_codes`).
    - `udp://host:port`: Modbus UDP, the same server answering each datagram to its source
      ([`ModbusUdpServer`][aiortu.slave.ModbusUdpServer]; the same `options`).
    - `tls://host:port`: Modbus/TCP Security, mutual TLS with roles
      ([`ModbusTlsServer`][aiortu.slave.ModbusTlsServer]; `options` `certfile`, `keyfile`,
      `cafile` and `rules`, and the Modbus TCP server's).
    - `rtu+tcp://host:port` with `listen` true, or with a wildcard host (`0.0.0.0`, `[::]`) or port
      0 (addresses nobody can connect to): listens for RTU framing over TCP and yields the running
      [`RtuOverTcpServer`][aiortu.slave.RtuOverTcpServer] (options `max_connections`,
      `idle_timeout`, and
      `framing="ascii"` for Modbus ASCII). `ascii+tcp://host:port` listens in the same cases,
      its lines in Modbus ASCII (option `ascii_timeout`).

    Port 0 asks the system for a free port (see the server's `port`). Raises `TypeError`, in
    one sentence, for an option the listener's server does not take (a certificate for
    `tcp://`), and the transport's [`PortError`][aiortu.errors.PortError] subclasses when the
    port cannot be opened or listened on.
    """
    settings = LineSettings(baudrate, bytesize, parity, stopbits)
    address = _listen_address(port_or_url, listen)
    if address is not None:
        kind = _SERVERS.get(address.scheme, RtuOverTcpServer)
        _refuse_unknown(port_or_url, kind, options)
        if kind is ModbusUdpServer:
            udp = ModbusUdpServer(units, handlers=handlers, trace=trace, **options)
            async with udp.running(address, port_or_url):
                yield udp
            return
        server: ModbusTcpServer | RtuOverTcpServer
        if kind is RtuOverTcpServer:
            if address.scheme == ASCII_TCP_SCHEME:
                if options.get("framing", "ascii") != "ascii":  # as open_stream refuses it
                    raise InvalidValue(
                        "framing", options["framing"], "'ascii' for an ascii+tcp:// URL"
                    )
                options = {**options, "framing": "ascii"}
            server = RtuOverTcpServer(
                units, settings, timing=timing, handlers=handlers, trace=trace, **options
            )
        else:  # Modbus TCP, or Modbus/TCP Security
            server = kind(units, handlers=handlers, trace=trace, **options)
        async with _running(server, address, port_or_url):
            yield server
        return

    def make(stream: anyio.abc.ByteStream) -> Slave:
        return Slave(
            stream, units, settings, frame_gap=frame_gap, timing=timing, handlers=handlers,
            trace=trace,
        )  # fmt: skip

    slave = await _on_port(port_or_url, settings, options, make)
    async with slave:
        yield slave


async def _on_port(
    port: str,
    settings: LineSettings,
    options: dict[str, Any],
    make: Callable[[anyio.abc.ByteStream], Slave],
) -> Slave:
    """`make`'s [`Slave`][aiortu.slave.Slave] on `port`, opened with `settings` and the
    transport's `options`; the port is closed again if the slave cannot be made."""
    stream = await open_stream(port, settings, **options)
    try:
        return make(stream)
    except BaseException:
        await stream.aclose()
        raise

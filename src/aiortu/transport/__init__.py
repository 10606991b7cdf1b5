"""Byte streams that carry RTU frames: serial ports, RTU over TCP, Modbus TCP (translated to
and from RTU frames), pty file descriptors.

Every transport is an `anyio.abc.ByteStream`, so the link, the master and the slave take any of
them. A stream that also implements [`PushStream`][aiortu.transport.PushStream] (the serial port
does) saves the link a task wake-up per chunk read and per frame sent.
[`open_stream`][aiortu.transport.open_stream] opens one from a port name as users write it: a serial
device path, `rtu+tcp://host:port`, or `tcp://host:port` (see
[`aiortu.transport`][aiortu.transport]). Opening errors are [`PortError`][aiortu.errors.PortError]
subclasses naming the port; see `docs/transports.md` for what each means and what to do about it.
"""

from __future__ import annotations

import importlib
from typing import TYPE_CHECKING, Any

from anyio.abc import ByteStream

from aiortu.core.serial import LineSettings
from aiortu.transport._echo import LocalEchoFilter
from aiortu.transport._fd import FileDescriptorStream
from aiortu.transport._listen import (
    AcceptCounters,
    ConnectionCounters,
    ConnectionLimit,
    UnixAddress,
    listen_tcp,
    listen_unix,
    listening_address,
    parse_unix_url,
    peer_address,
    remove_socket,
    serve_listener,
    write_now,
)
from aiortu.transport._mbap_stream import (
    FramedStream,
    ModbusTcpCounters,
    ModbusTcpStream,
    open_modbus_tcp,
)
from aiortu.transport._push import PushStream
from aiortu.transport._server_framing import RTU_SILENCE, Framing, MbapFraming, RtuFraming
from aiortu.transport._tcp import open_rtu_over_tcp
from aiortu.transport._url import (
    MODBUS_TCP_SCHEME,
    TCP_SCHEME,
    ListenAddress,
    ModbusTcpAddress,
    PortAddress,
    SerialAddress,
    TcpAddress,
    parse_listen_url,
    parse_port_url,
)

if TYPE_CHECKING:
    from aiortu.transport._serial import RS485Options, SerialAttribute, SerialStream, open_serial

__all__ = (
    "MODBUS_TCP_SCHEME",
    "RTU_SILENCE",
    "TCP_SCHEME",
    "AcceptCounters",
    "ConnectionCounters",
    "ConnectionLimit",
    "FileDescriptorStream",
    "FramedStream",
    "Framing",
    "ListenAddress",
    "LocalEchoFilter",
    "MbapFraming",
    "ModbusTcpAddress",
    "ModbusTcpCounters",
    "ModbusTcpStream",
    "PortAddress",
    "PushStream",
    "RS485Options",
    "RtuFraming",
    "SerialAddress",
    "SerialAttribute",
    "SerialStream",
    "TcpAddress",
    "UnixAddress",
    "listen_tcp",
    "listen_unix",
    "listening_address",
    "open_modbus_tcp",
    "open_rtu_over_tcp",
    "open_serial",
    "open_stream",
    "parse_listen_url",
    "parse_port_url",
    "parse_unix_url",
    "peer_address",
    "remove_socket",
    "serve_listener",
    "write_now",
)

_SERIAL_NAMES = frozenset({"RS485Options", "SerialAttribute", "SerialStream", "open_serial"})
"""Imported on first use: pyserial is loaded only by what opens a serial port, not by a
command that talks Modbus TCP."""


def __getattr__(name: str) -> Any:
    if name not in _SERIAL_NAMES:
        raise AttributeError(f"module 'aiortu.transport' has no attribute {name!r}")
    value = getattr(importlib.import_module("aiortu.transport._serial"), name)
    globals()[name] = value
    return value


_SERIAL_OPTIONS = frozenset({"exclusive", "rs485", "local_echo"})
_TCP_OPTIONS = frozenset({"connect_timeout"})
_MODBUS_TCP_OPTIONS = frozenset({"connect_timeout", "counters"})


async def open_stream(
    port_or_url: str,
    settings: LineSettings = LineSettings(),  # noqa: B008 - frozen, safe to share
    **options: Any,
) -> ByteStream:
    """Open the transport a port name designates and return it as a byte stream.

    `rtu+tcp://host:port` connects to a serial device server
    ([`open_rtu_over_tcp`][aiortu.transport.open_rtu_over_tcp]; option `connect_timeout`; `settings`
    are not sent anywhere, as the server's serial side is configured on the server).
    `tcp://host:port` connects to a Modbus TCP server and returns a
    [`ModbusTcpStream`][aiortu.transport.ModbusTcpStream], which carries RTU frames as MBAP ADUs
    ([`open_modbus_tcp`][aiortu.transport.open_modbus_tcp]; options `connect_timeout` and
    `counters`; `settings` are not used). Anything else is a serial device path
    ([`open_serial`][aiortu.transport.open_serial]; options `exclusive`, `rs485` and
    `local_echo`).

    Raises [`InvalidValue`][aiortu.errors.InvalidValue] for a malformed URL,
    `TypeError` for an option the transport does not take, and the transport's
    [`PortError`][aiortu.errors.PortError] subclasses when it cannot be opened.
    """
    address = parse_port_url(port_or_url)
    if isinstance(address, ModbusTcpAddress):
        kind, allowed = "Modbus TCP", _MODBUS_TCP_OPTIONS
    elif isinstance(address, TcpAddress):
        kind, allowed = "RTU over TCP", _TCP_OPTIONS
    else:
        kind, allowed = "a serial port", _SERIAL_OPTIONS
    unknown = sorted(set(options) - allowed)
    if unknown:
        raise TypeError(
            f"{port_or_url}: {kind} takes no option {', '.join(unknown)} "
            f"(it takes {', '.join(sorted(allowed))})"
        )
    if isinstance(address, ModbusTcpAddress):
        return await open_modbus_tcp(address.host, address.port, **options)
    if isinstance(address, TcpAddress):
        return await open_rtu_over_tcp(address.host, address.port, **options)
    from aiortu.transport._serial import open_serial

    return await open_serial(address.path, settings, **options)

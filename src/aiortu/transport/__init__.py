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

from aiortu._public import publish
from aiortu.core.serial import LineSettings
from aiortu.errors import InvalidValue
from aiortu.transport._ascii_push import PushAsciiStream, ascii_stream, pushes_ascii
from aiortu.transport._ascii_stream import ASCII_BYTESIZE, AsciiStream, check_ascii_settings
from aiortu.transport._authorization import (
    WRITE_FUNCTION_CODES,
    AccessRule,
    RoleRules,
    load_rules,
    parse_rules,
)
from aiortu.transport._datagram_listener import PEER_BACKLOG, DatagramListener
from aiortu.transport._datagram_server import DATAGRAM_BACKLOG, DatagramServer, DatagramSource
from aiortu.transport._echo import LocalEchoFilter
from aiortu.transport._fd import FileDescriptorStream
from aiortu.transport._listen import (
    WARNING_INTERVAL,
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
from aiortu.transport._mbap_stream import FramedStream, ModbusTcpCounters, ModbusTcpStream
from aiortu.transport._push import PushStream, loop_pushes
from aiortu.transport._push_server import (
    PushListener,
    PushServerStream,
    PushTlsListener,
    push_listener,
    pushed_listener,
)
from aiortu.transport._server_framing import (
    RTU_SILENCE,
    AsciiFraming,
    Framing,
    MbapFraming,
    RtuFraming,
)
from aiortu.transport._tcp import open_rtu_over_tcp, open_tcp_connection
from aiortu.transport._tcp_push import PushConnectionStream, open_modbus_tcp
from aiortu.transport._tls import (
    ROLE_OID,
    CertificateError,
    TlsListener,
    certificate_role,
    client_tls_context,
    describe_tls_failure,
    open_modbus_tls,
    server_tls_context,
)
from aiortu.transport._udp import (
    DatagramCounters,
    check_datagram,
    listen_udp,
    open_modbus_udp,
    serve_datagrams,
)
from aiortu.transport._udp_push import PushDatagramStream, log_level, push_datagrams
from aiortu.transport._url import (
    ASCII_TCP_SCHEME,
    MODBUS_TCP_SCHEME,
    MODBUS_UDP_SCHEME,
    TCP_SCHEME,
    TLS_SCHEME,
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
    "ASCII_BYTESIZE",
    "ASCII_TCP_SCHEME",
    "DATAGRAM_BACKLOG",
    "MODBUS_TCP_SCHEME",
    "MODBUS_UDP_SCHEME",
    "PEER_BACKLOG",
    "ROLE_OID",
    "RTU_SILENCE",
    "TCP_SCHEME",
    "TLS_SCHEME",
    "WARNING_INTERVAL",
    "WRITE_FUNCTION_CODES",
    "AcceptCounters",
    "AccessRule",
    "AsciiStream",
    "CertificateError",
    "ConnectionCounters",
    "ConnectionLimit",
    "DatagramCounters",
    "DatagramListener",
    "DatagramServer",
    "DatagramSource",
    "FileDescriptorStream",
    "FramedStream",
    "AsciiFraming",
    "Framing",
    "ListenAddress",
    "LocalEchoFilter",
    "MbapFraming",
    "ModbusTcpAddress",
    "ModbusTcpCounters",
    "ModbusTcpStream",
    "PortAddress",
    "PushAsciiStream",
    "PushConnectionStream",
    "PushDatagramStream",
    "PushListener",
    "PushServerStream",
    "PushTlsListener",
    "PushStream",
    "RoleRules",
    "RS485Options",
    "RtuFraming",
    "SerialAddress",
    "SerialAttribute",
    "SerialStream",
    "TcpAddress",
    "TlsListener",
    "UnixAddress",
    "ascii_stream",
    "certificate_role",
    "check_ascii_settings",
    "check_datagram",
    "client_tls_context",
    "describe_tls_failure",
    "listen_tcp",
    "listen_udp",
    "listen_unix",
    "listening_address",
    "load_rules",
    "log_level",
    "loop_pushes",
    "open_modbus_tcp",
    "open_modbus_tls",
    "open_modbus_udp",
    "open_rtu_over_tcp",
    "open_serial",
    "open_stream",
    "parse_listen_url",
    "parse_port_url",
    "parse_rules",
    "parse_unix_url",
    "push_listener",
    "pushed_listener",
    "peer_address",
    "push_datagrams",
    "pushes_ascii",
    "remove_socket",
    "serve_datagrams",
    "serve_listener",
    "server_tls_context",
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
    publish(__name__, (name,), globals())
    return value


_SERIAL_OPTIONS = frozenset({"exclusive", "rs485", "local_echo", "framing", "ascii_timeout"})
_TCP_OPTIONS = frozenset({"connect_timeout", "framing", "ascii_timeout"})
_MODBUS_TCP_OPTIONS = frozenset({"connect_timeout", "counters"})
_MODBUS_UDP_OPTIONS = frozenset({"counters"})
_MODBUS_TLS_OPTIONS = frozenset({"connect_timeout", "counters", "certfile", "keyfile", "cafile"})


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
    `counters`; `settings` are not used). `udp://host:port` talks Modbus UDP, one ADU per
    datagram, through the same stream ([`open_modbus_udp`][aiortu.transport.open_modbus_udp];
    option `counters`). `tls://host:port` talks Modbus/TCP Security
    ([`open_modbus_tls`][aiortu.transport.open_modbus_tls]; options `certfile`, `keyfile` and
    `cafile`, required, and `connect_timeout` and `counters`). Anything else is a serial device path
    ([`open_serial`][aiortu.transport.open_serial]; options `exclusive`, `rs485` and
    `local_echo`). `framing="ascii"` carries Modbus ASCII frames on a serial port or an
    `rtu+tcp://` connection instead of RTU ones, as `ascii+tcp://host:port` does
    ([`AsciiStream`][aiortu.transport.AsciiStream]; option `ascii_timeout`, the
    inter-character timeout, 1 s by default); a serial port without the spec's 7 data bits is
    opened as asked, with a warning.

    Raises [`InvalidValue`][aiortu.errors.InvalidValue] for a malformed URL,
    `TypeError` for an option the transport does not take, and the transport's
    [`PortError`][aiortu.errors.PortError] subclasses when it cannot be opened.
    """
    address = parse_port_url(port_or_url)
    if isinstance(address, ModbusTcpAddress) and address.scheme == MODBUS_UDP_SCHEME:
        kind, allowed = "Modbus UDP", _MODBUS_UDP_OPTIONS
    elif isinstance(address, ModbusTcpAddress) and address.scheme == TLS_SCHEME:
        kind, allowed = "Modbus/TCP Security", _MODBUS_TLS_OPTIONS
    elif isinstance(address, ModbusTcpAddress):
        kind, allowed = "Modbus TCP", _MODBUS_TCP_OPTIONS
    elif isinstance(address, TcpAddress):
        kind = "ASCII over TCP" if address.framing == "ascii" else "RTU over TCP"
        allowed = _TCP_OPTIONS
    else:
        kind, allowed = "a serial port", _SERIAL_OPTIONS
    unknown = sorted(set(options) - allowed)
    if unknown:
        raise TypeError(
            f"{port_or_url}: {kind} takes no option {', '.join(unknown)} "
            f"(it takes {', '.join(sorted(allowed))})"
        )
    ascii_options = _ascii_framing(port_or_url, address, options)
    stream = await _open(address, settings, options)
    if ascii_options is None:
        return stream
    if isinstance(address, SerialAddress):
        check_ascii_settings(port_or_url, settings)
    return ascii_stream(stream, settings, **ascii_options)


async def _open(address: PortAddress, settings: LineSettings, options: Any) -> ByteStream:
    if isinstance(address, ModbusTcpAddress) and address.scheme == MODBUS_UDP_SCHEME:
        return await open_modbus_udp(address.host, address.port, **options)
    if isinstance(address, ModbusTcpAddress) and address.scheme == TLS_SCHEME:
        return await open_modbus_tls(address.host, address.port, **options)
    if isinstance(address, ModbusTcpAddress):
        return await open_modbus_tcp(address.host, address.port, **options)
    if isinstance(address, TcpAddress):
        # Its errors name the URL as given: ascii+tcp:// too.
        return await open_tcp_connection(
            address.host, address.port, scheme=address.scheme, **options
        )
    from aiortu.transport._serial import open_serial

    return await open_serial(address.path, settings, **options)


def _ascii_framing(
    url: str, address: PortAddress, options: dict[str, Any]
) -> dict[str, Any] | None:
    """The [`AsciiStream`][aiortu.transport.AsciiStream] options when `url` is to carry ASCII
    frames (taken out of `options`), else None."""
    framing = options.pop("framing", None)
    timeout = options.pop("ascii_timeout", None)
    if isinstance(address, TcpAddress) and address.framing == "ascii":
        if framing not in (None, "ascii"):
            raise InvalidValue("framing", framing, "'ascii' for an ascii+tcp:// URL")
        framing = "ascii"
    if framing not in (None, "rtu", "ascii"):
        raise InvalidValue("framing", framing, "'rtu' or 'ascii'")
    if framing != "ascii":
        if timeout is not None:
            raise InvalidValue("ascii_timeout", timeout, "given with framing='ascii' only")
        return None
    return {} if timeout is None else {"timeout": timeout}


publish(__name__, __all__, globals())

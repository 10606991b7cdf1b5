"""Port names: a serial device path, `rtu+tcp://host:port` for RTU over TCP,
`tcp://host:port` for Modbus TCP, `udp://host:port` for Modbus UDP, or `tls://host:port` for
Modbus/TCP Security.

[`parse_port_url`][aiortu.transport.parse_port_url] turns the text a user gives (on the command
line, in `open_master`) into a [`SerialAddress`][aiortu.transport.SerialAddress], a
[`TcpAddress`][aiortu.transport.TcpAddress], a
[`ModbusTcpAddress`][aiortu.transport.ModbusTcpAddress] (with its `scheme`: `tcp`, `udp` or
`tls`), or raises
[`InvalidValue`][aiortu.errors.InvalidValue] saying what is wrong with it.
[`parse_listen_url`][aiortu.transport.parse_listen_url] does the same for the address a server
listens on (`serve`), where port 0 asks the system for a free port.

The URL form is `SCHEME://HOST:PORT`, optionally with a trailing `/`. HOST is a
name, an IPv4 address, or an IPv6 address in brackets (`rtu+tcp://[::1]:5020`); PORT
is required (there is no standard port for RTU over TCP, and 502 needs privileges).
Anything else containing `://` is refused, so that a typing mistake does not end up as
a device path. Any other text is taken as a serial device path, unchanged.
"""

from __future__ import annotations

import ipaddress
from collections.abc import Collection
from dataclasses import dataclass

from aiortu.errors import InvalidValue

__all__ = (
    "ASCII_TCP_SCHEME",
    "MODBUS_TCP_SCHEME",
    "MODBUS_UDP_SCHEME",
    "TLS_SCHEME",
    "ListenAddress",
    "ModbusTcpAddress",
    "PortAddress",
    "SerialAddress",
    "TCP_SCHEME",
    "TcpAddress",
    "parse_listen_url",
    "parse_port_url",
)

TCP_SCHEME = "rtu+tcp"
"""The URL scheme of RTU over TCP."""

MODBUS_TCP_SCHEME = "tcp"
"""The URL scheme of Modbus TCP (MBAP framing)."""

MODBUS_UDP_SCHEME = "udp"
"""The URL scheme of Modbus UDP (one MBAP ADU per datagram)."""

TLS_SCHEME = "tls"
"""The URL scheme of Modbus/TCP Security (MBAP framing inside mutual TLS)."""

ASCII_TCP_SCHEME = "ascii+tcp"
"""The URL scheme of Modbus ASCII over TCP, to a serial device server."""

_MBAP_SCHEMES = (MODBUS_TCP_SCHEME, MODBUS_UDP_SCHEME, TLS_SCHEME)


def format_tcp_url(host: str, port: int, scheme: str = TCP_SCHEME) -> str:
    """The `scheme://host:port` URL of a server, with IPv6 hosts in brackets."""
    if ":" in host:
        return f"{scheme}://[{host}]:{port}"
    return f"{scheme}://{host}:{port}"


_URL_FORM = (
    "a serial device path, rtu+tcp://host:port, ascii+tcp://host:port, tcp://host:port, "
    "udp://host:port or tls://host:port"
)


@dataclass(frozen=True, slots=True)
class SerialAddress:
    """A serial device path such as `/dev/ttyUSB0` or `COM3`."""

    path: str

    def __str__(self) -> str:
        return self.path


@dataclass(frozen=True, slots=True)
class TcpAddress:
    """A serial device server reached over TCP, its frames in RTU (`rtu+tcp://`) or ASCII
    (`ascii+tcp://`) framing."""

    host: str
    """A host name, an IPv4 address, or an IPv6 address without brackets."""
    port: int
    framing: str = "rtu"
    """`rtu` or `ascii`."""

    @property
    def scheme(self) -> str:
        """`rtu+tcp` or `ascii+tcp`, by the framing."""
        return ASCII_TCP_SCHEME if self.framing == "ascii" else TCP_SCHEME

    def __str__(self) -> str:
        return format_tcp_url(self.host, self.port, self.scheme)


@dataclass(frozen=True, slots=True)
class ModbusTcpAddress:
    """A device or server reached with MBAP framing: over TCP (`scheme` `tcp`), UDP (`udp`)
    or mutual TLS (`tls`)."""

    host: str
    """A host name, an IPv4 address, or an IPv6 address without brackets."""
    port: int
    scheme: str = MODBUS_TCP_SCHEME
    """`tcp`, `udp` or `tls`."""

    def __str__(self) -> str:
        return format_tcp_url(self.host, self.port, self.scheme)


@dataclass(frozen=True, slots=True)
class ListenAddress:
    """Where a server listens: `scheme` `tcp` (Modbus TCP), `udp` (Modbus UDP), `tls`
    (Modbus/TCP Security) or `rtu+tcp` (RTU framing over TCP), a `host` to bind (`0.0.0.0`
    or `::` for every interface) and a `port` (0: a free port the system picks)."""

    scheme: str
    host: str
    port: int

    def __str__(self) -> str:
        return format_tcp_url(self.host, self.port, self.scheme)


PortAddress = SerialAddress | TcpAddress | ModbusTcpAddress
"""What [`parse_port_url`][aiortu.transport.parse_port_url] returns."""


def _bad(text: str, detail: str, form: str = _URL_FORM) -> InvalidValue:
    return InvalidValue("port", text, form, detail)


def _parse_host_port(
    text: str, rest: str, scheme: str, lowest_port: int = 1, form: str = _URL_FORM
) -> tuple[str, int]:
    """The host and port of `scheme://host:port` (`rest` is what follows `://`)."""

    def bad(detail: str) -> InvalidValue:
        return _bad(text, detail, form)

    netloc, _, tail = rest.partition("/")
    if tail or any(mark in netloc for mark in "?#"):
        raise bad(f"a {scheme} URL has no path, query or fragment")
    if "@" in netloc:
        raise bad(f"a {scheme} URL has no user name or password")
    if netloc.startswith("["):
        closing = netloc.find("]")
        if closing < 0:
            raise bad("an IPv6 address opened with '[' needs a closing ']'")
        host, after = netloc[1:closing], netloc[closing + 1 :]
        try:
            ipaddress.IPv6Address(host)
        except ValueError:
            raise bad(f"{host!r} in brackets is not an IPv6 address") from None
        if not after:
            raise bad(f"the port number is missing: {scheme}://[host]:port")
        if not after.startswith(":"):
            raise bad("expected ':port' after the IPv6 address")
        port_text = after[1:]
    else:
        host, colon, port_text = netloc.rpartition(":")
        if not colon:
            raise bad(f"the port number is missing: {scheme}://host:port")
        if ":" in host:
            raise bad(f"write an IPv6 address in brackets: {scheme}://[::1]:5020")
    if not host:
        raise bad("the host is missing")
    if any(char.isspace() or char in "[]" for char in host):
        raise bad(f"{host!r} is not a host name or address")
    if not port_text:
        raise bad("the port is missing")
    if not (port_text.isascii() and port_text.isdigit()):
        raise bad(f"the port {port_text!r} is not a number")
    port = int(port_text)
    if not lowest_port <= port <= 65535:
        raise bad(f"the port {port} is outside {lowest_port}..65535")
    return host, port


def parse_port_url(text: str) -> PortAddress:
    """Parse a port name: a serial device path, `rtu+tcp://host:port`, `ascii+tcp://host:port`,
    `tcp://host:port`, `udp://host:port` or `tls://host:port`.

    >>> parse_port_url("/dev/ttyUSB0")
    SerialAddress(path='/dev/ttyUSB0')
    >>> parse_port_url("rtu+tcp://[::1]:5020")
    TcpAddress(host='::1', port=5020, framing='rtu')

    Raises [`InvalidValue`][aiortu.errors.InvalidValue] for an empty name, an unknown scheme, or
    a URL without a valid host and port (1..65535).
    """
    if not isinstance(text, str):
        raise InvalidValue("port", text, _URL_FORM, "not a string")
    if not text.strip():
        raise _bad(text, "the port name is empty")
    scheme, separator, rest = text.partition("://")
    if not separator:
        return SerialAddress(text)
    scheme = scheme.lower()
    if scheme in _MBAP_SCHEMES:
        return ModbusTcpAddress(*_parse_host_port(text, rest, scheme), scheme)
    if scheme == ASCII_TCP_SCHEME:
        return TcpAddress(*_parse_host_port(text, rest, scheme), "ascii")
    if scheme != TCP_SCHEME:
        # The sentence already lists the forms a port may take.
        raise _bad(text, f"unknown scheme {scheme!r}")
    return TcpAddress(*_parse_host_port(text, rest, scheme))


def parse_listen_url(
    text: str, schemes: Collection[str] = (MODBUS_TCP_SCHEME, TCP_SCHEME)
) -> ListenAddress:
    """Parse the address a server listens on: `tcp://host:port` (Modbus TCP) or
    `rtu+tcp://host:port` (RTU framing over TCP) by default, and the other `schemes` a server
    takes (`udp` for Modbus UDP, `tls` for Modbus/TCP Security); port 0 asks for a free port.

    >>> parse_listen_url("tcp://0.0.0.0:1502")
    ListenAddress(scheme='tcp', host='0.0.0.0', port=1502)

    Raises [`InvalidValue`][aiortu.errors.InvalidValue] for another scheme, a device path, or a
    URL without a valid host and port (0..65535).
    """
    names = [f"{scheme}://" for scheme in schemes]
    form = f"{', '.join(names[:-1])} or {names[-1]}" if len(names) > 1 else names[0]
    if not isinstance(text, str):
        raise InvalidValue("port", text, f"{form}host:port", "not a string")
    scheme, separator, rest = text.partition("://")
    scheme = scheme.lower()
    if not separator or scheme not in schemes:
        raise _bad(text, f"a server listens on a {form} URL", f"{form}host:port")
    return ListenAddress(scheme, *_parse_host_port(text, rest, scheme, 0, f"{form}host:port"))

"""Port names: a serial device path, or `rtu+tcp://host:port` for RTU over TCP.

[`parse_port_url`][aiortu.transport.parse_port_url] turns the text a user gives (on the command
line, in `open_master`) into a [`SerialAddress`][aiortu.transport.SerialAddress] or a
[`TcpAddress`][aiortu.transport.TcpAddress], or raises [`InvalidValue`][aiortu.errors.InvalidValue]
saying what is wrong with it.

The URL form is `rtu+tcp://HOST:PORT`, optionally with a trailing `/`. HOST is a
name, an IPv4 address, or an IPv6 address in brackets (`rtu+tcp://[::1]:5020`); PORT
is required (there is no standard port for RTU over TCP). Anything else containing
`://` is refused, so that a typing mistake does not end up as a device path. Any other
text is taken as a serial device path, unchanged.
"""

from __future__ import annotations

import ipaddress
from dataclasses import dataclass

from aiortu.errors import InvalidValue

__all__ = ("PortAddress", "SerialAddress", "TCP_SCHEME", "TcpAddress", "parse_port_url")

TCP_SCHEME = "rtu+tcp"
"""The URL scheme of RTU over TCP."""

_URL_FORM = "a serial device path or rtu+tcp://host:port"


@dataclass(frozen=True, slots=True)
class SerialAddress:
    """A serial device path such as `/dev/ttyUSB0` or `COM3`."""

    path: str

    def __str__(self) -> str:
        return self.path


@dataclass(frozen=True, slots=True)
class TcpAddress:
    """A serial device server reached by RTU over TCP."""

    host: str
    """A host name, an IPv4 address, or an IPv6 address without brackets."""
    port: int

    def __str__(self) -> str:
        host = f"[{self.host}]" if ":" in self.host else self.host
        return f"{TCP_SCHEME}://{host}:{self.port}"


PortAddress = SerialAddress | TcpAddress
"""What [`parse_port_url`][aiortu.transport.parse_port_url] returns."""


def _bad(text: str, detail: str) -> InvalidValue:
    return InvalidValue("port", text, _URL_FORM, detail)


def _parse_tcp(text: str, rest: str) -> TcpAddress:
    netloc, _, tail = rest.partition("/")
    if tail or any(mark in netloc for mark in "?#"):
        raise _bad(text, "an rtu+tcp URL has no path, query or fragment")
    if "@" in netloc:
        raise _bad(text, "an rtu+tcp URL has no user name or password")
    if netloc.startswith("["):
        closing = netloc.find("]")
        if closing < 0:
            raise _bad(text, "an IPv6 address opened with '[' needs a closing ']'")
        host, after = netloc[1:closing], netloc[closing + 1 :]
        try:
            ipaddress.IPv6Address(host)
        except ValueError:
            raise _bad(text, f"{host!r} in brackets is not an IPv6 address") from None
        if not after:
            raise _bad(text, "the port is missing (rtu+tcp://[host]:port)")
        if not after.startswith(":"):
            raise _bad(text, "expected ':port' after the IPv6 address")
        port_text = after[1:]
    else:
        host, colon, port_text = netloc.rpartition(":")
        if not colon:
            raise _bad(text, "the port is missing (rtu+tcp://host:port)")
        if ":" in host:
            raise _bad(text, "write an IPv6 address in brackets: rtu+tcp://[::1]:5020")
    if not host:
        raise _bad(text, "the host is missing")
    if any(char.isspace() or char in "[]" for char in host):
        raise _bad(text, f"{host!r} is not a host name or address")
    if not port_text:
        raise _bad(text, "the port is missing")
    if not (port_text.isascii() and port_text.isdigit()):
        raise _bad(text, f"the port {port_text!r} is not a number")
    port = int(port_text)
    if not 1 <= port <= 65535:
        raise _bad(text, f"the port {port} is outside 1..65535")
    return TcpAddress(host, port)


def parse_port_url(text: str) -> PortAddress:
    """Parse a port name: a serial device path, or `rtu+tcp://host:port`.

    >>> parse_port_url("/dev/ttyUSB0")
    SerialAddress(path='/dev/ttyUSB0')
    >>> parse_port_url("rtu+tcp://[::1]:5020")
    TcpAddress(host='::1', port=5020)

    Raises [`InvalidValue`][aiortu.errors.InvalidValue] for an empty name, a scheme other than
    `rtu+tcp`, or an `rtu+tcp` URL without a valid host and port.
    """
    if not isinstance(text, str):
        raise InvalidValue("port", text, _URL_FORM, "not a string")
    if not text.strip():
        raise _bad(text, "the port name is empty")
    scheme, separator, rest = text.partition("://")
    if not separator:
        return SerialAddress(text)
    if scheme.lower() != TCP_SCHEME:
        raise _bad(text, f"unknown scheme {scheme!r}: only {TCP_SCHEME}:// is supported")
    return _parse_tcp(text, rest)

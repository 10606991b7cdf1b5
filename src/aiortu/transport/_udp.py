"""Modbus UDP: one MBAP ADU per datagram, for a master and for a server.

Modbus UDP is field practice rather than a Modbus.org spec: the ADU of Modbus TCP, one per
datagram, usually on port 502. Datagrams get lost, duplicated and reordered, and anyone can send
one, so both ends check every datagram on its own:

- a datagram that is not exactly one well-formed ADU (shorter than its MBAP length field says,
  longer, over 260 bytes, or with a bad header) is refused, counted and logged in one sentence;
  nothing after it is affected, since each datagram stands alone;
- a master takes replies only from the address it sends to: a datagram from any other address
  is dropped and counted ([`ModbusTcpCounters.strangers`][aiortu.transport.ModbusTcpCounters]);
- a master matches transaction ids as over TCP (the
  [`ModbusTcpStream`][aiortu.transport.ModbusTcpStream] it gets is the same one): a late or
  duplicated reply never reaches a later request, and its retries resend lost requests;
- a server answers each request to the datagram's source address
  ([`serve_datagrams`][aiortu.transport.serve_datagrams]).
"""

from __future__ import annotations

import socket
from collections.abc import Awaitable, Callable
from dataclasses import dataclass
from typing import Any

import anyio
import anyio.abc

from aiortu._log import get_logger
from aiortu.core.mbap import MAX_ADU_LENGTH, Adu, decode_adu
from aiortu.errors import FrameError, InvalidValue, PortNotFound
from aiortu.transport._listen import _tcp_error as listen_error  # a socket's bind errors
from aiortu.transport._mbap_stream import ModbusTcpCounters, ModbusTcpStream
from aiortu.transport._udp_push import (
    PushDatagramStream,
    log_level,
    open_push_datagrams,
    push_datagrams,
)
from aiortu.transport._url import MODBUS_UDP_SCHEME, format_tcp_url

__all__ = (
    "DatagramCounters",
    "check_datagram",
    "listen_udp",
    "open_modbus_udp",
    "serve_datagrams",
)

_log = get_logger(__name__)


def check_datagram(data: bytes) -> Adu:
    """The one ADU `data` holds; raises [`FrameError`][aiortu.errors.FrameError] with a
    one-sentence reason when it holds anything else."""
    if len(data) > MAX_ADU_LENGTH:
        raise FrameError(
            f"a Modbus UDP datagram holds one ADU of at most {MAX_ADU_LENGTH} bytes, "
            f"not {len(data)}",
            reason="length",
        )
    return decode_adu(data)


class _DatagramLink(anyio.abc.ByteStream):
    """The datagrams exchanged with one peer as a byte stream of whole, checked ADUs."""

    def __init__(
        self,
        sock: anyio.abc.UDPSocket,
        peer: tuple[str, int],
        counters: ModbusTcpCounters,
        where: str,
    ) -> None:
        self._socket = sock
        self._peer = peer
        self._counters = counters
        self._where = where

    @property
    def extra_attributes(self) -> Any:
        return self._socket.extra_attributes

    async def send(self, item: bytes) -> None:
        await self._socket.sendto(item, *self._peer)

    async def receive(self, max_bytes: int = 65536) -> bytes:
        while True:
            data, source = await self._socket.receive()
            if (source[0], source[1]) != self._peer:
                self._counters.strangers += 1
                _log.log(
                    log_level(self._counters.strangers),
                    "%s: dropped a datagram from %s, which is not the server (counted in "
                    "strangers; logged at debug level after the first)",
                    self._where,
                    format_tcp_url(source[0], source[1], MODBUS_UDP_SCHEME),
                )
                continue
            try:
                check_datagram(data)
            except FrameError as error:
                self._counters.refused += 1
                _log.log(
                    log_level(self._counters.refused),
                    "%s: refused a datagram: %s",
                    self._where,
                    error,
                )
                continue
            return data

    async def send_eof(self) -> None:
        pass  # datagrams have no end of stream

    async def aclose(self) -> None:
        await self._socket.aclose()


async def open_modbus_udp(
    host: str, port: int, *, counters: ModbusTcpCounters | None = None
) -> ModbusTcpStream | PushDatagramStream:
    """Talk Modbus UDP to the server at `host`:`port`; return a
    [`ModbusTcpStream`][aiortu.transport.ModbusTcpStream] of RTU frames over its datagrams.

    Raises [`PortNotFound`][aiortu.errors.PortNotFound] when the host is unknown and
    [`InvalidValue`][aiortu.errors.InvalidValue] for a port outside 1..65535. Nothing is sent
    before the first request: whether a server answers shows then. On asyncio the stream is a
    [`PushDatagramStream`][aiortu.transport.PushDatagramStream], which hands each reply over
    from the event loop's callback; elsewhere, a `ModbusTcpStream` over a datagram socket.
    """
    if isinstance(port, bool) or not isinstance(port, int) or not 1 <= port <= 65535:
        raise InvalidValue("port", port, range(1, 65536))
    where = format_tcp_url(host, port, MODBUS_UDP_SCHEME)
    try:
        found = await anyio.getaddrinfo(host, port, type=socket.SOCK_DGRAM)
    except socket.gaierror as exc:
        raise PortNotFound(where, f"unknown host {host!r} ({exc.strerror})") from exc
    family, _, _, _, address = found[0]
    counters = counters if counters is not None else ModbusTcpCounters()
    peer = (str(address[0]), int(address[1]))
    if push_datagrams():
        return await open_push_datagrams(family, peer, counters, where, check_datagram)
    if family == socket.AF_INET6:
        sock = await anyio.create_udp_socket(family=socket.AF_INET6)
    else:
        sock = await anyio.create_udp_socket(family=socket.AF_INET)
    link = _DatagramLink(sock, peer, counters, where)
    return ModbusTcpStream(link, counters)


async def listen_udp(host: str, port: int, *, url: str | None = None) -> anyio.abc.UDPSocket:
    """Bind a datagram socket to `host`:`port` (0: a free port) for a server.

    Raises [`PortBusy`][aiortu.errors.PortBusy],
    [`PortPermissionDenied`][aiortu.errors.PortPermissionDenied] or
    [`PortNotFound`][aiortu.errors.PortNotFound], as
    [`listen_tcp`][aiortu.transport.listen_tcp] does.
    """
    where = url or format_tcp_url(host, port, MODBUS_UDP_SCHEME)
    try:
        return await anyio.create_udp_socket(local_host=host, local_port=port)
    except socket.gaierror as exc:
        raise PortNotFound(where, f"unknown host {host!r} ({exc.strerror})") from exc
    except OSError as exc:
        raise listen_error(where, exc) from exc


@dataclass(slots=True)
class DatagramCounters:
    """What [`serve_datagrams`][aiortu.transport.serve_datagrams] received and sent."""

    received: int = 0
    """Datagrams received."""
    refused: int = 0
    """Datagrams that were not exactly one well-formed ADU, dropped unanswered."""
    replies: int = 0
    """Replies sent."""
    unsent: int = 0
    """Replies lost because the socket could not take them (its send buffer full)."""


async def serve_datagrams(
    sock: anyio.abc.UDPSocket,
    answer: Callable[[Adu], Awaitable[bytes | None]],
    counters: DatagramCounters,
) -> None:
    """Answer every well-formed request datagram on `sock` with `answer`'s reply ADU (None:
    no reply), sent to the datagram's source; refuse the rest. Runs until cancelled, one
    request at a time."""
    while True:
        data, source = await sock.receive()
        counters.received += 1
        try:
            adu = check_datagram(data)
        except FrameError as error:
            counters.refused += 1
            _log.log(
                log_level(counters.refused),
                "Modbus UDP: refused a datagram from %s: %s",
                format_tcp_url(source[0], source[1], MODBUS_UDP_SCHEME),
                error,
            )
            continue
        reply = await answer(adu)
        if reply is not None:
            counters.replies += 1
            await sock.sendto(reply, source[0], source[1])

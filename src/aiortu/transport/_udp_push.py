"""Modbus UDP for a master, pushed: each reply datagram handed over from the event loop's
callback.

Where the event loop is asyncio, [`open_modbus_udp`][aiortu.transport.open_modbus_udp] returns
this stream rather than a [`ModbusTcpStream`][aiortu.transport.ModbusTcpStream] over a datagram
socket read by a task: the loop's reader callback takes each datagram
(`DatagramSocket`), and the stream implements the push
extension
([`PushStream`][aiortu.transport.PushStream]), so the [`Link`][aiortu.line.Link] gets each reply
without a task wake-up and writes each request without a yield, and the master's usual exchange
runs over UDP as it does on a serial port.

It checks every datagram as the general path does, with the same functions: a datagram from
another address is dropped and counted in `strangers`, one that is not exactly one well-formed
ADU in `refused` ([`check_datagram`][aiortu.transport.check_datagram]), and a reply whose
transaction id is not the one outstanding in `dropped` (`reply_frame`, shared with
[`ModbusTcpStream`][aiortu.transport.ModbusTcpStream]). `push_datagrams` is the one predicate
that picks this path; the differential tests run the same exchanges through both.
"""

from __future__ import annotations

import logging
import socket
from collections.abc import Callable
from typing import Any

import anyio
import anyio.abc
import anyio.lowlevel

from aiortu._log import get_logger
from aiortu.core.mbap import Adu
from aiortu.errors import FrameError
from aiortu.transport._datagram_socket import DatagramSocket
from aiortu.transport._mbap_push import PushedMbap
from aiortu.transport._mbap_stream import ModbusTcpCounters
from aiortu.transport._push import loop_pushes
from aiortu.transport._url import MODBUS_UDP_SCHEME, format_tcp_url

__all__ = ("PushDatagramStream", "log_level", "open_push_datagrams", "push_datagrams")

_log = get_logger(__name__)

_Address = tuple[str, int]


def push_datagrams() -> bool:
    """Whether Modbus UDP reads its socket from the event loop's reader callback (a master's
    [`PushDatagramStream`][aiortu.transport.PushDatagramStream], a server's
    [`DatagramServer`][aiortu.transport.DatagramServer]): where the running loop is asyncio."""
    return loop_pushes()


def log_level(count: int) -> int:
    """Log the first of a kind as a warning and the rest at debug level: a flood of bad
    datagrams costs counts, not log lines."""
    return logging.WARNING if count == 1 else logging.DEBUG


class PushDatagramStream(PushedMbap):
    """RTU frames over Modbus UDP to `peer`, pushed (see the module docstring). Made by
    [`open_modbus_udp`][aiortu.transport.open_modbus_udp] on asyncio."""

    def __init__(
        self,
        peer: _Address,
        counters: ModbusTcpCounters,
        where: str,
        check: Callable[[bytes], Adu],
    ) -> None:
        super().__init__(counters, where)
        self.peer = peer
        self._check = check
        self.socket: DatagramSocket | None = None
        """The socket, once `open_push_datagrams`
        has opened it."""

    @property
    def extra_attributes(self) -> Any:
        return {anyio.abc.SocketAttribute.remote_address: lambda: self.peer}

    # -- receiving -------------------------------------------------------------------

    def datagram(self, data: bytes, source: Any) -> None:
        """The socket's callback: check `data`, and hand on the reply it carries."""
        counters = self.counters
        if (source[0], source[1]) != self.peer:
            counters.strangers += 1
            _log.log(
                log_level(counters.strangers),
                "%s: dropped a datagram from %s, which is not the server (counted in "
                "strangers; logged at debug level after the first)",
                self.where,
                format_tcp_url(source[0], source[1], MODBUS_UDP_SCHEME),
            )
            return
        if self.repeated_reply(data):
            return
        try:
            adu = self._check(data)
        except FrameError as error:
            counters.refused += 1
            _log.log(log_level(counters.refused), "%s: refused a datagram: %s", self.where, error)
            return
        self.hand_on(adu, data)

    def closed(self) -> None:
        """The socket closed (by `aclose`)."""
        self.lost(anyio.ClosedResourceError())

    # -- sending ---------------------------------------------------------------------

    def send_nowait(self, item: bytes) -> bool:
        """The push extension: send the RTU frame `item` as one datagram now, if the socket
        can take it now."""
        sock = self.socket
        if sock is None or self._error is not None:
            return False
        counters = self.counters
        transaction_id, adu = self.next_adu(item)
        if not sock.sendto(adu, self.peer):
            # Not sent: the id and the count are taken back, for send() to try again.
            counters.requests -= 1
            counters.next_transaction_id = transaction_id
            return False
        self._outstanding = transaction_id
        self._kept.clear()  # a new request: nothing that came before answers it
        return True

    async def send(self, item: bytes) -> None:
        """Send the RTU frame `item` as one datagram with the next transaction id, once the
        socket can take it."""
        await anyio.lowlevel.checkpoint()
        while not self.send_nowait(item):
            if self._error is not None or self.socket is None:
                raise self._error or anyio.ClosedResourceError()
            await self.socket.wait_writable()

    async def send_eof(self) -> None:
        pass  # datagrams have no end of stream

    async def aclose(self) -> None:
        if self.socket is not None:
            self.socket.close()
        self.closed()
        await anyio.lowlevel.checkpoint()


async def open_push_datagrams(
    family: int,
    peer: _Address,
    counters: ModbusTcpCounters,
    where: str,
    check: Callable[[bytes], Adu],
) -> PushDatagramStream:
    """A [`PushDatagramStream`][aiortu.transport.PushDatagramStream] to `peer` on a new socket
    of `family`, each datagram checked by `check` (on asyncio only; see `push_datagrams`)."""
    stream = PushDatagramStream(peer, counters, where, check)
    stream.socket = DatagramSocket(
        socket.socket(family, socket.SOCK_DGRAM), stream.datagram, stream.closed, where
    )
    return stream

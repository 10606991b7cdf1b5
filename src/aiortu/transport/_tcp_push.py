"""Modbus TCP and Modbus/TCP Security for a master, pushed: each reply handed over from the
event loop's callback.

Where the event loop is asyncio, [`open_modbus_tcp`][aiortu.transport.open_modbus_tcp] and
[`open_modbus_tls`][aiortu.transport.open_modbus_tls] return this stream rather than a
[`ModbusTcpStream`][aiortu.transport.ModbusTcpStream] over anyio's socket (and TLS) stream read
by a task: an `asyncio.Protocol` on asyncio's own transport (for `tls://` behind the
connection's own TLS layer, `TlsBioTransport` in `_tls_bio.py`) feeds each chunk to the MBAP
decoder in the loop's read callback, and the stream implements the push extension
([`PushStream`][aiortu.transport.PushStream]), so the [`Link`][aiortu.line.Link] gets each reply
without a task wake-up and writes each request without a yield, and the master's usual exchange
runs as it does on a serial port.

It decodes and matches replies as the general path does, with the same functions: a reply whose
transaction id is not the one outstanding is dropped and counted (`reply_frame`, through
`PushedMbap` in `_mbap_push.py`), and a malformed MBAP header closes the connection (`receive()`
raises `anyio.BrokenResourceError`, which a master takes as a lost connection). A chunk that
comes while no ADU is under way and is the last lone reply again, byte for byte after its
transaction id (a poll's usual reply), is not decoded again (`PushedMbap.repeated_reply`). A
server that stops reading holds the master back: a request is written at once only while the
transport's buffer is below its high-water mark, else `send()` waits for it to drain.
`push_connections` is the one predicate that picks this path; the differential tests run the
same exchanges through both.
"""

from __future__ import annotations

import asyncio
from collections.abc import Callable
from typing import Any, Final

import anyio
import anyio.abc
import anyio.lowlevel

from aiortu._log import get_logger
from aiortu.core.mbap import AduDecoder, MalformedHeader
from aiortu.transport._mbap_push import PushedMbap
from aiortu.transport._mbap_stream import ModbusTcpCounters, ModbusTcpStream
from aiortu.transport._push import WriteGate, ended, loop_pushes
from aiortu.transport._tcp import connect_protocol, open_tcp_connection
from aiortu.transport._url import MODBUS_TCP_SCHEME, format_tcp_url

__all__ = ("PushConnectionStream", "open_modbus_tcp", "open_pushed", "push_connections")

_log = get_logger(__name__)


def push_connections() -> bool:
    """Whether a master's Modbus TCP and Modbus/TCP Security streams are pushed: where the
    running loop is asyncio."""
    return loop_pushes()


_RECEIVE: Final = 4096
"""The buffer a plain connection receives into: replies are at most 260 bytes each."""


class _Protocol(asyncio.BufferedProtocol):
    """A plain connection receives into a buffer of its own, not into a new bytes object of
    asyncio's `max_size` (256 KiB) per read, whose cost moves with the process's heap; over TLS
    the TLS layer calls `data_received` with each record's plaintext."""

    def __init__(self, stream: PushConnectionStream) -> None:
        self.stream = stream
        self._buffer: memoryview | None = None
        self.data_received: Callable[[bytes], None] = stream.data
        """Where the TLS layer hands each record's plaintext: the stream's decoder, with no
        call in between."""

    def get_buffer(self, sizehint: int) -> memoryview:
        buffer = self._buffer
        if buffer is None:
            buffer = self._buffer = memoryview(bytearray(_RECEIVE))
        return buffer

    def buffer_updated(self, nbytes: int) -> None:
        self.stream.data(bytes(self._buffer[:nbytes]))  # type: ignore[index]  # got it first

    def eof_received(self) -> bool:
        self.stream.lost(anyio.EndOfStream())
        return False  # close the transport

    def connection_lost(self, exc: Exception | None) -> None:
        if exc is None:
            self.stream.lost(anyio.EndOfStream())
            return
        broken = anyio.BrokenResourceError(str(exc))
        broken.__cause__ = exc  # a TLS alert's reason, for one
        self.stream.lost(broken)

    def pause_writing(self) -> None:
        self.stream.gate.pause()

    def resume_writing(self) -> None:
        self.stream.resume_writing()


class PushConnectionStream(PushedMbap):
    """RTU frames over a Modbus TCP or Modbus/TCP Security connection, pushed (see the module
    docstring). Made by [`open_modbus_tcp`][aiortu.transport.open_modbus_tcp] and
    [`open_modbus_tls`][aiortu.transport.open_modbus_tls] on asyncio, connected by
    `connect`."""

    def __init__(self, counters: ModbusTcpCounters, where: str) -> None:
        super().__init__(counters, where)
        self.transport: asyncio.Transport | None = None
        self.protocol = _Protocol(self)
        """The asyncio protocol that feeds this stream (for `loop.create_connection`)."""
        self.gate = WriteGate()
        self._decoder = AduDecoder()
        self.refusal: Callable[[BaseException], BaseException] | None = None
        """What an end before the server's first byte means (set on a TLS connection, whose
        server may refuse the client's certificate only after the handshake)."""

    @property
    def extra_attributes(self) -> Any:
        transport = self.transport
        if transport is None:
            return {}
        return {
            anyio.abc.SocketAttribute.remote_address: lambda: transport.get_extra_info("peername"),
            anyio.abc.SocketAttribute.local_address: lambda: transport.get_extra_info("sockname"),
        }

    def data(self, data: bytes) -> None:
        """The protocol's callback: decode `data`, and hand on the reply it completes."""
        self.refusal = None  # the server spoke: it took the certificate
        decoder = self._decoder
        fresh = not decoder.buffered
        # A chunk that starts where no ADU is under way may be the last lone reply again.
        if fresh and self.repeated_reply(data):
            return
        try:
            adus = decoder.feed(data)
        except MalformedHeader as error:
            _log.warning("%s: closing the Modbus TCP connection: %s", self.where, error)
            self.forget_replies()
            self.lost(anyio.BrokenResourceError(str(error)))
            if self.transport is not None:
                self.transport.abort()
            return
        if fresh and len(adus) == 1 and not decoder.buffered:
            self.hand_on(adus[0], data)  # the chunk was this ADU alone
            return
        for adu in adus:
            self.hand_on(adu)

    def resume_writing(self) -> None:
        """The transport's buffer drained below its low-water mark."""
        self.gate.resume()

    def lost(self, error: BaseException) -> None:
        if self.refusal is not None and not isinstance(error, anyio.ClosedResourceError):
            error = self.refusal(error)
        super().lost(error)
        self.resume_writing()  # a writer waiting for the drain sees the end instead

    def send_nowait(self, item: bytes) -> bool:
        """The push extension: write the RTU frame `item` as one ADU now, unless the server
        has left earlier requests unread (the buffer above its high-water mark)."""
        transport = self.transport
        if transport is None or self._error is not None or not self.gate.open:
            return False
        transport.write(self.request(item))
        return True

    async def send(self, item: bytes) -> None:
        """Send the RTU frame `item` as one ADU with the next transaction id, once the
        transport's buffer has room."""
        await self.gate.write(self.send_nowait, item, lambda: ended(self._error, self.transport))

    async def send_eof(self) -> None:
        if self.transport is not None and self.transport.can_write_eof():
            self.transport.write_eof()

    async def aclose(self) -> None:
        if self.transport is not None:
            self.transport.close()
        self.lost(anyio.ClosedResourceError())
        await anyio.lowlevel.checkpoint()


async def open_pushed(
    host: str,
    port: int,
    counters: ModbusTcpCounters,
    *,
    connect_timeout: float,
    scheme: str,
) -> PushConnectionStream:
    """A [`PushConnectionStream`][aiortu.transport.PushConnectionStream] connected to
    `host`:`port` over plain TCP (asyncio only; see `push_connections`); errors as
    [`open_modbus_tcp`][aiortu.transport.open_modbus_tcp]'s, naming `scheme://host:port`."""
    stream = PushConnectionStream(counters, format_tcp_url(host, port, scheme))
    stream.transport = await connect_protocol(
        host, port, stream.protocol, connect_timeout=connect_timeout, scheme=scheme
    )
    return stream


async def open_modbus_tcp(
    host: str,
    port: int,
    *,
    connect_timeout: float = 5.0,
    counters: ModbusTcpCounters | None = None,
) -> ModbusTcpStream | PushConnectionStream:
    """Connect to the Modbus TCP server at `host`:`port` and return the connection as a
    stream of RTU frames: a [`ModbusTcpStream`][aiortu.transport.ModbusTcpStream], or on
    asyncio a [`PushConnectionStream`][aiortu.transport.PushConnectionStream], which hands each
    reply over from the event loop's callback.

    `counters` continue those of an earlier connection (see
    [`ModbusTcpCounters`][aiortu.transport.ModbusTcpCounters]). Raises
    [`PortNotFound`][aiortu.errors.PortNotFound] when the host is unknown, the connection is
    refused or fails, or nothing answers within `connect_timeout` seconds, and
    [`InvalidValue`][aiortu.errors.InvalidValue] for a port outside 1..65535 or a timeout that
    is not positive.
    """
    counters = counters if counters is not None else ModbusTcpCounters()
    if push_connections():
        return await open_pushed(
            host, port, counters, connect_timeout=connect_timeout, scheme=MODBUS_TCP_SCHEME
        )
    stream = await open_tcp_connection(
        host, port, connect_timeout=connect_timeout, scheme=MODBUS_TCP_SCHEME
    )
    return ModbusTcpStream(stream, counters)

"""The broker connection on asyncio's own transport: received bytes handed over from the
event loop's read callback, written without a yield.

Where the running event loop is asyncio (`push_session`, the one predicate), the
[`BrokerSession`][aiortu.bridge.BrokerSession] connects through a `PushedLink`, an
`asyncio.Protocol`, rather than
anyio's socket stream read by a task: the broker's acknowledgements are read in the loop's
callback, and what the bridge puts in the outbox is written from the call that put it. The
session does the same things on both paths with the same functions (the packets, their ids,
their order); only who reads and who writes differs, and a differential test holds the
two to the same packets.

Before the session hands it a receiver, the link keeps what it receives for `receive()` (the
CONNACK is read that way), and it writes only while the transport's buffer is below its
high-water mark (`writable`): a broker that
stops reading leaves the messages in the bounded outbox, not in the transport.

A broker acknowledges a poll's messages one by one as it takes them, so the PUBACKs of one
write come in as many reads as the broker was quick (up to one each, on an idle machine), each
a turn of the event loop. On a plain TCP connection on Linux the session tells the link when
to wake it (`expect`), and the link asks the kernel not to wake it before that many bytes are
there (`SO_RCVLOWAT`; the end of the connection wakes it whatever the mark). The mark is one
byte above the PUBACKs of what is in flight (every QoS 1 PUBLISH the broker took gets its
PUBACK): the PUBACKs alone wake nobody. They wait in the kernel until the outbox is filled
again, and the session reads them first (`collect`, a read that does not wait), in the turn
of the loop the poll woke anyway: at QoS 1 a poll wakes the process no more than at QoS 0.
Any other byte (a command, a PINGRESP) lifts what is there over the mark once the PUBACKs are
in, so a command that comes meanwhile is read with them. The mark is one byte whenever the
session needs an answer to go on: while messages wait for room in the window, which each
PUBACK makes, and after a PINGREQ until the broker says anything, so the keep-alive hears the
PINGRESP as before (and the PUBACKs are read at least once a half keep-alive).
"""

from __future__ import annotations

import asyncio
import os
import socket
import ssl
import sys
from collections.abc import Callable

import anyio
import anyio.lowlevel

from aiortu.transport import loop_pushes

__all__ = ("PushedLink", "open_pushed", "push_session")


def push_session() -> bool:
    """Whether the session to the broker is pushed: where the running loop is asyncio (on trio
    the session reads anyio's stream in a task)."""
    return loop_pushes()


class PushedLink(asyncio.Protocol):
    """An MQTT connection on an asyncio transport (see the module docstring)."""

    def __init__(self) -> None:
        self.transport: asyncio.Transport | None = None
        self.writable = False
        """Whether a write goes out now: connected, and the transport's buffer below its
        high-water mark."""
        self.on_writable: Callable[[], None] | None = None
        """Called when the buffer drains below its low-water mark."""
        self._receiver: Callable[[bytes], None] | None = None
        self._kept: list[bytes] = []
        self._arrived: asyncio.Future[None] | None = None
        self._ended: asyncio.Future[None] = asyncio.get_running_loop().create_future()
        self._error: BaseException | None = None
        self._socket: socket.socket | None = None  # where `expect` sets the mark, if it can
        self._mark = 1

    # asyncio's callbacks

    def connection_made(self, transport: asyncio.BaseTransport) -> None:
        assert isinstance(transport, asyncio.Transport)
        self.transport, self.writable = transport, True
        if _MARKS and transport.get_extra_info("sslcontext") is None:
            self._socket = transport.get_extra_info("socket")

    def data_received(self, data: bytes) -> None:
        receiver = self._receiver
        if receiver is None:
            self._kept.append(data)
            self._wake_receive()
            return
        try:
            receiver(data)
        except Exception as error:  # bytes that are not MQTT, or a bug: either ends the link
            self.end(error)
            if self.transport is not None:
                self.transport.abort()

    def eof_received(self) -> bool:
        self.end(anyio.EndOfStream())
        return False  # close the transport

    def connection_lost(self, exc: Exception | None) -> None:
        self.end(anyio.EndOfStream() if exc is None else exc)

    def pause_writing(self) -> None:
        self.writable = False

    def resume_writing(self) -> None:
        self.writable = self._error is None
        if self.writable and self.on_writable is not None:
            self.on_writable()

    # the session's side

    def set_receiver(self, receiver: Callable[[bytes], None]) -> None:
        """Hand every chunk from now on to `receiver`, in the loop's callback; those kept for
        `receive()` go to it at once. An exception from `receiver` ends the link with it."""
        self._receiver = receiver
        kept, self._kept = self._kept, []
        for data in kept:
            self.data_received(data)

    def expect(self, size: int) -> None:
        """Wake the receiver only once `size` bytes (at least 1) can be read, or the
        connection ends: at most one byte more than what will come, the rest read by
        `collect` (see the module docstring). Where the mark cannot be set (TLS, not Linux),
        every chunk wakes it."""
        size = max(1, size)
        if size == self._mark or self._socket is None or self._error is not None:
            return
        try:
            self._socket.setsockopt(socket.SOL_SOCKET, socket.SO_RCVLOWAT, size)
        except OSError:  # a socket that takes no mark: read every chunk, as elsewhere
            self._socket = None
            return
        self._mark = size

    def collect(self) -> None:
        """Hand what waits below the mark in the kernel to the receiver, as the loop's
        callback would (an error ends the link), without waiting. Nothing is read while the
        mark is one byte: the loop's callback reads every chunk then. The end of the
        connection is left for that callback, which reads it as ever."""
        if self._mark == 1 or self._socket is None:
            return
        try:
            data = os.read(self._socket.fileno(), _COLLECT)
        except BlockingIOError:
            return
        except OSError as error:
            self.end(error)
            if self.transport is not None:
                self.transport.abort()
            return
        self.data_received(data)  # empty at the end, which the loop's callback then reads

    def write(self, data: bytes) -> None:
        """Write `data` now (nothing once the link has ended)."""
        if self._error is None and self.transport is not None:
            self.transport.write(data)

    async def send(self, data: bytes) -> None:
        """Write `data`, or raise what ended the link."""
        if self._error is not None:
            raise self._error
        self.write(data)

    async def receive(self) -> bytes:
        """The next chunk kept (before a receiver is set), or raise what ended the link."""
        while not self._kept:
            if self._error is not None:
                raise self._error
            self._arrived = asyncio.get_running_loop().create_future()
            try:
                await self._arrived
            finally:
                self._arrived = None
        return self._kept.pop(0)

    async def ended(self) -> None:
        """Wait for the end of the link; raise what ended it."""
        await asyncio.shield(self._ended)

    def end(self, error: BaseException) -> None:
        """The link ended with `error` (the first end counts): `ended()` and `receive()`
        raise it, and nothing more is written."""
        if self._error is None:
            self._error, self.writable = error, False
            self._ended.set_exception(error)
            self._ended.exception()  # retrieved: no warning when nobody waits
            self._wake_receive()

    def abort(self) -> None:
        """Close at once, dropping what is not written yet."""
        self.end(anyio.ClosedResourceError())
        if self.transport is not None:
            self.transport.abort()

    async def aclose(self) -> None:
        """Close after what is written has gone out (a DISCONNECT, for one)."""
        self.end(anyio.ClosedResourceError())
        if self.transport is not None:
            self.transport.close()
        await anyio.lowlevel.checkpoint()

    def _wake_receive(self) -> None:
        if self._arrived is not None and not self._arrived.done():
            self._arrived.set_result(None)


_MARKS = sys.platform == "linux"
"""Whether `expect` sets the socket's receive low-water mark: Linux's epoll honours it for TCP
(and wakes on the connection's end whatever the mark)."""

_COLLECT = 256 * 1024
"""The most `collect` reads at once (what asyncio's read callback takes at once)."""


async def open_pushed(host: str, port: int, context: ssl.SSLContext | None) -> PushedLink:
    """A `PushedLink` connected to `host`:`port`,
    over TLS with `context` if given (asyncio only); raises OSError when it cannot connect,
    `ssl.SSLError` when the handshake fails."""
    link = PushedLink()
    await asyncio.get_running_loop().create_connection(
        lambda: link, host, port, ssl=context, server_hostname=host if context else None
    )
    return link

"""Server connections on asyncio's own transports, whose read callback may answer a request
at once.

A Modbus TCP or Modbus/TCP Security server reads each connection in a task of its own
([`ModbusTcpServer.serve_connection`][aiortu.slave.ModbusTcpServer.serve_connection]): a task
wake-up, anyio's socket stream and, over TLS, anyio's TLS stream on every request. Where
`push_listener` allows it (the running loop is asyncio and the listener is anyio's TCP
listener), `pushed_listener` puts the listener's sockets behind `PushListener`, whose
connections are `PushServerStream`s: byte streams on asyncio's transport (behind
`PushTlsListener`, with the connection's own TLS layer, `TlsBioTransport` in `_tls_bio.py`),
read by the same task through `receive()` as any stream, and also offering the server a *tap*: a
function that gets each chunk received while the task waits for bytes with nothing unread, and
may answer it from the read callback. A chunk the tap declines is kept for `receive()`, as any
other. Nothing else changes: the accept loop
([`serve_listener`][aiortu.transport.serve_listener]) with its limits, the handshake's timeout
and its one-sentence failures ([`TlsListener`][aiortu.transport.TlsListener]), the task's own
idle timeout and framing.

Back-pressure holds as on anyio's streams: bytes the task has not read stop reading from the
socket until it asks for more, and a client that does not read its replies fills the transport's
write buffer, which stops the tap (the task's `send()` then waits for the buffer to drain).
"""

from __future__ import annotations

import asyncio
import socket
import ssl
from collections.abc import Callable, Mapping
from typing import Any, cast, overload

import anyio
import anyio.abc
import anyio.lowlevel
from anyio.streams.stapled import MultiListener
from anyio.streams.tls import TLSAttribute

from aiortu.transport._push import WriteGate, ended, loop_pushes
from aiortu.transport._tls import TlsListener
from aiortu.transport._tls_bio import TlsBioTransport

__all__ = (
    "PushListener",
    "PushServerStream",
    "PushTlsListener",
    "push_listener",
    "pushed_listener",
)

Tap = Callable[[bytes], bool]
"""`tap(chunk)`: answer `chunk` at once and return True, or return False (nothing done)."""


class _Protocol(asyncio.Protocol):
    def __init__(self, stream: PushServerStream) -> None:
        self.stream = stream

    def data_received(self, data: bytes) -> None:
        self.stream.data(data)

    def eof_received(self) -> bool:
        # A half-closed client still reads its replies: the server closes once it is done
        # (over TLS, asyncio closes the transport whatever this returns).
        if self.stream.half_close:
            self.stream.ended = True
            self.stream.wake()
            return True
        self.stream.lost(anyio.EndOfStream())
        return False

    def connection_lost(self, exc: Exception | None) -> None:
        self.stream.lost(anyio.BrokenResourceError(str(exc)) if exc else anyio.EndOfStream())

    def pause_writing(self) -> None:
        self.stream.gate.pause()

    def resume_writing(self) -> None:
        self.stream.resume_writing()


class PushServerStream(anyio.abc.SocketStream):
    """An accepted connection on asyncio's transport (see the module docstring); made by
    [`PushListener`][aiortu.transport.PushListener], connected by `connect`."""

    def __init__(self, sock: socket.socket) -> None:
        self._socket = sock
        try:  # kept: a failed handshake closes the socket before its failure is logged
            self._peer: tuple[str, int] | None = sock.getpeername()[:2]
        except OSError:
            self._peer = None  # reset in the backlog: the accept loop closes it
        self.transport: asyncio.Transport | None = None
        self.tap: Tap | None = None
        """The server's function that may answer a chunk at once (see the module docstring)."""
        self.gate = WriteGate()
        self.half_close = False
        """Whether the transport stays open for the replies after the client's end of stream
        (plain TCP only)."""
        self.ended = False
        """Whether the client ended its stream (half-closed: replies may still be sent)."""
        self._kept = bytearray()
        self._error: BaseException | None = None
        self._waiter: asyncio.Future[None] | None = None

    async def connect(self, context: ssl.SSLContext | None = None) -> None:
        """Make the transport, over TLS with `context` (whose handshake's errors raise: the
        caller bounds its time); reading waits for the first `receive()`."""
        loop = asyncio.get_running_loop()
        if context is None:
            self.transport, _ = await loop.connect_accepted_socket(
                lambda: _Protocol(self), self._socket
            )
            self.half_close = True
        else:
            tls = TlsBioTransport(context, _Protocol(self), server_side=True)
            await loop.connect_accepted_socket(lambda: tls, self._socket)
            self.transport = tls  # what aclose() closes from now on, the socket with it
            await tls.handshake()
        self.transport.pause_reading()  # until the first receive()

    @property
    def _raw_socket(self) -> socket.socket:
        return self._socket

    @property
    def extra_attributes(self) -> Mapping[Any, Callable[[], Any]]:
        attributes: dict[Any, Callable[[], Any]] = {}
        if self._socket.fileno() >= 0:
            attributes.update(super().extra_attributes)
        peer = self._peer
        if peer is not None:
            attributes[anyio.abc.SocketAttribute.remote_address] = lambda: peer
            attributes[anyio.abc.SocketAttribute.remote_port] = lambda: peer[1]
        ssl_object = None if self.transport is None else self.transport.get_extra_info("ssl_object")
        if ssl_object is not None:
            attributes[TLSAttribute.peer_certificate_binary] = lambda: ssl_object.getpeercert(
                binary_form=True
            )
            attributes[TLSAttribute.ssl_object] = lambda: ssl_object
        return attributes

    # -- receiving -------------------------------------------------------------------

    def data(self, data: bytes) -> None:
        """The protocol's callback: the tap's, when the task waits with nothing unread and the
        client reads its replies; else kept for `receive()`, reading paused meanwhile."""
        tap = self.tap
        if (
            tap is not None
            and self._waiter is not None
            and not self._kept
            and self.gate.open
            and tap(data)
        ):
            return
        self._kept += data
        if self.transport is not None:
            self.transport.pause_reading()
        self.wake()

    def lost(self, error: BaseException) -> None:
        """The connection ended with `error` (the first one counts)."""
        if self._error is None:
            self._error = error
        self.wake()
        self.resume_writing()  # a writer waiting for the drain sees the end instead

    def wake(self) -> None:
        """Wake the task waiting in `receive()`."""
        waiter = self._waiter
        if waiter is not None and not waiter.done():
            waiter.set_result(None)

    async def receive(self, max_bytes: int = 65536) -> bytes:
        """At most `max_bytes` of the bytes received and not yet read."""
        if self._kept:
            await anyio.lowlevel.checkpoint()
        while not self._kept:
            if self._error is not None:
                raise self._error
            if self.ended:
                raise anyio.EndOfStream()
            if self.transport is None:
                raise anyio.ClosedResourceError()
            self.transport.resume_reading()
            self._waiter = asyncio.get_running_loop().create_future()
            try:
                await self._waiter
            finally:
                self._waiter = None
        data = bytes(self._kept[:max_bytes])
        del self._kept[:max_bytes]
        return data

    # -- sending ---------------------------------------------------------------------

    def resume_writing(self) -> None:
        """The transport's buffer drained below its low-water mark."""
        self.gate.resume()

    def write_now(self, data: bytes) -> bool:
        """Write `data` at once where the client reads its replies; False (nothing written)
        while the write buffer is above its high-water mark, or the connection is gone."""
        transport = self.transport
        if transport is None or self._error is not None or not self.gate.open:
            return False
        transport.write(data)
        return True

    async def send(self, item: bytes) -> None:
        """Write `item` once the transport's buffer has room."""
        await self.gate.write(self.write_now, item, lambda: ended(self._error, self.transport))

    async def send_eof(self) -> None:
        if self.transport is not None and self.transport.can_write_eof():
            self.transport.write_eof()

    async def aclose(self) -> None:
        if self.transport is not None:
            self.transport.close()
        else:
            self._socket.close()
        self.lost(anyio.ClosedResourceError())
        await anyio.lowlevel.checkpoint()


class PushListener(anyio.abc.SocketListener):
    """anyio's TCP `listener`, accepting [`PushServerStream`][aiortu.transport.PushServerStream]s
    (plain ones connected at once; `tls` leaves that to
    [`PushTlsListener`][aiortu.transport.PushTlsListener]'s handshake)."""

    def __init__(self, listener: anyio.abc.SocketListener, *, tls: bool = False) -> None:
        self.listener = listener
        self._tls = tls

    @property
    def _raw_socket(self) -> socket.socket:
        return self.listener.extra(anyio.abc.SocketAttribute.raw_socket)

    async def accept(self) -> PushServerStream:
        loop = asyncio.get_running_loop()
        sock, _ = await loop.sock_accept(self._raw_socket)
        sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
        stream = PushServerStream(sock)
        if not self._tls:
            try:
                await stream.connect()
            except BaseException:
                sock.close()
                raise
        return stream

    async def aclose(self) -> None:
        await self.listener.aclose()


class PushTlsListener(TlsListener):
    """[`TlsListener`][aiortu.transport.TlsListener] over a
    [`PushListener`][aiortu.transport.PushListener]: the handshake by the connection's own TLS
    layer on asyncio's plain transport (which sends the alert of a refused one before it
    closes), its failures told and counted the same way."""

    async def handshake(self, stream: anyio.abc.ByteStream) -> anyio.abc.ByteStream | None:
        """`stream` once its TLS handshake on asyncio's transport is done; None when it
        failed (logged, counted, `stream` closed)."""
        assert isinstance(stream, PushServerStream)
        try:
            with anyio.fail_after(self.handshake_timeout):
                await stream.connect(self.ssl_context)
        except BaseException as error:
            await self.handle_handshake_error(error, stream)
            return None
        return stream


def push_listener(listener: anyio.abc.Listener[Any]) -> bool:
    """Whether `listener`'s connections may be `PushServerStream`s: the running loop is
    asyncio, and `listener` is anyio's TCP listener (its sockets in a `MultiListener`)."""
    if not loop_pushes() or not isinstance(listener, MultiListener):
        return False
    return all(
        isinstance(each, anyio.abc.SocketListener)
        and each.extra(anyio.abc.SocketAttribute.family, None) in (socket.AF_INET, socket.AF_INET6)
        for each in listener.listeners
    )


@overload
def pushed_listener(listener: anyio.abc.Listener[Any]) -> anyio.abc.Listener[Any]: ...


@overload
def pushed_listener(
    listener: anyio.abc.Listener[Any], context: ssl.SSLContext, **tls: Any
) -> PushTlsListener: ...


def pushed_listener(
    listener: anyio.abc.Listener[Any], context: ssl.SSLContext | None = None, **tls: Any
) -> anyio.abc.Listener[Any]:
    """`listener`'s sockets behind [`PushListener`][aiortu.transport.PushListener]s; with an
    SSL `context`, behind a [`PushTlsListener`][aiortu.transport.PushTlsListener] too (`tls`:
    its other fields, as `handshake_timeout`)."""
    assert isinstance(listener, MultiListener), "push_listener(listener) is true"
    pushed = MultiListener(
        [
            PushListener(cast(anyio.abc.SocketListener, each), tls=context is not None)
            for each in listener.listeners
        ]
    )
    if context is None:
        return pushed
    return PushTlsListener(pushed, context, **tls)

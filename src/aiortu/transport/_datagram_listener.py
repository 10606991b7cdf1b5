"""Modbus UDP as a listener of connections: each source address a stream of its own.

A server built on connections (the gateway, with its window per connection, its fairness
between them, its idle timeout and its connection limit) serves Modbus UDP through
[`DatagramListener`][aiortu.transport.DatagramListener] unchanged: the first datagram from an
address opens a stream for it, each later datagram from there is received on that stream as one
whole ADU, and what the server sends on the stream goes to that address. The server closes a
peer's stream as it closes a connection (idle, or over the limit); the peer's next datagram opens
a new one.

Each datagram is checked on its own ([`check_datagram`][aiortu.transport.check_datagram]): one
that is not exactly one well-formed ADU is refused and counted, and so is one that arrives while
its peer has [`PEER_BACKLOG`][aiortu.transport.PEER_BACKLOG] datagrams not yet read (a client
flooding the server loses datagrams, as UDP would, rather than memory).
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import anyio
import anyio.abc
from anyio.streams.memory import MemoryObjectReceiveStream, MemoryObjectSendStream

from aiortu._log import get_logger
from aiortu.errors import FrameError
from aiortu.transport._udp import DatagramCounters, check_datagram
from aiortu.transport._udp_push import log_level
from aiortu.transport._url import MODBUS_UDP_SCHEME, format_tcp_url

__all__ = ("PEER_BACKLOG", "DatagramListener")

_log = get_logger(__name__)

PEER_BACKLOG = 16
"""Datagrams a peer may have waiting to be read; more are dropped and counted as refused."""

_Address = tuple[str, int]


class _PeerStream(anyio.abc.ByteStream):
    """The datagrams of one source address, as a stream of whole ADUs."""

    def __init__(self, listener: DatagramListener, peer: _Address) -> None:
        self._listener = listener
        self.peer = peer
        self.inbox: MemoryObjectSendStream[bytes]
        self._outbox: MemoryObjectReceiveStream[bytes]
        self.inbox, self._outbox = anyio.create_memory_object_stream[bytes](PEER_BACKLOG)

    @property
    def extra_attributes(self) -> Any:
        local = self._listener.local_address
        return {
            anyio.abc.SocketAttribute.remote_address: lambda: self.peer,
            anyio.abc.SocketAttribute.local_address: lambda: local,
        }

    async def send(self, item: bytes) -> None:
        listener = self._listener
        # The peers share one socket, which takes one writer at a time.
        async with listener.sending:
            await listener.socket.sendto(item, *self.peer)
        listener.counters.replies += 1

    async def receive(self, max_bytes: int = 65536) -> bytes:
        try:
            return await self._outbox.receive()
        except (anyio.EndOfStream, anyio.ClosedResourceError):
            raise anyio.EndOfStream from None

    async def send_eof(self) -> None:
        pass  # datagrams have no end of stream

    async def aclose(self) -> None:
        if self._listener.peers.get(self.peer) is self:
            del self._listener.peers[self.peer]
        self.inbox.close()
        self._outbox.close()


class DatagramListener(anyio.abc.Listener[anyio.abc.ByteStream]):
    """Modbus UDP on `sock`, one stream per source address (see the module docstring); `url`
    names it in logs. What it received and refused is counted in
    [`counters`][aiortu.transport.DatagramListener.counters]."""

    def __init__(self, sock: anyio.abc.UDPSocket, url: str) -> None:
        self.socket = sock
        self.url = url
        self.counters = DatagramCounters()
        """Datagrams received, refused (malformed, or over a peer's backlog) and answered."""
        self.peers: dict[_Address, _PeerStream] = {}
        """The stream of each source address being served."""
        self.sending = anyio.Lock()
        """Held by the peer stream that writes to the socket."""
        local = sock.extra(anyio.abc.SocketAttribute.local_address)
        self.local_address: _Address = (str(local[0]), int(local[1]))
        """The host and port the socket is bound to."""

    @property
    def extra_attributes(self) -> Any:
        return {anyio.abc.SocketAttribute.local_address: lambda: self.local_address}

    async def serve(
        self,
        handler: Callable[[anyio.abc.ByteStream], Any],
        task_group: anyio.abc.TaskGroup | None = None,
    ) -> None:
        """Receive datagrams until cancelled; run `handler` in a task on the stream of each new
        source address."""
        async with anyio.create_task_group() as tasks:
            while True:
                data, source = await self.socket.receive()
                self.counters.received += 1
                peer = (str(source[0]), int(source[1]))
                if not self._checked(data, peer):
                    continue
                stream = self.peers.get(peer)
                if stream is None:
                    stream = self.peers[peer] = _PeerStream(self, peer)
                    (task_group or tasks).start_soon(handler, stream)
                try:
                    stream.inbox.send_nowait(data)
                except (anyio.WouldBlock, anyio.ClosedResourceError):
                    self._refuse(peer, "its backlog of unread requests is full")

    def _checked(self, data: bytes, peer: _Address) -> bool:
        try:
            check_datagram(data)
        except FrameError as error:
            self._refuse(peer, str(error))
            return False
        return True

    def _refuse(self, peer: _Address, why: str) -> None:
        self.counters.refused += 1
        _log.log(
            log_level(self.counters.refused),
            "%s: refused a datagram from %s: %s (counted; logged at debug level after the first)",
            self.url,
            format_tcp_url(peer[0], peer[1], MODBUS_UDP_SCHEME),
            why,
        )

    async def aclose(self) -> None:
        for stream in list(self.peers.values()):
            await stream.aclose()
        await self.socket.aclose()

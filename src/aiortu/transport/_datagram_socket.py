"""A datagram socket read from the event loop's reader callback: each datagram handed over as it
arrives, each write straight to the socket.

asyncio's own datagram transport receives every datagram into a new buffer of 256 KiB (its
`max_size`), which the C library serves with `mmap` and frees with `munmap`: on the machine of
the benchmarks about 20 us of CPU per datagram, more than all the rest of a Modbus UDP exchange
on one side. Both ends of Modbus UDP on asyncio (the master's
[`PushDatagramStream`][aiortu.transport.PushDatagramStream] and the server's
[`DatagramServer`][aiortu.transport.DatagramServer]) read their socket here instead: the loop's
reader callback receives at most `RECEIVE_SIZE` bytes at a time, which holds any UDP datagram
whole, so lengths are exact and an oversize datagram is refused for what it is.
"""

from __future__ import annotations

import asyncio
import socket
from collections.abc import Callable
from typing import Any, Final

from aiortu._log import get_logger

__all__ = ("RECEIVE_SIZE", "DatagramSocket")

_log = get_logger(__name__)

RECEIVE_SIZE: Final = 65536
"""The bytes read at once: more than the largest UDP datagram (65,507 bytes over IPv4)."""


class DatagramSocket:
    """The non-blocking datagram socket `sock`, read by the running asyncio loop: `on_datagram`
    gets each datagram and its source address, in the loop's thread; `on_closed` is called once
    when the socket is closed. `where` names it in logs.
    """

    __slots__ = (
        "_fd",
        "_loop",
        "_on_closed",
        "_on_datagram",
        "_sock",
        "_writable",
        "closed",
        "where",
    )

    def __init__(
        self,
        sock: socket.socket,
        on_datagram: Callable[[bytes, Any], None],
        on_closed: Callable[[], None],
        where: str,
    ) -> None:
        sock.setblocking(False)
        self._sock = sock
        self._on_datagram = on_datagram
        self._on_closed = on_closed
        self.where = where
        self.closed = False
        """Whether `close` was called."""
        self._writable: asyncio.Future[None] | None = None
        self._loop = asyncio.get_running_loop()
        self._fd = sock.fileno()
        self._loop.add_reader(self._fd, self._readable)

    @property
    def local_address(self) -> tuple[str, int]:
        """The host and port the socket is bound to."""
        name = self._sock.getsockname()
        return str(name[0]), int(name[1])

    def _readable(self) -> None:
        # One datagram a call, as asyncio's transport reads: another waiting makes the loop
        # call again, and no read ends in a refused one (a syscall and an exception more).
        try:
            data, source = self._sock.recvfrom(RECEIVE_SIZE)
        except (BlockingIOError, InterruptedError):
            return
        except OSError as exc:
            # An ICMP error the socket reports (a peer's port closed): what it concerns is
            # lost, as a datagram may be; retries and timeouts deal with it.
            _log.debug("%s: %s", self.where, exc)
            return
        self._on_datagram(data, source)

    def sendto(self, data: bytes, address: Any) -> bool:
        """Send `data` to `address` now; False when the socket cannot take it now (its send
        buffer is full) or is closed. A datagram the network refuses (no route, say) counts as
        sent: it is lost, as a datagram may be, and logged at debug level."""
        if self.closed:
            return False
        try:
            self._sock.sendto(data, address)
        except (BlockingIOError, InterruptedError):
            return False
        except OSError as exc:
            _log.debug("%s: sending to %s: %s", self.where, address, exc)
        return True

    async def wait_writable(self) -> None:
        """Wait until the socket can take a datagram, or is closed."""
        if self.closed:
            return
        future = self._writable = self._loop.create_future()
        self._loop.add_writer(self._fd, self._wake_writer)
        try:
            await future
        finally:
            self._writable = None
            if not self.closed:
                self._loop.remove_writer(self._fd)

    def _wake_writer(self) -> None:
        future = self._writable
        if future is not None and not future.done():
            future.set_result(None)

    def close(self) -> None:
        """Stop reading, close the socket, and tell `on_closed` (once)."""
        if self.closed:
            return
        self.closed = True
        self._loop.remove_reader(self._fd)
        self._loop.remove_writer(self._fd)
        self._wake_writer()
        self._sock.close()
        self._on_closed()

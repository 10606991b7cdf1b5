"""Modbus UDP for a server, pushed: each request answered in the event loop's callback where it
can be, the rest queued, within a bound, for one task.

Where the event loop is asyncio ([`push_datagrams`][aiortu.transport.push_datagrams]), a server
serves Modbus UDP through [`DatagramServer`][aiortu.transport.DatagramServer], an
`asyncio.DatagramProtocol`, rather than through
[`serve_datagrams`][aiortu.transport.serve_datagrams] on a socket read by a task. Each datagram
is checked in the loop's read callback as `serve_datagrams` checks it, with the same function
([`check_datagram`][aiortu.transport.check_datagram]), the same counts
([`DatagramCounters`][aiortu.transport.DatagramCounters]) and the same log lines (the first of
a kind a warning, the rest at debug level). Then:

- the server's `at_once` callback may answer the request then and there (a store that answers
  from memory): no task wakes, and the reply goes out from the callback;
- else the request waits for the server's task, which answers the waiting requests one at a
  time, in order (`answer`, which may await a handler, a hook or a store). At most `backlog`
  requests wait, the one being answered included: more are refused and counted, as a flood of
  datagrams should cost lost datagrams, not memory.

The `at_once` callback sees `pending`, the requests waiting or being answered: it must not
answer while any are (a request answered at once would overtake them). The server's
predicate (`AnswerAtOnce.may_answer` in the slave) holds that condition with the others.
"""

from __future__ import annotations

import asyncio
import socket
from collections import deque
from collections.abc import Awaitable, Callable
from typing import Any, Final, cast

from aiortu._log import get_logger
from aiortu.core.mbap import Adu
from aiortu.errors import FrameError, PortNotFound
from aiortu.transport._listen import _tcp_error as listen_error  # a socket's bind errors
from aiortu.transport._udp import DatagramCounters, check_datagram
from aiortu.transport._udp_push import log_level
from aiortu.transport._url import MODBUS_UDP_SCHEME, format_tcp_url

__all__ = ("DATAGRAM_BACKLOG", "DatagramServer", "DatagramSource")

_log = get_logger(__name__)

DATAGRAM_BACKLOG: Final = 64
"""Requests a [`DatagramServer`][aiortu.transport.DatagramServer] keeps waiting for its task by
default; more are refused and counted."""

DatagramSource = tuple[Any, ...]
"""A datagram's source address, as the socket gives it (host and port first)."""


class DatagramServer(asyncio.DatagramProtocol):
    """Modbus UDP for a server on asyncio (see the module docstring).

    `answer` gives the reply ADU to a request ADU (None: no reply), in the server's task;
    `at_once(adu, source)` answers a request in the read callback if it can (True) with
    [`reply`][aiortu.transport.DatagramServer.reply], or leaves it (False); `counters` counts
    what was received, refused and answered; `url` names the server in errors; `pending` is the
    deque that holds the requests waiting (one that `at_once` sees, say; a new one by
    default). Bind it with
    [`bind`][aiortu.transport.DatagramServer.bind], then run
    [`serve`][aiortu.transport.DatagramServer.serve] until cancelled.
    """

    def __init__(
        self,
        answer: Callable[[Adu], Awaitable[bytes | None]],
        counters: DatagramCounters,
        *,
        at_once: Callable[[Adu, DatagramSource], bool] | None = None,
        url: str = "Modbus UDP",
        backlog: int = DATAGRAM_BACKLOG,
        pending: deque[tuple[Adu, DatagramSource]] | None = None,
    ) -> None:
        self._answer = answer
        self._at_once = at_once
        self.counters = counters
        self.url = url
        self.backlog = backlog
        """The most requests waiting for the task (the one being answered included)."""
        self.pending = deque() if pending is None else pending
        """The requests waiting for the task, first the one it answers (if any): `pending`,
        or a new deque."""
        self.transport: asyncio.DatagramTransport | None = None
        self._waiter: asyncio.Future[None] | None = None
        self._lost: asyncio.Future[None] | None = None

    async def bind(self, host: str, port: int) -> tuple[str, int]:
        """Bind a datagram socket to `host`:`port` (0: a free port) for this server, and return
        the host and port it is bound to.

        Raises [`PortBusy`][aiortu.errors.PortBusy],
        [`PortPermissionDenied`][aiortu.errors.PortPermissionDenied] or
        [`PortNotFound`][aiortu.errors.PortNotFound], as
        [`listen_udp`][aiortu.transport.listen_udp] does.
        """
        loop = asyncio.get_running_loop()
        try:
            transport, _ = await loop.create_datagram_endpoint(
                lambda: self, local_addr=(host, port)
            )
        except socket.gaierror as exc:
            raise PortNotFound(self.url, f"unknown host {host!r} ({exc.strerror})") from exc
        except OSError as exc:
            raise listen_error(self.url, exc) from exc
        local = transport.get_extra_info("sockname")
        return str(local[0]), int(local[1])

    # -- the protocol: the event loop's callbacks ----------------------------------------

    def connection_made(self, transport: asyncio.BaseTransport) -> None:
        self.transport = cast(asyncio.DatagramTransport, transport)
        self._lost = asyncio.get_running_loop().create_future()

    def datagram_received(self, data: bytes, addr: DatagramSource) -> None:
        self.counters.received += 1
        try:
            adu = check_datagram(data)
        except FrameError as error:
            self._refuse(addr, str(error))
            return
        at_once = self._at_once
        if at_once is not None and at_once(adu, addr):
            return
        pending = self.pending
        if len(pending) >= self.backlog:
            self._refuse(addr, "the requests waiting to be answered fill the backlog")
            return
        pending.append((adu, addr))
        waiter = self._waiter
        if waiter is not None and not waiter.done():
            waiter.set_result(None)

    def error_received(self, exc: Exception) -> None:
        # An ICMP error (a client's port gone): its reply is lost, as a datagram may be.
        _log.debug("%s: %s", self.url, exc)

    def connection_lost(self, exc: Exception | None) -> None:
        lost = self._lost
        if lost is not None and not lost.done():
            if exc is None:
                lost.set_result(None)
            else:
                lost.set_exception(exc)
        waiter = self._waiter
        if waiter is not None and not waiter.done():
            waiter.set_result(None)

    def _refuse(self, source: DatagramSource, why: str) -> None:
        self.counters.refused += 1
        _log.log(
            log_level(self.counters.refused),
            "Modbus UDP: refused a datagram from %s: %s",  # as serve_datagrams says it
            format_tcp_url(source[0], source[1], MODBUS_UDP_SCHEME),
            why,
        )

    # -- replies and the task ------------------------------------------------------------

    def reply(self, adu: bytes, destination: DatagramSource) -> None:
        """Send the reply ADU `adu` to `destination` now, and count it."""
        transport = self.transport
        if transport is None or transport.is_closing():
            return  # closed: the reply is lost, as a datagram may be
        self.counters.replies += 1
        transport.sendto(adu, destination)

    async def serve(self) -> None:
        """Answer the waiting requests, one at a time and in order, until cancelled (the socket
        is closed then) or the socket fails (raised here)."""
        lost = self._lost
        assert lost is not None, "bind first"
        loop = asyncio.get_running_loop()
        pending = self.pending
        try:
            while True:
                if lost.done():
                    lost.result()  # the socket's failure, if any
                    return
                if not pending:
                    self._waiter = loop.create_future()
                    await self._waiter
                    self._waiter = None
                    continue
                adu, source = pending[0]
                try:
                    reply = await self._answer(adu)
                finally:
                    pending.popleft()
                if reply is not None:
                    self.reply(reply, source)
        finally:
            self._waiter = None
            if self.transport is not None:
                self.transport.close()

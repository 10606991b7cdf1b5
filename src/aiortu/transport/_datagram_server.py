"""Modbus UDP for a server, pushed: each request answered in the event loop's callback where it
can be, the rest queued, within a bound, for one task.

Where the event loop is asyncio ([`push_datagrams`][aiortu.transport.push_datagrams]), a server
serves Modbus UDP through [`DatagramServer`][aiortu.transport.DatagramServer], whose socket the
loop's reader callback reads (`DatagramSocket`), rather than through
[`serve_datagrams`][aiortu.transport.serve_datagrams] on a socket read by a task. Each datagram
is checked in the loop's reader callback as `serve_datagrams` checks it, with the same function
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
from typing import Any, Final

import anyio

from aiortu._log import get_logger
from aiortu.core.mbap import Adu
from aiortu.errors import FrameError, PortNotFound
from aiortu.transport._datagram_socket import DatagramSocket
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


class DatagramServer:
    """Modbus UDP for a server on asyncio (see the module docstring).

    `answer` gives the reply ADU to a request ADU (None: no reply), in the server's task;
    `at_once(adu, source)` answers a request in the reader callback if it can (True) with
    [`reply`][aiortu.transport.DatagramServer.reply], or leaves it (False); `counters` counts
    what was received, refused and answered; `url` names the server in errors; `pending` is the
    deque that holds the requests waiting (one that `at_once` sees, say; a new one by
    default). Bind it with [`bind`][aiortu.transport.DatagramServer.bind], then run
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
        self.socket: DatagramSocket | None = None
        """The socket, once bound."""
        self._waiter: asyncio.Future[None] | None = None

    async def bind(self, host: str, port: int) -> tuple[str, int]:
        """Bind a datagram socket to `host`:`port` (0: a free port) for this server, and return
        the host and port it is bound to.

        Raises [`PortBusy`][aiortu.errors.PortBusy],
        [`PortPermissionDenied`][aiortu.errors.PortPermissionDenied] or
        [`PortNotFound`][aiortu.errors.PortNotFound], as
        [`listen_udp`][aiortu.transport.listen_udp] does.
        """
        try:
            found = await anyio.getaddrinfo(host, port, type=socket.SOCK_DGRAM)
        except socket.gaierror as exc:
            raise PortNotFound(self.url, f"unknown host {host!r} ({exc.strerror})") from exc
        family, _, _, _, address = found[0]
        sock = socket.socket(family, socket.SOCK_DGRAM)
        try:
            sock.bind(address)
        except OSError as exc:
            sock.close()
            raise listen_error(self.url, exc) from exc
        self.socket = DatagramSocket(sock, self.datagram_received, self._wake, self.url)
        return self.socket.local_address

    # -- the reader callback -------------------------------------------------------------

    def datagram_received(self, data: bytes, source: DatagramSource) -> None:
        """Check, count and answer (or queue) the datagram `data` from `source`."""
        self.counters.received += 1
        try:
            adu = check_datagram(data)
        except FrameError as error:
            self._refuse(source, str(error))
            return
        at_once = self._at_once
        if at_once is not None and at_once(adu, source):
            return
        pending = self.pending
        if len(pending) >= self.backlog:
            self._refuse(source, "the requests waiting to be answered fill the backlog")
            return
        pending.append((adu, source))
        self._wake()

    def _wake(self) -> None:
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
        """Send the reply ADU `adu` to `destination` now, and count it; one the socket cannot
        take now (its send buffer full, or closed) is lost, as a datagram may be, and counted
        in `unsent`."""
        sock = self.socket
        if sock is not None and sock.sendto(adu, destination):
            self.counters.replies += 1
            return
        self.counters.unsent += 1
        _log.log(
            log_level(self.counters.unsent),
            "Modbus UDP: a reply to %s was lost: the socket could not take it (counted in "
            "unsent; logged at debug level after the first)",
            format_tcp_url(destination[0], destination[1], MODBUS_UDP_SCHEME),
        )

    async def serve(self) -> None:
        """Answer the waiting requests, one at a time and in order, until cancelled or the
        socket is closed; the socket is closed on the way out."""
        sock = self.socket
        assert sock is not None, "bind first"
        loop = asyncio.get_running_loop()
        pending = self.pending
        try:
            while not sock.closed:
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
            sock.close()

"""Modbus UDP for the slave: the Modbus TCP server's answers, one datagram at a time.

[`ModbusUdpServer`][aiortu.slave.ModbusUdpServer] is a
[`ModbusTcpServer`][aiortu.slave.ModbusTcpServer] fed by datagrams instead of connections: the
same stores, handlers, hooks, unit aliases and exception codes, each reply sent to the address
the request came from. A datagram that is not exactly one well-formed ADU is refused and counted
(see [`aiortu.transport.serve_datagrams`][aiortu.transport.serve_datagrams]); the connection
limits of the TCP server (`max_connections`, `idle_timeout`) mean nothing here.
`aiortu.serve("udp://0.0.0.0:1502", {17: store})` runs one.

On asyncio the socket is a [`DatagramServer`][aiortu.transport.DatagramServer]: a request the
slave's answer-at-once allows (`AnswerAtOnce.may_answer`: a register or bit read or write to a
`MemoryStore` while nothing else is under way, no hooks, no trace) is answered from the event
loop's datagram callback, and the rest wait, within
[`DATAGRAM_BACKLOG`][aiortu.transport.DATAGRAM_BACKLOG], for the server's task, which answers
them in order by the general route. Elsewhere (trio) a task reads the socket and answers every
request by the general route.
"""

from __future__ import annotations

from collections import deque
from collections.abc import AsyncIterator, Awaitable, Callable, Sized
from contextlib import asynccontextmanager
from typing import Any

import anyio
import anyio.abc

from aiortu._log import get_logger
from aiortu.core.mbap import Adu, encode_adu
from aiortu.slave._tcp_server import ModbusTcpServer
from aiortu.transport import (
    DatagramCounters,
    DatagramServer,
    DatagramSource,
    ListenAddress,
    listen_udp,
    push_datagrams,
    serve_datagrams,
)

__all__ = ("ModbusUdpServer",)

_log = get_logger(__name__)


class ModbusUdpServer(ModbusTcpServer):
    """A Modbus UDP server for `units` (see the module docstring); it takes
    [`ModbusTcpServer`][aiortu.slave.ModbusTcpServer]'s arguments."""

    def __init__(self, units: Any, **options: Any) -> None:
        super().__init__(units, **options)
        self.datagrams = DatagramCounters()
        """Datagrams received, refused and answered."""
        self._endpoint: DatagramServer | None = None

    def _pending_requests(self) -> Sized:
        """The datagrams waiting for the server's task (made here, as the base class makes its
        answer-at-once)."""
        self._waiting: deque[tuple[Adu, DatagramSource]] = deque()
        return self._waiting

    @asynccontextmanager
    async def running(self, address: ListenAddress, url: str) -> AsyncIterator[None]:
        """Bind to `address` and serve for the duration of the `async with`; `url` names it in
        errors ([`PortError`][aiortu.errors.PortError] when the port cannot be bound)."""
        serve: Callable[..., Awaitable[None]]
        bound: DatagramServer | anyio.abc.UDPSocket
        if push_datagrams():
            endpoint = DatagramServer(
                self._answer_datagram,
                self.datagrams,
                at_once=self._answer_now,
                url=url,
                pending=self._waiting,
            )
            self.local_address = await endpoint.bind(address.host, address.port)
            serve, bound = self._serve_endpoint, endpoint
        else:
            serve, bound = self._serve_socket, await listen_udp(address.host, address.port, url=url)
        group = anyio.create_task_group()
        await group.__aenter__()
        try:
            await group.start(serve, bound)
            yield
        finally:
            group.cancel_scope.cancel()
            # The body's own exception propagates as it is, not wrapped in an ExceptionGroup.
            await group.__aexit__(None, None, None)

    async def _serve_endpoint(
        self,
        endpoint: DatagramServer,
        *,
        task_status: anyio.abc.TaskStatus[None] = anyio.TASK_STATUS_IGNORED,
    ) -> None:
        self._endpoint = endpoint
        try:
            task_status.started()
            await endpoint.serve()
        except Exception as error:
            self.connection_error = error
            _log.error("Modbus UDP: the socket failed: %s", error)
        finally:
            self._endpoint = None
            self._stopped.set()

    async def _serve_socket(
        self,
        sock: anyio.abc.UDPSocket,
        *,
        task_status: anyio.abc.TaskStatus[None] = anyio.TASK_STATUS_IGNORED,
    ) -> None:
        try:
            local = sock.extra(anyio.abc.SocketAttribute.local_address)
            self.local_address = (str(local[0]), int(local[1]))
            task_status.started()
            async with sock:
                await serve_datagrams(sock, self._answer_datagram, self.datagrams)
        except Exception as error:
            self.connection_error = error
            _log.error("Modbus UDP: the socket failed: %s", error)
        finally:
            self._stopped.set()

    def _answer_now(self, adu: Adu, source: DatagramSource) -> bool:
        """The datagram callback's try: answer `adu` at once where the shortcut allows it."""
        endpoint = self._endpoint
        if endpoint is None:
            return False

        def send(unit: int, reply: bytes) -> bool:
            endpoint.reply(encode_adu(adu.transaction_id, adu.unit, reply), source)
            return True

        if self._at_once.answer(self.unit_aliases.get(adu.unit, adu.unit), adu.pdu, send):
            self.counters.requests += 1
            return True
        return False

    async def _answer_datagram(self, adu: Adu) -> bytes | None:
        outgoing = await self._respond(adu)
        if outgoing is None:
            return None
        if outgoing.delay > 0:
            await anyio.sleep(outgoing.delay)
        return outgoing.adu

"""The line server: network clients share one serial line through its master's engine.

[`Gateway`][aiortu.gateway.Gateway] reads requests from any number of connections and hands
them to the line one at a time, fairly. What it decides:

- **Forwarding.** Every request goes out at frame level, whatever its function code (see
  [`aiortu.gateway`][aiortu.gateway]); the reply carries the client's transaction id and unit id.
- **Fairness.** Connections are served in turn (round-robin), those of a listener with a lower
  `priority` value first; the gateway hands the engine at most two requests at a time, so a
  quiet client's request waits for one request of each busy client, not for their queues.
- **Pipelining.** A connection may have `max_in_flight` requests waiting for their replies;
  the gateway reads nothing more from it until one is answered (TCP then holds the client back).
- **Lines.** Each line has its own master, queue and window; a request goes to the line whose
  unit range holds its unit id, and a unit no line serves gets exception 0A at once.
- **Unit ids.** Unit 0 is a broadcast: executed on every line, followed by the master's
  turnaround delay, never answered. Unit 255 is `default_unit` (exception 0B when None).
  Units 248..254 get exception 0B at once.
- **Failures.** Exception 0B when the unit does not answer after the master's timeout and
  retries, and at once while it is offline (with the master's `fail_fast_offline`, which
  [`gateway`][aiortu.gateway.gateway] turns on); 0A while the port is gone.
- **Coalescing.** Identical reads (01..04, same unit and PDU) in flight at the same moment are
  one transaction on the line; every client gets the reply with its own ids. A write, or any
  request that is not such a read, ends the sharing for its unit, so a read sent after a write
  never gets a reply read before it.
- **Cache.** With `cache_ms`, a read of a block answered at most that long ago is answered
  again without the line; a write drops the blocks it touches.
- **Statistics.** Per line, unit and client host, in `statistics`.
- **Framing.** A connection speaks Modbus TCP, or RTU frames over TCP (see
  [`serve_connection`][aiortu.gateway.Gateway.serve_connection]).
- **Limits.** At most `max_connections` at once (more are closed at once); a connection with
  nothing waiting that sends nothing for `idle_timeout` seconds is closed; a malformed MBAP
  header closes that connection only, logged once.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Final

import anyio
import anyio.abc

from aiortu._log import get_logger
from aiortu.core.codes import BROADCAST_UNIT, ExceptionCode
from aiortu.core.mbap import Adu, MalformedHeader
from aiortu.errors import InvalidValue
from aiortu.gateway._cache import ReadCache
from aiortu.gateway._fair_queue import FairQueue, Lane
from aiortu.gateway._forward import COALESCED_CODES, exception_reply, forward, forward_broadcast
from aiortu.gateway._lines import GatewayLine, check_lines, line_names
from aiortu.gateway._stats import GatewayStatistics, LineStatistics
from aiortu.master import Master
from aiortu.transport import (
    RTU_SILENCE,
    ConnectionLimit,
    Framing,
    MbapFraming,
    RtuFraming,
    peer_address,
    serve_listener,
)

__all__ = (
    "DEFAULT_IDLE_TIMEOUT",
    "DEFAULT_MAX_CONNECTIONS",
    "DEFAULT_MAX_IN_FLIGHT",
    "Gateway",
    "GatewayCounters",
)

_log = get_logger(__name__)

DEFAULT_MAX_IN_FLIGHT: Final = 4
"""Requests a connection may have waiting for their replies, unless told otherwise."""

DEFAULT_MAX_CONNECTIONS: Final = 32
"""Connections served at once, unless told otherwise."""

DEFAULT_IDLE_TIMEOUT: Final = 120.0
"""Seconds a connection with nothing waiting may stay silent, unless told otherwise."""

_ENGINE_WINDOW = 2
"""Requests handed to the engine at once: one on the line, one ready to follow it."""

_READ_SIZE = 4096
_UNIT_RANGE = range(1, 248)
_ALL_UNITS = 0xFF
_NO_RESPONSE = ExceptionCode.GATEWAY_TARGET_DEVICE_FAILED_TO_RESPOND
_NO_PATH = ExceptionCode.GATEWAY_PATH_UNAVAILABLE
_GONE = (anyio.EndOfStream, anyio.BrokenResourceError, anyio.ClosedResourceError)


@dataclass(slots=True)
class GatewayCounters:
    """What happened to the connections and requests of a [`Gateway`][aiortu.gateway.Gateway]."""

    connections_accepted: int = 0
    """Connections served."""
    connections_refused: int = 0
    """Connections closed at once because *max_connections* were open."""
    connections_idle: int = 0
    """Connections closed after *idle_timeout* of silence."""
    connections_malformed: int = 0
    """Connections closed for a malformed MBAP header."""
    requests: int = 0
    """Requests received (ADUs with a valid header)."""
    transactions: int = 0
    """Requests handed to the master (broadcasts included); the master refuses those to an
    offline unit without sending them."""
    coalesced: int = 0
    """Reads answered by an identical read in flight: no transaction of their own."""
    broadcasts: int = 0
    """Requests to unit 0 sent on the line."""
    refused_units: int = 0
    """Requests answered with exception 0B at once for their unit id (248..254, or 255 with no
    default unit), or 0A for a unit no line serves."""
    cache_hits: int = 0
    """Reads answered from the read cache: no transaction of their own."""


class _Line:
    """One line: its master, the units routed to it, its queue, window, shared reads, cache."""

    def __init__(
        self, line: GatewayLine, name: str, cache: ReadCache | None, stats: LineStatistics
    ) -> None:
        if not isinstance(line.port, Master):
            raise InvalidValue("port", line.port, "a running Master (gateway() opens ports)")
        self.name = name
        self.master = line.port
        self.units = line.units
        self.queue: FairQueue[_Job] = FairQueue()
        self.window = anyio.Semaphore(_ENGINE_WINDOW)
        self.shared: dict[tuple[int, bytes], _Shared] = {}
        self.cache = cache
        self.stats = stats


class _Connection:
    """One client: its lane in the fair queue, its in-flight slots, its writer."""

    def __init__(
        self, stream: anyio.abc.ByteStream, priority: int, max_in_flight: int, framing: Framing
    ) -> None:
        self.stream = stream
        self.priority = priority
        self.framing = framing
        self.lanes: dict[_Line, Lane[_Job]] = {}
        self.client = _host(stream) or "local"
        # Without transaction ids, one request at a time keeps the replies in order.
        self.slots = anyio.Semaphore(1 if framing.in_order else max_in_flight)
        self.in_flight = 0
        self.open = True
        self._send_lock = anyio.Lock()

    def lane(self, line: _Line) -> Lane[_Job]:
        """The connection's lane in the queue of `line`."""
        lane = self.lanes.get(line)
        if lane is None:
            lane = self.lanes[line] = Lane(self.priority)
        return lane

    async def answer(self, adu: Adu, reply: bytes | None) -> None:
        """Send `reply` with the request's ids (None: nothing to send), and free the slot."""
        try:
            if reply is not None and self.open:
                async with self._send_lock:
                    await self.stream.send(self.framing.encode(adu, reply))
        except _GONE:
            self.open = False
        finally:
            self.in_flight -= 1
            self.slots.release()


@dataclass(slots=True)
class _Job:
    connection: _Connection
    adu: Adu
    unit: int
    line: _Line
    """The unit on the line (unit 255 mapped)."""


@dataclass(slots=True)
class _Shared:
    """A read on the line that identical reads wait for."""

    reply: bytes
    done: anyio.Event = field(default_factory=anyio.Event)


class Gateway:
    """A line server in front of `master` (see the module docstring for what it decides).

    Run it with [`run`][aiortu.gateway.Gateway.run] (the dispatcher) and serve connections with
    [`serve`][aiortu.gateway.Gateway.serve] (a listener) or
    [`serve_connection`][aiortu.gateway.Gateway.serve_connection];
    [`gateway`][aiortu.gateway.gateway] does it all for listen URLs.

    `master` is the line's master, or several [`GatewayLine`][aiortu.gateway.GatewayLine]s
    whose `port` is a running master: a request goes to the line whose `units` hold its unit
    id, and a unit no line serves gets exception 0A (gateway path unavailable: the spec's code
    for a gateway with no path to the target, as a misconfiguration). With `cache_ms`, a read
    (01 to 04) of the same unit and block as one answered at most that many milliseconds ago is
    answered again without the line; `clock` gives the cache's time in seconds.

    Raises [`InvalidValue`][aiortu.errors.InvalidValue] for a `max_in_flight` or
    `max_connections` below 1, an `idle_timeout` that is not positive, a `default_unit`
    outside 1..247, a negative `cache_ms`, or lines whose unit ranges overlap.
    """

    def __init__(
        self,
        master: Master | Sequence[GatewayLine],
        *,
        max_in_flight: int = DEFAULT_MAX_IN_FLIGHT,
        max_connections: int = DEFAULT_MAX_CONNECTIONS,
        idle_timeout: float = DEFAULT_IDLE_TIMEOUT,
        default_unit: int | None = None,
        coalesce: bool = True,
        cache_ms: float = 0,
        clock: Callable[[], float] = time.monotonic,
    ) -> None:
        lines = [GatewayLine(master)] if isinstance(master, Master) else list(master)
        check_lines(lines)
        if not (isinstance(cache_ms, (int, float)) and cache_ms >= 0):
            raise InvalidValue("cache_ms", cache_ms, "a number of milliseconds, 0 or more")
        for name, value in (("max_in_flight", max_in_flight), ("max_connections", max_connections)):
            if type(value) is not int or value < 1:
                raise InvalidValue(name, value, "an int of at least 1")
        if not (isinstance(idle_timeout, (int, float)) and idle_timeout > 0):
            raise InvalidValue("idle_timeout", idle_timeout, "a positive number of seconds")
        if default_unit is not None and default_unit not in _UNIT_RANGE:
            raise InvalidValue("default_unit", default_unit, _UNIT_RANGE)
        self.statistics = GatewayStatistics()
        """Counters per line, unit and client."""
        self._lines = [
            _Line(
                line,
                name,
                ReadCache(cache_ms / 1000, clock) if cache_ms else None,
                self.statistics.line(name),
            )
            for line, name in zip(lines, line_names(lines), strict=True)
        ]
        self.master = self._lines[0].master
        """The master whose engine serves the (first) line."""
        self.max_in_flight = max_in_flight
        """Requests a connection may have waiting for their replies."""
        self.idle_timeout = float(idle_timeout)
        """Seconds of silence, with no request waiting, after which a connection is closed."""
        self.default_unit = default_unit
        """The unit a request to unit id 255 goes to (None: exception 0B)."""
        self.coalesce = coalesce
        """Whether identical reads in flight at once share one transaction."""
        self.counters = GatewayCounters()
        """What happened to the connections and requests."""
        self.local_addresses: list[tuple[str, int]] = []
        """The host and port of each TCP listener [`serve`][aiortu.gateway.Gateway.serve]
        serves."""
        self.metrics_address: tuple[str, int] | None = None
        """The host and port the statistics are served on as Prometheus text (None: not)."""
        self.unix_paths: list[str] = []
        """The path of each Unix socket listener [`serve`][aiortu.gateway.Gateway.serve]
        serves."""
        self._limit = ConnectionLimit("gateway", max_connections, self.counters)
        self._tasks: anyio.abc.TaskGroup | None = None

    @property
    def connections(self) -> int:
        """The connections open now."""
        return self._limit.open

    @property
    def max_connections(self) -> int:
        """Connections served at once, over every listener; more are closed at once."""
        return self._limit.max_connections

    @max_connections.setter
    def max_connections(self, value: int) -> None:
        self._limit.max_connections = value

    @property
    def port(self) -> int:
        """The port of the first listener (useful after asking for port 0)."""
        if not self.local_addresses:
            raise RuntimeError("the gateway is not listening yet")
        return self.local_addresses[0][1]

    # -- the dispatcher ----------------------------------------------------------------

    async def run(
        self, *, task_status: anyio.abc.TaskStatus[None] = anyio.TASK_STATUS_IGNORED
    ) -> None:
        """Hand queued requests to each line in turn, until cancelled."""
        async with anyio.create_task_group() as tasks:
            self._tasks = tasks
            for line in self._lines:
                tasks.start_soon(self._dispatch, line, tasks)
            task_status.started()
            try:
                await anyio.sleep_forever()
            finally:
                self._tasks = None

    async def _dispatch(self, line: _Line, tasks: anyio.abc.TaskGroup) -> None:
        while True:
            await line.window.acquire()
            job = await line.queue.take()
            tasks.start_soon(self._run_job, job)

    async def _run_job(self, job: _Job) -> None:
        released = False

        def release() -> None:
            nonlocal released
            if not released:
                released = True
                job.line.window.release()

        reply: bytes | None = None
        try:
            reply = await self._reply(job, release)
        except Exception:
            # A bug must cost one request, not every connection.
            _log.exception("gateway: forwarding a request failed; answered with exception 0B")
            reply = exception_reply(job.adu.pdu, _NO_RESPONSE)
        finally:
            release()
            if reply is not None:
                self.statistics.answered(job.line.name, job.unit, reply)
            await self._answer(job.connection, job.adu, reply)

    async def _answer(self, connection: _Connection, adu: Adu, reply: bytes | None) -> None:
        if reply is not None:
            self.statistics.client(connection.client).replies += 1
        await connection.answer(adu, reply)

    async def _reply(self, job: _Job, release: Callable[[], None]) -> bytes | None:
        """The reply to `job` from the line; `release` frees its place in the engine window
        early when the cache or another read's transaction answers it."""
        pdu, unit, line = job.adu.pdu, job.unit, job.line
        if unit == BROADCAST_UNIT:
            await self._broadcast(pdu, job.connection.priority)
            return None
        if pdu[0] not in COALESCED_CODES:
            for other in [k for k in line.shared if k[0] == unit]:
                del line.shared[other]  # later reads of this unit must follow the write
            if line.cache is not None:
                line.cache.invalidate(unit, pdu)
            self._count_transaction(line)
            return await forward(line.master, unit, pdu, job.connection.priority)
        cache = line.cache if line.cache is not None and line.cache.cacheable(pdu) else None
        if cache is not None and (cached := cache.get(unit, pdu)) is not None:
            release()
            self.counters.cache_hits += 1
            line.stats.cache_hits += 1
            return cached
        generation = cache.generation(unit) if cache is not None else (0, 0)
        reply = await self._shared_read(job, release)
        if cache is not None:
            cache.put(unit, pdu, reply, generation)
        return reply

    async def _broadcast(self, pdu: bytes, priority: int) -> None:
        """Send `pdu` to every unit of every line: a broadcast may write anything."""
        for line in self._lines:
            line.shared.clear()
            if line.cache is not None:
                line.cache.clear()
            if await forward_broadcast(line.master, pdu, priority):
                self._count_transaction(line)
                self.counters.broadcasts += 1
                line.stats.broadcasts += 1

    def _count_transaction(self, line: _Line) -> None:
        self.counters.transactions += 1
        line.stats.transactions += 1

    async def _shared_read(self, job: _Job, release: Callable[[], None]) -> bytes:
        """The reply to read `job`, shared with identical reads in flight at the same moment."""
        pdu, unit, line = job.adu.pdu, job.unit, job.line
        if not self.coalesce:
            self._count_transaction(line)
            return await forward(line.master, unit, pdu, job.connection.priority)
        key = (unit, pdu)
        shared = line.shared.get(key)
        if shared is not None:
            release()
            self.counters.coalesced += 1
            line.stats.coalesced += 1
            await shared.done.wait()
            return shared.reply
        shared = line.shared[key] = _Shared(exception_reply(pdu, _NO_RESPONSE))
        self._count_transaction(line)
        try:
            shared.reply = await forward(line.master, unit, pdu, job.connection.priority)
        finally:
            if line.shared.get(key) is shared:
                del line.shared[key]
            shared.done.set()
        return shared.reply

    # -- connections -------------------------------------------------------------------

    async def serve(
        self,
        listener: anyio.abc.Listener[anyio.abc.ByteStream],
        *,
        priority: int = 0,
        rtu_framing: bool = False,
        task_status: anyio.abc.TaskStatus[None] = anyio.TASK_STATUS_IGNORED,
    ) -> None:
        """Accept connections from `listener` and serve each with `priority` (lower values go
        first), until cancelled: Modbus TCP, or RTU frames with `rtu_framing` (see
        [`serve_connection`][aiortu.gateway.Gateway.serve_connection]). Reports started once its
        address is in [`local_addresses`][aiortu.gateway.Gateway.local_addresses]."""
        address = listener.extra(anyio.abc.SocketAttribute.local_address, None)
        if isinstance(address, tuple):
            self.local_addresses.append((str(address[0]), int(address[1])))
        elif isinstance(address, str):
            self.unix_paths.append(address)
        task_status.started()

        async def accepted(stream: anyio.abc.ByteStream) -> None:
            client = _host(stream)
            if client is not None:
                self.statistics.client(client).connections += 1
            await self.serve_connection(stream, priority, rtu_framing=rtu_framing)

        await serve_listener(listener, accepted, self._limit)

    async def serve_connection(
        self, stream: anyio.abc.ByteStream, priority: int = 0, *, rtu_framing: bool = False
    ) -> None:
        """Serve one connection until the client closes it, it stays idle for
        [`idle_timeout`][aiortu.gateway.Gateway.idle_timeout], or it sends a malformed header;
        then close it. Needs [`run`][aiortu.gateway.Gateway.run] running.

        The connection speaks Modbus TCP, or with `rtu_framing` RTU frames (unit, PDU, CRC) as
        a serial device server does: a frame whose length its function code does not tell ends
        after 20 ms of silence, a frame with a bad CRC is dropped, and as RTU frames carry no
        transaction id the connection has one request on the line at a time.
        """
        framing: Framing = RtuFraming() if rtu_framing else MbapFraming()
        connection = _Connection(stream, priority, self.max_in_flight, framing)
        try:
            while (adus := await self._next_requests(connection)) is not None:
                for adu in adus:
                    await connection.slots.acquire()
                    connection.in_flight += 1
                    self._accept(connection, adu)
        except _GONE:
            return
        finally:
            connection.open = False
            for line, lane in connection.lanes.items():
                line.queue.drop(lane)
            await stream.aclose()

    async def _next_requests(self, connection: _Connection) -> list[Adu] | None:
        """The requests the connection's next bytes (or silence) complete; None to close it."""
        stream, framing = connection.stream, connection.framing
        while True:
            silence = framing.waiting_for_silence()
            with anyio.move_on_after(RTU_SILENCE if silence else self.idle_timeout) as timer:
                data = await stream.receive(_READ_SIZE)
            if not timer.cancelled_caught:
                break
            if silence:
                return framing.silence()
            if not connection.in_flight:
                self.counters.connections_idle += 1
                _log.info(
                    "gateway: %s idle for %g s, closed", peer_address(stream), self.idle_timeout
                )
                return None
            # Not idle: the client waits for the line.
        try:
            return framing.feed(data)
        except MalformedHeader as error:
            self.counters.connections_malformed += 1
            _log.warning("gateway: %s sent %s; connection closed", peer_address(stream), error)
            return None

    def _accept(self, connection: _Connection, adu: Adu) -> None:
        """Queue `adu` for its line, or answer it at once when its unit id names no unit (0B)
        or a unit no line serves (0A)."""
        self.counters.requests += 1
        self.statistics.client(connection.client).requests += 1
        unit = adu.unit
        if unit == _ALL_UNITS and self.default_unit is not None:
            unit = self.default_unit
        line = self._route(unit)
        if line is None:
            self.counters.refused_units += 1
            assert self._tasks is not None, "Gateway.run is not running"
            code = _NO_PATH if unit in _UNIT_RANGE else _NO_RESPONSE
            refusal = exception_reply(adu.pdu, code)
            self._tasks.start_soon(self._answer, connection, adu, refusal)
            return
        self.statistics.unit(line.name, unit).requests += 1
        line.queue.put(connection.lane(line), _Job(connection, adu, unit, line))

    def _route(self, unit: int) -> _Line | None:
        """The line of `unit` (the first line for a broadcast, which goes on every line)."""
        if unit == BROADCAST_UNIT:
            return self._lines[0]
        for line in self._lines:
            if unit in line.units:
                return line
        return None


def _host(stream: anyio.abc.ByteStream) -> str | None:
    """The client's host, for statistics (its port changes with every connection); None for a
    client already gone."""
    try:
        address = stream.extra(anyio.abc.SocketAttribute.remote_address, None)
    except OSError:
        return None
    if isinstance(address, tuple):
        return str(address[0])
    return "unix" if isinstance(address, str) else "local"

"""The line server: network clients share one serial line through its master's engine.

[`Gateway`][aiortu.gateway.Gateway] reads requests from any number of connections and hands
each to the engine of its line at once, with a key that keeps the line fair. What it decides:

- **Forwarding.** Every request goes out at frame level, whatever its function code (see
  [`aiortu.gateway`][aiortu.gateway]); the reply carries the client's transaction id and unit id.
- **Fairness.** Connections are served in turn (round-robin), those of a listener with a lower
  `priority` value first: each request takes its connection's next turn on the line, never
  earlier than the line's current turn, and the engine's queue goes by (priority, turn), so a
  quiet client's request waits for one request of each busy client, not for their queues.
- **Pipelining.** A connection may have `max_in_flight` requests waiting for their replies;
  the gateway reads nothing more from it until one is answered (TCP then holds the client back,
  from its first byte: see [`serve_listener`][aiortu.transport.serve_listener]).
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
- **Access rules.** A listener may have [`RoleRules`][aiortu.transport.RoleRules]: a request
  they refuse (a write on a read-only listener, a function code or unit not allowed, a
  broadcast) is answered with exception 01 at once, never sent, and counted
  (`refused_by_rules`, and per client host); the first refusal of a connection is logged as a
  warning. A `tcp://`, `rtu+tcp://` or `unix:` client gets the default role's rule; a `tls://`
  client the rule of its certificate's role.
- **Statistics.** Per line, unit and client host, in `statistics`.
- **Framing.** A connection speaks Modbus TCP, or RTU frames over TCP (see
  [`serve_connection`][aiortu.gateway.Gateway.serve_connection]).
- **Limits.** At most `max_connections` at once (more are closed at once); a connection with
  nothing waiting that sends nothing for `idle_timeout` seconds is closed, and so is one whose
  reply could not be written for `idle_timeout` (it reads nothing), while one whose request
  waits for a slow line is not idle; a malformed MBAP header closes that connection only,
  the first logged as a warning and the rest at debug level (all counted).
- **Clients that leave.** A client that resets its connection, or to which a reply cannot be
  written, has its queued requests dropped before they reach the line; one on the wire
  completes there. A client that half-closes (a request, then end of stream) gets the replies
  to the requests already read, then the connection closes.
"""

from __future__ import annotations

import asyncio
import functools
import inspect
import logging
import time
from collections.abc import Awaitable, Callable, Sequence
from dataclasses import dataclass, field
from typing import Any, Final, TypeGuard

import anyio
import anyio.abc
from anyio.streams.tls import TLSAttribute

from aiortu._log import get_logger
from aiortu.core.codes import BROADCAST_UNIT, UNIT_ADDRESSES, ExceptionCode
from aiortu.core.mbap import Adu, MalformedHeader, decode_adu
from aiortu.errors import FrameError, InvalidValue
from aiortu.gateway._as_bytes import ReadsAsBytes
from aiortu.gateway._cache import ReadCache
from aiortu.gateway._connection import GONE, Connection, Turns
from aiortu.gateway._forward import (
    COALESCED_CODES,
    FORCE_LISTEN_ONLY,
    RESTART,
    exception_reply,
    forward,
    forward_broadcast,
    forward_unanswered,
    reply_from,
    reply_pdu,
    request_of,
    start_forward,
)
from aiortu.gateway._lines import GatewayLine, check_lines, line_names
from aiortu.gateway._stats import DEFAULT_CLIENT_STATISTICS, GatewayStatistics, LineStatistics
from aiortu.line import loop_clock
from aiortu.master import Master
from aiortu.transport import (
    RTU_SILENCE,
    CertificateError,
    ConnectionLimit,
    Framing,
    MbapFraming,
    PushServerStream,
    RoleRules,
    RtuFraming,
    certificate_role,
    log_level,
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

_READ_SIZE = 4096
_WORKER_TASK = "gateway requests"  # named here: anyio would work a name out per task
_ALL_UNITS = 0xFF
_NO_RESPONSE = ExceptionCode.GATEWAY_TARGET_DEVICE_FAILED_TO_RESPOND
_NO_PATH = ExceptionCode.GATEWAY_PATH_UNAVAILABLE
_REFUSED = ExceptionCode.ILLEGAL_FUNCTION


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
    """Requests answered with an exception at once for their unit id: 0B for 248..254, 255
    with no default unit, or a unit in listen-only mode; 0A for a unit no line serves; 01 for a
    read (any request that may not be broadcast) to unit 0."""
    cache_hits: int = 0
    """Reads answered from the read cache: no transaction of their own."""
    refused_by_rules: int = 0
    """Requests the listener's access rules refused (answered with exception 01)."""


class _Line(Turns):
    """One line: its master, the units routed to it, its current turn, shared reads, cache."""

    def __init__(
        self, line: GatewayLine, name: str, cache: ReadCache | None, stats: LineStatistics
    ) -> None:
        super().__init__()
        if not isinstance(line.port, Master):
            raise InvalidValue("port", line.port, "a running Master (gateway() opens ports)")
        self.name = name
        self.master = line.port
        self.units = line.units
        self.shared: dict[tuple[int, bytes], _Shared] = {}
        self.cache = cache
        self.stats = stats
        self.as_bytes = ReadsAsBytes(self.master)
        """The line's byte shortcut for reads."""
        self.listen_only: set[int] = set()
        """Units the gateway put in listen-only mode (08/04), until an 08/01 to them."""


@dataclass(slots=True)
class _Request:
    connection: _Client
    adu: Adu
    unit: int
    """The unit on the line (unit 255 mapped)."""
    line: _Line
    turn: int
    """Its connection's turn on the line, taken as it came."""
    work: Callable[[], Awaitable[bytes | None]] | None = None
    """What the worker that takes it calls, and awaits, for its reply (None: it is answered
    from a callback). A coroutine is made only by the worker that will await it."""
    submitted: Awaitable[Any] | None = None
    """The line's awaitable of a read handed to the line before a worker took it: closed
    when none ever does (see `_drop_unstarted`)."""
    shared: _Shared | None = None
    """The shared read it leads (see `Gateway._start_read`)."""
    generation: tuple[int, int] | None = None
    """The cache's generation of its unit when a cacheable read began."""


_Client = Connection[_Request]


@dataclass(slots=True)
class _Shared:
    """A read on the line that identical reads wait for: they get its reply, or ask again
    when its own client left before its reply came."""

    followers: list[_Request] = field(default_factory=list)


class Gateway:
    """A line server in front of `master` (see the module docstring for what it decides).

    Serve connections with [`serve`][aiortu.gateway.Gateway.serve] (a listener) or
    [`serve_connection`][aiortu.gateway.Gateway.serve_connection];
    [`gateway`][aiortu.gateway.gateway] does it all for listen URLs.

    `master` is the line's master, or several [`GatewayLine`][aiortu.gateway.GatewayLine]s
    whose `port` is a running master: a request goes to the line whose `units` hold its unit
    id, and a unit no line serves gets exception 0A (gateway path unavailable: the spec's code
    for a gateway with no path to the target, as a misconfiguration). With `cache_ms`, a read
    (01 to 04) of the same unit and block as one answered at most that many milliseconds ago is
    answered again without the line; `clock` gives the cache's time in seconds (None: the event
    loop's, read where the gateway is made; `time.monotonic` if it is made outside one).

    Raises [`InvalidValue`][aiortu.errors.InvalidValue] for a `max_in_flight`,
    `max_connections` or `client_statistics` below 1, an `idle_timeout` that is not positive, a
    `default_unit` outside 1..247, a negative `cache_ms`, or lines whose unit ranges overlap.
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
        clock: Callable[[], float] | None = None,
        client_statistics: int = DEFAULT_CLIENT_STATISTICS,
    ) -> None:
        lines = [GatewayLine(master)] if isinstance(master, Master) else list(master)
        check_lines(lines)
        _check_options(
            max_in_flight=max_in_flight,
            max_connections=max_connections,
            client_statistics=client_statistics,
            idle_timeout=idle_timeout,
            default_unit=default_unit,
            cache_ms=cache_ms,
        )
        self.statistics = GatewayStatistics(max_clients=client_statistics)
        """Counters per line, unit and client (the `client_statistics` most recent hosts one
        by one, the others added up)."""
        self._lines = [
            _Line(
                line,
                name,
                ReadCache(cache_ms / 1000, _cache_clock(clock)) if cache_ms else None,
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

    # -- connections -------------------------------------------------------------------

    async def serve(
        self,
        listener: anyio.abc.Listener[anyio.abc.ByteStream],
        *,
        priority: int = 0,
        rtu_framing: bool = False,
        rules: RoleRules | None = None,
        task_status: anyio.abc.TaskStatus[None] = anyio.TASK_STATUS_IGNORED,
    ) -> None:
        """Accept connections from `listener` and serve each with `priority` (lower values go
        first) and the access `rules` (None: everything allowed), until cancelled: Modbus TCP,
        or RTU frames with `rtu_framing` (see
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
            await self.serve_connection(stream, priority, rtu_framing=rtu_framing, rules=rules)

        await serve_listener(listener, accepted, self._limit)

    async def serve_connection(
        self,
        stream: anyio.abc.ByteStream,
        priority: int = 0,
        *,
        rtu_framing: bool = False,
        rules: RoleRules | None = None,
    ) -> None:
        """Serve one connection until the client closes it (the replies to the requests it sent
        before are sent first), stays idle for
        [`idle_timeout`][aiortu.gateway.Gateway.idle_timeout], or sends a malformed header;
        then close it.

        The connection speaks Modbus TCP, or with `rtu_framing` RTU frames (unit, PDU, CRC) as
        a serial device server does: a frame whose length its function code does not tell ends
        after 20 ms of silence, a frame with a bad CRC is dropped, and as RTU frames carry no
        transaction id the connection has one request on the line at a time. With `rules`, each
        request is checked first (see the module docstring); a TLS stream's client has the role
        its certificate carries.
        """
        framing: Framing = RtuFraming() if rtu_framing else MbapFraming()
        connection: _Client = Connection(
            stream,
            framing,
            priority=priority,
            window=1 if framing.in_order else self.max_in_flight,
            idle_timeout=self.idle_timeout,
            client=_host(stream) or "local",
            rules=rules,
            role=certificate_role_of(stream) if rules is not None else None,
        )
        try:
            async with anyio.create_task_group() as tasks:
                connection.tasks = tasks
                if isinstance(stream, PushServerStream):
                    stream.tap = functools.partial(self._tap, connection)
                    tasks.start_soon(self._worker, connection, name=_WORKER_TASK)  # parks
                tasks.start_soon(self._watch_idle, connection)
                tasks.start_soon(self._writer, connection)
                await self._read(connection)
                # End of stream: the requests read go on, and their replies are sent.
                while connection.in_flight:
                    await connection.freed()
                tasks.cancel_scope.cancel()  # the watch and the writer
        finally:
            connection.leave()  # what is still on the line is dropped
            _drop_unstarted(connection)
            if isinstance(stream, PushServerStream):
                stream.tap = None
            await stream.aclose()

    async def _watch_idle(self, connection: _Client) -> None:
        """Close `connection` once it has been silent for `idle_timeout` with nothing waiting:
        one timer per connection, not a deadline per read (the reader only notes the time)."""
        while True:
            heard = connection.heard
            # Until a time, not for a time left: a remainder below the clock's resolution
            # (a virtual clock's) would never pass.
            await anyio.sleep_until(heard + self.idle_timeout)
            if connection.heard != heard:
                continue  # heard from meanwhile: silent since then
            if not connection.in_flight:
                self._idle(connection, "idle")
                return
            await anyio.sleep(self.idle_timeout)  # a request waits for the line

    async def _read(self, connection: _Client) -> None:
        """Read and start the connection's requests, each once its window has room, until the
        client ends its stream (return) or leaves (the connection's requests cancelled)."""
        while (adus := await self._next_requests(connection)) is not None:
            for adu in adus:
                await connection.room()
                await self._accept(connection, adu)

    async def _next_requests(self, connection: _Client) -> list[Adu] | None:
        """The requests the connection's next bytes (or silence) complete; None at the end of
        the client's stream. A connection to close leaves."""
        stream, framing = connection.stream, connection.framing
        try:
            if framing.waiting_for_silence():
                with anyio.move_on_after(RTU_SILENCE):
                    data = await stream.receive(_READ_SIZE)
                    connection.heard = connection.clock()
                    return framing.feed(data)
                return framing.silence()
            data = await stream.receive(_READ_SIZE)
            connection.heard = connection.clock()
        except anyio.EndOfStream:
            return None
        except GONE:
            connection.leave()
            return None
        try:
            return framing.feed(data)
        except MalformedHeader as error:
            self.counters.connections_malformed += 1
            _log.log(
                log_level(self.counters.connections_malformed),
                "gateway: %s sent %s; connection closed (logged at debug level after the first)",
                peer_address(connection.stream),
                error,
            )
            connection.leave()
            return None

    def _idle(self, connection: _Client, why: str) -> None:
        if not connection.open:
            return  # closed already
        self.counters.connections_idle += 1
        _log.info(
            "gateway: %s %s for %g s, closed",
            peer_address(connection.stream),
            why,
            self.idle_timeout,
        )
        connection.leave()

    async def _accept(self, connection: _Client, adu: Adu) -> None:
        """Start `adu` on its line, or answer it at once (see `_admit`)."""
        reply = self._admit(connection, adu)
        if reply is not None:
            await self._answer(connection, adu, reply)

    def _admit(self, connection: _Client, adu: Adu) -> bytes | None:
        """Start `adu` on its line (None), or return the reply that answers it at once: from
        the cache, or an exception when the rules refuse it (01), its unit id names no unit
        (0B) or a unit no line serves (0A)."""
        self.counters.requests += 1
        self.statistics.client(connection.client).requests += 1
        unit = adu.unit
        if unit == _ALL_UNITS and self.default_unit is not None:
            unit = self.default_unit
        if connection.rules is not None and self._refused(connection, unit, adu.pdu):
            return exception_reply(adu.pdu, _REFUSED)
        line = self._route(unit)
        code = self._refused_unit(line, unit, adu.pdu)
        if code is not None:
            self.counters.refused_units += 1
            return exception_reply(adu.pdu, code)
        assert line is not None
        self.statistics.unit(line.name, unit).requests += 1
        cached = self._cached(line, unit, adu.pdu)
        if cached is not None:
            self.statistics.answered(line.name, unit, cached)
            return cached
        self._start(_Request(connection, adu, unit, line, connection.turn(line)))
        return None

    def _tap(self, connection: _Client, chunk: bytes) -> bool:
        """The tap of a pushed connection ([`PushServerStream`][aiortu.transport.PushServerStream],
        which offers it a chunk only while the reader waits with nothing unread and the client
        reads its replies): take `chunk` in the read callback that got it, with no task wake-up,
        as the reader would (`_admit`), and return True, when `accepted_in_callback` allows it;
        else return False, nothing done: the reader takes it."""
        adu = accepted_in_callback(connection, chunk)
        if adu is None:
            return False
        connection.heard = connection.clock()
        reply = self._admit(connection, adu)
        if reply is not None:  # as `_answer`, without a task: a reply not sent holds a place
            self.statistics.client(connection.client).replies += 1
            if not connection.send_now(adu, reply):
                connection.in_flight += 1
                connection.send_later(adu, reply)  # `_writer` frees its place
        return True

    @staticmethod
    def _refused_unit(line: _Line | None, unit: int, pdu: bytes) -> ExceptionCode | None:
        """The exception that answers `pdu` to `unit` at once, or None to forward it: 0A for a
        unit no line serves, 0B for a unit id that names no unit or a unit in listen-only mode
        (it answers nothing but 08/01), 01 for a request to unit 0 that may not be broadcast
        (a read: no device answers a broadcast, and the client would wait for nothing)."""
        if line is None:
            return _NO_PATH if unit in UNIT_ADDRESSES else _NO_RESPONSE
        if unit == BROADCAST_UNIT:
            return None if request_of(pdu).broadcastable else _REFUSED
        if line.listen_only and unit in line.listen_only and not pdu.startswith(RESTART):
            return _NO_RESPONSE
        return None

    def _refused(self, connection: _Client, unit: int, pdu: bytes) -> bool:
        """Whether the connection's rules refuse `pdu` to `unit`; a refusal is counted, and
        logged as a warning the first time on each connection."""
        assert connection.rules is not None
        refusal = connection.rules.refusal(connection.role, unit, pdu)
        if refusal is None:
            return False
        self.counters.refused_by_rules += 1
        self.statistics.client(connection.client).refused += 1
        _log.log(
            logging.DEBUG if connection.warned else logging.WARNING,
            "gateway: refused a request of %s to unit %d: %s",
            peer_address(connection.stream),
            unit,
            refusal,
        )
        connection.warned = True
        return True

    async def _answer(self, connection: _Client, adu: Adu, reply: bytes) -> None:
        self.statistics.client(connection.client).replies += 1
        if not await connection.send(adu, reply):
            self._idle(connection, "read no reply")

    def _route(self, unit: int) -> _Line | None:
        """The line of `unit` (the first line for a broadcast, which goes on every line)."""
        if unit == BROADCAST_UNIT:
            return self._lines[0]
        for line in self._lines:
            if unit in line.units:
                return line
        return None

    # -- one request on the line ---------------------------------------------------------

    def _start(self, request: _Request) -> None:
        """Start `request` on its line (it takes a place in its connection's window): a read
        in `_start_read`, anything else on a worker. What a write or a broadcast changes for
        later reads (shared reads, the cache) changes here, in the order requests come."""
        request.connection.in_flight += 1
        pdu, unit, line = request.adu.pdu, request.unit, request.line
        if unit == BROADCAST_UNIT:
            for each in self._lines:  # a broadcast may write anything
                each.shared.clear()
                if each.cache is not None:
                    each.cache.clear()
        elif pdu[0] in COALESCED_CODES:
            self._start_read(request)
            return
        else:
            for other in [k for k in line.shared if k[0] == unit]:
                del line.shared[other]  # later reads of this unit must follow the write
            if line.cache is not None:
                line.cache.invalidate(unit, pdu)
            self._count_transaction(line)
        request.work = functools.partial(self._line_request, request)
        self._to_worker(request)

    def _to_worker(self, request: _Request) -> None:
        """Have a worker of the connection run `request.work` (started if none is parked)."""
        connection = request.connection
        if not connection.put(request):
            assert connection.tasks is not None
            connection.tasks.start_soon(self._worker, connection, name=_WORKER_TASK)

    async def _worker(self, connection: _Client) -> None:
        """Run the connection's requests one after the other, parked between them, until the
        connection is done: a request costs no task of its own."""
        pending = connection.pending
        while True:
            while pending:
                await self._request(pending.popleft())
            await connection.park()

    async def _request(self, request: _Request) -> None:
        """Await `request`'s reply and end it (see `_end`)."""
        assert request.work is not None
        try:
            reply = await request.work()
        except Exception:
            # A bug must cost one request, not every connection.
            _log.exception("gateway: forwarding a request failed; answered with exception 0B")
            reply = exception_reply(request.adu.pdu, _NO_RESPONSE)
        except BaseException:
            self._end(request, None)  # its client left: identical reads ask again
            raise
        self._end(request, reply)

    async def _line_request(self, request: _Request) -> bytes | None:
        """The reply to `request`, not a read, from the line (None for a broadcast)."""
        pdu, unit, line = request.adu.pdu, request.unit, request.line
        priority, turn = request.connection.priority, request.turn
        if unit == BROADCAST_UNIT:
            await self._broadcast(pdu, priority, turn)
            return None
        if pdu.startswith(FORCE_LISTEN_ONLY) or (
            unit in line.listen_only and pdu.startswith(RESTART)
        ):
            return await self._unanswered(line, unit, pdu, priority, turn)
        return await forward(line.master, unit, pdu, priority, turn)

    def _start_read(self, request: _Request) -> None:
        """Start read `request`: it joins an identical read in flight (the key holds the unit
        and the whole PDU), or goes on the line. Its reply comes from the done-callback of an
        event loop future where the engine runs it itself (a queued read, or one its fast
        path sent), else from a worker; `_end` ends it either way."""
        pdu, unit, line = request.adu.pdu, request.unit, request.line
        request.shared = None
        connection = request.connection
        if connection.pending:
            # A request handed to a worker reaches the engine only once the worker runs: this
            # read must not pass it on the line, so the worker that takes it takes this read
            # next (no task started: this may run in a callback).
            self._count_transaction(line)
            request.work = functools.partial(
                forward, line.master, unit, pdu, connection.priority, request.turn
            )
            connection.pending.append(request)
            return
        if self.coalesce:
            key = (unit, pdu)
            shared = line.shared.get(key)
            if shared is not None:
                self.counters.coalesced += 1
                line.stats.coalesced += 1
                shared.followers.append(request)
                return
            request.shared = line.shared[key] = _Shared()
        cache = line.cache
        if cache is not None and cache.cacheable(pdu):
            request.generation = cache.generation(unit)
        self._count_transaction(line)
        try:
            awaitable = start_forward(
                line.master, unit, line.as_bytes.request(pdu), connection.priority, request.turn
            )
        except Exception:
            _log.exception("gateway: forwarding a request failed; answered with exception 0B")
            self._end(request, exception_reply(pdu, _NO_RESPONSE))
            return
        if answered_from_callback(awaitable):
            request.connection.on_line.add(awaitable)
            awaitable.add_done_callback(functools.partial(self._read_done, request))
        else:
            request.submitted = awaitable
            request.work = functools.partial(reply_from, awaitable, unit, pdu)
            self._to_worker(request)

    def _read_done(self, request: _Request, future: asyncio.Future[Any]) -> None:
        """The done-callback of read `request`'s future: end it with its reply (none when
        its client left: the future is cancelled)."""
        request.connection.on_line.discard(future)
        reply: bytes | None = None
        if not future.cancelled():
            pdu = request.adu.pdu
            error = future.exception()
            try:
                result = None if error is not None else future.result()
                reply = reply_pdu(pdu, request.unit, result, error)
            except Exception:
                _log.exception("gateway: forwarding a request failed; answered with exception 0B")
                reply = exception_reply(pdu, _NO_RESPONSE)
        self._end(request, reply)

    def _end(self, request: _Request, reply: bytes | None) -> None:
        """`request` is over with `reply` (None: a broadcast, or its client left): the cache
        and the reads that shared it are told, the line's turn moves on, the reply is sent
        (unless its client has left), and its window place is freed once it is."""
        line = request.line
        if request.generation is not None and reply is not None:
            assert line.cache is not None
            line.cache.put(request.unit, request.adu.pdu, reply, request.generation)
        line.now = max(line.now, request.turn)
        connection = request.connection
        if reply is None or not connection.open:
            connection.done()
        else:
            self.statistics.answered(line.name, request.unit, reply)
            self.statistics.client(connection.client).replies += 1
            if connection.send_now(request.adu, reply):
                connection.done()
            else:
                connection.send_later(request.adu, reply)  # `_writer` frees its place
        shared = request.shared
        if shared is not None:  # after its own reply: a client's replies come in order
            self._shared_over(request, shared, reply)

    def _shared_over(self, request: _Request, shared: _Shared, reply: bytes | None) -> None:
        """The read that `shared` stands for is over: identical reads that joined it get
        `reply`, or ask again when its client left before it came (`reply` None)."""
        line = request.line
        key = (request.unit, request.adu.pdu)
        if line.shared.get(key) is shared:
            del line.shared[key]
        for follower in shared.followers:
            if reply is not None:
                self._end(follower, reply)
            elif follower.connection.open:
                self.counters.coalesced -= 1
                line.stats.coalesced -= 1
                follower.connection.in_flight -= 1  # counted again as it starts again
                self._start(follower)
            else:
                follower.connection.done()

    async def _writer(self, connection: _Client) -> None:
        """Send the connection's replies the stream did not take at once, in order, each
        freeing its window place once sent (see `Connection.send`)."""
        while True:
            adu, reply = await connection.next_unsent()
            try:
                if not await connection.send(adu, reply):
                    self._idle(connection, "read no reply")
            finally:
                connection.unsent.popleft()
                connection.done()

    def _cached(self, line: _Line, unit: int, pdu: bytes) -> bytes | None:
        """The cache's reply to read `pdu`, counted; None when it has none."""
        cache = line.cache
        if cache is None or not cache.cacheable(pdu):
            return None
        cached = cache.get(unit, pdu)
        if cached is not None:
            self.counters.cache_hits += 1
            line.stats.cache_hits += 1
        return cached

    @staticmethod
    async def _unanswered(line: _Line, unit: int, pdu: bytes, priority: int, turn: int) -> bytes:
        """Send 08/04, or 08/01 to a unit in listen-only mode, which no reply follows; note the
        unit's mode once sent."""
        reply = await forward_unanswered(line.master, unit, pdu, priority, turn)
        if reply is pdu:
            if pdu.startswith(FORCE_LISTEN_ONLY):
                line.listen_only.add(unit)
            else:
                line.listen_only.discard(unit)
        return reply

    async def _broadcast(self, pdu: bytes, priority: int, turn: int) -> None:
        """Send `pdu` to every unit of every line."""
        for line in self._lines:
            if await forward_broadcast(line.master, pdu, priority, turn):
                self._count_transaction(line)
                self.counters.broadcasts += 1
                line.stats.broadcasts += 1

    def _count_transaction(self, line: _Line) -> None:
        self.counters.transactions += 1
        line.stats.transactions += 1


def answered_from_callback(awaitable: object) -> TypeGuard[asyncio.Future[Any]]:
    """The read shortcut's predicate: the reply comes as an event loop future (the engine runs
    the read itself: its fast path, or its queue on a line with an event loop), so the future's
    done-callback answers it, with no task. Elsewhere (trio, a line without an event loop, a
    read the engine runs on its caller's task) a worker awaits it. Both end in
    `Gateway._end`."""
    return isinstance(awaitable, asyncio.Future)


def accepted_in_callback(connection: _Client, chunk: bytes) -> Adu | None:
    """The pushed read's predicate: the request in `chunk`, which a pushed connection's tap
    offers, for the read callback to take (`Gateway._tap`), or None for the reader task
    (`Gateway._read`); both take a request through `Gateway._admit`. The callback takes it when:

    - the connection is open and speaks Modbus TCP (RTU frames may wait for a silence, which
      only the reader times), and its framing holds nothing of an earlier request (that
      comes first, through the reader);
    - its window has room (else the reader waits for room, and TCP holds the client back);
    - one of its workers is parked (a write, or a read the engine runs on its caller's task,
      is handed to it: a callback cannot start a task);
    - `chunk` is exactly one well-formed MBAP request (several, a part of one or a malformed
      header go to the framing, which splits them or closes the connection).
    """
    if not connection.open or not isinstance(connection.framing, MbapFraming):
        return None
    if connection.framing.buffered or connection.in_flight >= connection.window:
        return None
    if not connection.parked:
        return None  # a request may need a worker, and a callback cannot start a task
    try:
        return decode_adu(chunk)
    except FrameError:
        return None


def _drop_unstarted(connection: _Client) -> None:
    """The connection is over: close the line's awaitables of the reads no worker took (a
    coroutine not started yet, which sent nothing), so that none is left unawaited."""
    for request in connection.pending:
        submitted = request.submitted
        if inspect.iscoroutine(submitted):
            submitted.close()
    connection.pending.clear()


def _check_options(
    *,
    max_in_flight: int,
    max_connections: int,
    client_statistics: int,
    idle_timeout: float,
    default_unit: int | None,
    cache_ms: float,
) -> None:
    """Raise InvalidValue for the first of the gateway's options that is wrong."""
    if not (isinstance(cache_ms, (int, float)) and cache_ms >= 0):
        raise InvalidValue("cache_ms", cache_ms, "a number of milliseconds, 0 or more")
    for name, value in (
        ("max_in_flight", max_in_flight),
        ("max_connections", max_connections),
        ("client_statistics", client_statistics),
    ):
        if type(value) is not int or value < 1:
            raise InvalidValue(name, value, "an int of at least 1")
    if not (isinstance(idle_timeout, (int, float)) and idle_timeout > 0):
        raise InvalidValue("idle_timeout", idle_timeout, "a positive number of seconds")
    if default_unit is not None and default_unit not in UNIT_ADDRESSES:
        raise InvalidValue("default_unit", default_unit, UNIT_ADDRESSES)


def certificate_role_of(stream: anyio.abc.ByteStream) -> str | None:
    """The role in the client certificate of a TLS `stream` (None: not TLS, no certificate, or
    no readable role: the rules' default role applies)."""
    der = stream.extra(TLSAttribute.peer_certificate_binary, None)
    if der is None:
        return None
    try:
        return certificate_role(der)
    except CertificateError:
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


def _cache_clock(clock: Callable[[], float] | None) -> Callable[[], float]:
    """`clock`, or the event loop's where the gateway is made in one. (Not `anyio.current_time`:
    the cache is also read from the loop's callbacks, where no task runs to tell the backend.)"""
    if clock is not None:
        return clock
    try:
        return loop_clock()
    except RuntimeError:  # no event loop runs here: asyncio's clock
        return time.monotonic

"""Modbus TCP for the slave: the same stores, handlers, routes and hooks, many connections.

[`ModbusTcpServer`][aiortu.slave.ModbusTcpServer] answers Modbus TCP (MBAP) requests on any number
of connections; `aiortu.serve("tcp://0.0.0.0:1502", {17: store})` opens the listener and runs one.
Each request goes through the same general route as on a serial line (`Dispatcher`: the machine's
checks, the handler, the hooks, the exception codes); only the framing differs. What the spec leaves
to us, and what this server does:

- **Replies** carry the request's transaction id and unit id. A connection's requests are
  answered one at a time, in order; a client may pipeline them. The server reads from a
  connection again only once it has answered everything it read, at most
  `READ_SIZE` bytes at a time, so the requests in flight per connection are
  bounded and a client that sends faster than it is answered is held back by TCP.
- **Requests of all connections are executed one at a time**, as one device executes
  them: a store never sees two requests at once, and the state machine's counters stay
  consistent. An async handler that waits holds up the other connections meanwhile.
- **Unit ids.** Over TCP the IP address names the device and the unit id is for
  gateways; the Implementation Guide recommends 0xFF and also accepts 0 for "the device
  itself". `unit_aliases` maps unit ids to served units; by default a server with one
  unit maps 0 and 255 to it. With several units and no alias, unit 0 is a broadcast,
  executed by every unit and never answered, as a gateway does on its serial line.
- **A unit the server does not serve** gets exception 0B (gateway target device failed to
  respond) at once, as a gateway answers for a device that is not there: over a serial
  line silence costs the master one timeout, but a TCP client would wait its whole
  timeout for nothing, and 0B tells it at once that the unit, not the server, is
  missing. `answer_unknown_units=False` keeps silent instead.
- **The serial-line-only function codes** 07, 08, 0B, 0C and 11 get exception 01 by
  default: the application protocol spec marks them "serial line only", their answers
  (bus counters, the comm event log) describe a serial line this server does not have,
  and 08/04 from one client would put the device in listen-only mode for every client.
  `serial_line_codes=True` serves them with the built-in handlers; a handler set for
  one of them with `set_handler` is always served.
- **Limits.** At most `max_connections` at once: a connection over the limit is closed at
  once (logged once until the count drops). A connection that sends nothing for
  `idle_timeout` seconds is closed, and so is one whose reply cannot be written for as long
  (a client that sends requests and never reads the replies). A malformed MBAP header
  (protocol id not 0, a length field outside 2..254) closes that connection only: nothing in
  the stream marks where the next request would start. The first is logged as a warning,
  the rest at debug level (all counted in `connections_malformed`), so that a flood of them
  costs counts, not log lines.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sized
from dataclasses import dataclass
from typing import Final

import anyio
import anyio.abc

from aiortu._log import get_logger
from aiortu.core.codes import BROADCAST_UNIT, UNIT_ADDRESSES, ExceptionCode, FunctionCode
from aiortu.core.machines import SlaveMachine
from aiortu.core.mbap import Adu, MalformedHeader
from aiortu.core.model import AsyncDataStore, DataStore
from aiortu.core.pdu import encode_exception
from aiortu.errors import InvalidValue
from aiortu.slave._answer_at_once import AnswerAtOnce
from aiortu.slave._dispatch import RESTART_COMMUNICATIONS, Dispatcher, TraceCallback
from aiortu.slave._handlers import BUILTIN_HANDLERS, Handler, Reply
from aiortu.slave._tcp_at_once import ConnectionTap, Permits
from aiortu.transport import (
    RTU_SILENCE,
    ConnectionLimit,
    Framing,
    MbapFraming,
    PushServerStream,
    listening_address,
    log_level,
    peer_address,
    push_listener,
    pushed_listener,
    serve_listener,
    write_now,
)

__all__ = (
    "DEFAULT_IDLE_TIMEOUT",
    "DEFAULT_MAX_CONNECTIONS",
    "READ_SIZE",
    "SERIAL_LINE_ONLY",
    "ModbusTcpServer",
    "TcpServerCounters",
)

_log = get_logger(__name__)

DEFAULT_MAX_CONNECTIONS: Final = 32
"""Connections served at once unless told otherwise."""

DEFAULT_IDLE_TIMEOUT: Final = 120.0
"""Seconds a connection may stay silent before it is closed, unless told otherwise."""

READ_SIZE: Final = 4096
"""The most bytes read from a connection at once (about 16 requests of the longest kind)."""

SERIAL_LINE_ONLY: Final = frozenset(
    {
        FunctionCode.READ_EXCEPTION_STATUS,
        FunctionCode.DIAGNOSTICS,
        FunctionCode.GET_COMM_EVENT_COUNTER,
        FunctionCode.GET_COMM_EVENT_LOG,
        FunctionCode.REPORT_SERVER_ID,
    }
)
"""The function codes the spec defines for serial lines only: 07, 08, 0B, 0C, 11."""

_ID_RANGE = range(256)
_GATEWAY_NO_RESPONSE = ExceptionCode.GATEWAY_TARGET_DEVICE_FAILED_TO_RESPOND


@dataclass(slots=True)
class TcpServerCounters:
    """What happened to the connections and requests of a
    [`ModbusTcpServer`][aiortu.slave.ModbusTcpServer]."""

    connections_accepted: int = 0
    """Connections served (over TLS counted from the accept: the handshake takes a place)."""
    connections_refused: int = 0
    """Connections closed at once because *max_connections* were open."""
    connections_idle: int = 0
    """Connections closed after *idle_timeout* of silence, or of replies not read."""
    connections_malformed: int = 0
    """Connections closed for a malformed MBAP header."""
    requests: int = 0
    """Requests received (ADUs with a valid header)."""
    unknown_unit: int = 0
    """Requests for a unit id the server does not serve."""


@dataclass(frozen=True, slots=True)
class _Outgoing:
    """A reply ADU, and the seconds to wait before sending it (a Reply's delay)."""

    adu: bytes
    delay: float = 0.0


class ModbusTcpServer(Dispatcher):
    """A Modbus TCP server for `units` (see the module docstring for what it decides).

    `units` maps unit addresses (1..247) to data stores; `handlers` adds or replaces handlers by
    function code as `set_handler` does. `unit_aliases` maps unit ids (0..255) to served units
    (default: 0 and 255 to the only unit, when there is one). `trace` sees `("received", adu)` and
    `("sent", adu)` for every request and reply, MBAP header included. Serve connections with
    [`serve`][aiortu.slave.ModbusTcpServer.serve] (a listener) or
    [`serve_connection`][aiortu.slave.ModbusTcpServer.serve_connection] (one byte stream);
    [`aiortu.slave.serve`][aiortu.slave.serve] does it for a URL.

    Raises [`InvalidValue`][aiortu.errors.InvalidValue] for a unit outside 1..247, an alias that
    is not a served unit, a `max_connections` below 1 or an `idle_timeout` that is not
    positive.
    """

    _new_framing: Callable[[], Framing] = MbapFraming
    """How a connection's bytes become requests and its replies bytes (one per connection)."""
    _name = "Modbus TCP"

    def __init__(
        self,
        units: Mapping[int, DataStore | AsyncDataStore],
        *,
        handlers: Mapping[int, Handler] | None = None,
        unit_aliases: Mapping[int, int] | None = None,
        answer_unknown_units: bool = True,
        serial_line_codes: bool = False,
        max_connections: int = DEFAULT_MAX_CONNECTIONS,
        idle_timeout: float = DEFAULT_IDLE_TIMEOUT,
        trace: TraceCallback | None = None,
    ) -> None:
        for unit in units:
            if unit not in UNIT_ADDRESSES:
                raise InvalidValue("unit", unit, UNIT_ADDRESSES)
        if type(max_connections) is not int or max_connections < 1:
            raise InvalidValue("max_connections", max_connections, "an int of at least 1")
        if not (isinstance(idle_timeout, (int, float)) and idle_timeout > 0):
            raise InvalidValue("idle_timeout", idle_timeout, "a positive number of seconds")
        stores: dict[int, DataStore | AsyncDataStore] = dict(units)
        builtins = {
            code: handler
            for code, handler in BUILTIN_HANDLERS.items()
            if serial_line_codes or code not in SERIAL_LINE_ONLY
        }
        self._init_dispatch(stores, SlaveMachine(stores), builtins)
        self._build_contexts()
        for function_code, handler in (handlers or {}).items():
            self.set_handler(function_code, handler)
        self.unit_aliases: dict[int, int] = _aliases(stores, unit_aliases)
        """Unit ids answered as another unit (see the module docstring)."""
        self.answer_unknown_units = answer_unknown_units
        """Whether a request for a unit not served gets exception 0B (else no reply)."""
        self.idle_timeout = idle_timeout
        """Seconds of silence after which a connection is closed."""
        self.counters = TcpServerCounters()
        """What happened to the connections and requests."""
        self.trace = trace
        self.local_address: tuple[str, int] | None = None
        """The host and port [`serve`][aiortu.slave.ModbusTcpServer.serve] listens on, once it
        does."""
        self.connection_error: Exception | None = None
        """Why [`serve`][aiortu.slave.ModbusTcpServer.serve] stopped, when the listener failed."""
        self._served = frozenset((*stores, *self.unit_aliases, BROADCAST_UNIT))
        self._limit = ConnectionLimit(self._name, max_connections, self.counters)
        self._replies = self._new_framing()  # encodes replies: the same for every connection
        self._lock = anyio.Lock(fast_acquire=True)
        self._stopped = anyio.Event()

    def _init_dispatch(
        self,
        units: dict[int, DataStore | AsyncDataStore],
        machine: SlaveMachine,
        handlers: Mapping[int, Handler],
    ) -> None:
        super()._init_dispatch(units, machine, handlers)
        # Made here: the base class configures the handlers and sets the trace next.
        self._at_once = AnswerAtOnce(
            machine, self._pending_requests(), before=self._before, after=self._after
        )

    def _pending_requests(self) -> Sized:
        """What waits for the general route, which a request answered at once must not pass.
        Nothing on a connection: its stream offers the shortcut nothing while its task has
        bytes to read (a datagram server's backlog is another matter)."""
        return ()

    @property
    def connections(self) -> int:
        """The connections open now."""
        return self._limit.open

    @property
    def max_connections(self) -> int:
        """Connections served at once; more are closed at once."""
        return self._limit.max_connections

    @max_connections.setter
    def max_connections(self, value: int) -> None:
        self._limit.max_connections = value

    @property
    def port(self) -> int:
        """The port [`serve`][aiortu.slave.ModbusTcpServer.serve] listens on (useful after asking
        for port 0)."""
        if self.local_address is None:
            raise RuntimeError("the server is not listening yet")
        return self.local_address[1]

    async def wait_stopped(self) -> None:
        """Wait until [`serve`][aiortu.slave.ModbusTcpServer.serve] has ended (the listener failed
        or closed)."""
        await self._stopped.wait()

    # -- connections -----------------------------------------------------------------

    async def serve(
        self,
        listener: anyio.abc.Listener[anyio.abc.ByteStream],
        *,
        task_status: anyio.abc.TaskStatus[None] = anyio.TASK_STATUS_IGNORED,
    ) -> None:
        """Accept connections from `listener` and serve each, until cancelled.

        Reports started to `task_status` once
        [`local_address`][aiortu.slave.ModbusTcpServer.local_address] is set.
        """
        if push_listener(listener):
            listener = pushed_listener(listener)
        try:
            self.local_address = listening_address(listener)
            task_status.started()
            await serve_listener(listener, self.serve_connection, self._limit)
        except Exception as error:
            self.connection_error = error
            _log.error("%s: the listener failed: %s", self._name, error)
        finally:
            self._stopped.set()

    async def serve_connection(self, stream: anyio.abc.ByteStream) -> None:
        """Serve one connection until the client closes it, it stays silent for
        [`idle_timeout`][aiortu.slave.ModbusTcpServer.idle_timeout], a reply cannot be written
        for as long (it reads nothing), or it sends a malformed header; then close it."""
        framing = self._new_framing()
        tap = None
        if isinstance(stream, PushServerStream) and isinstance(framing, MbapFraming):
            tap = stream.tap = ConnectionTap(self._at_once, self, stream, framing, self._permits())
        try:
            while (adus := await self._next_requests(stream, framing, tap)) is not None:
                if adus and not await self._answer_all(stream, adus):
                    return
        except (anyio.EndOfStream, anyio.BrokenResourceError, anyio.ClosedResourceError):
            return
        finally:
            await stream.aclose()

    def _permits(self) -> Permits | None:
        """Whether the client of the connection being served may send a request (None: any)."""
        return None

    async def _next_requests(
        self, stream: anyio.abc.ByteStream, framing: Framing, tap: ConnectionTap | None
    ) -> list[Adu] | None:
        """The requests the connection's next bytes (or a silence, for a frame of unknown
        length) complete; None when the connection is to close (idle, malformed). Requests
        `tap` answered at once meanwhile count as traffic."""
        quiet = RTU_SILENCE if framing.waiting_for_silence() else self.idle_timeout
        while True:
            with anyio.move_on_after(quiet) as idle:
                data = await stream.receive(READ_SIZE)
            if not idle.cancelled_caught:
                break
            if framing.waiting_for_silence():
                return framing.silence()
            if tap is not None and tap.last_answer >= 0:
                quiet = tap.last_answer + self.idle_timeout - anyio.current_time()
                if quiet > 0:
                    continue  # answered at once meanwhile: not idle
            self.counters.connections_idle += 1
            _log.info(
                "%s: %s idle for %g s, closed", self._name, peer_address(stream), self.idle_timeout
            )
            return None
        try:
            return framing.feed(data)
        except MalformedHeader as error:
            self.counters.connections_malformed += 1
            _log.log(
                log_level(self.counters.connections_malformed),
                "%s: %s sent %s; connection closed (logged at debug level after the first)",
                self._name,
                peer_address(stream),
                error,
            )
            return None

    async def _answer_all(self, stream: anyio.abc.ByteStream, adus: list[Adu]) -> bool:
        """Answer `adus` in order; replies that need no wait go out in one write. False when
        a reply could not be written (see `_send`)."""
        out = bytearray()
        for adu in adus:
            outgoing = await self._respond(adu)
            if outgoing is None:
                continue
            if outgoing.delay > 0:
                if out and not await self._send(stream, bytes(out)):
                    return False
                out.clear()
                await anyio.sleep(outgoing.delay)
            out += outgoing.adu
        return not out or await self._send(stream, bytes(out))

    async def _send(self, stream: anyio.abc.ByteStream, data: bytes) -> bool:
        """Send `data`; False when it could not be written for `idle_timeout` seconds: the
        client reads nothing, and the connection is to close (counted as idle). Data the
        transport takes at once needs no timer (nor the event-loop turn `send()` ends with)."""
        if write_now(stream, data):
            return True
        with anyio.move_on_after(self.idle_timeout):
            await stream.send(data)
            return True
        self.counters.connections_idle += 1
        _log.info(
            "%s: %s read no reply for %g s, closed",
            self._name,
            peer_address(stream),
            self.idle_timeout,
        )
        return False

    # -- one request -----------------------------------------------------------------

    async def _respond(self, adu: Adu) -> _Outgoing | None:
        """The reply to one request, through the machine, the handler and the hooks."""
        self.counters.requests += 1
        if self.trace is not None:
            self._traced("received", self._replies.encode(adu, adu.pdu))
        unit = self.unit_aliases.get(adu.unit, adu.unit)
        pdu = adu.pdu
        if unit not in self._served:
            self.counters.unknown_unit += 1
            if not self.answer_unknown_units:
                return None
            return self._sent(adu, encode_exception(pdu[0], _GATEWAY_NO_RESPONSE))
        async with self._lock:
            machine = self.machine
            machine.frame_received(unit, pdu[0])
            if machine.listen_only and pdu[:3] != RESTART_COMMUNICATIONS:
                machine.ignore()
                return None
            reply = await self._answer(unit, pdu)
            if reply is None or not machine.should_reply:
                machine.no_reply()
                return None
            if type(reply) is bytes:
                outgoing = self._sent(adu, reply)
            else:
                assert isinstance(reply, Reply)
                assert reply.response is not None
                unit_id = adu.unit if reply.unit is None else reply.unit
                outgoing = self._sent(adu, reply.response.encode(), unit_id, reply.delay)
            machine.reply_sent()
            return outgoing

    def _sent(
        self, request: Adu, pdu: bytes, unit_id: int | None = None, delay: float = 0.0
    ) -> _Outgoing:
        if unit_id is not None and unit_id != request.unit:
            request = Adu(request.transaction_id, unit_id, b"")
        adu = self._replies.encode(request, pdu)
        if self.trace is not None:
            self._traced("sent", adu)
        return _Outgoing(adu, delay)


def _aliases(stores: Mapping[int, object], aliases: Mapping[int, int] | None) -> dict[int, int]:
    """The unit aliases, checked; by default 0 and 255 name the only unit, if one."""
    if aliases is None:
        if len(stores) != 1:
            return {}
        (only,) = stores
        return {BROADCAST_UNIT: only, 0xFF: only}
    for unit_id, unit in aliases.items():
        if unit_id not in _ID_RANGE:
            raise InvalidValue("unit_aliases", unit_id, _ID_RANGE, "a unit id is 0..255")
        if unit not in stores:
            raise InvalidValue(
                "unit_aliases", unit, sorted(stores), f"unit id {unit_id} must name a served unit"
            )
    return dict(aliases)

# ruff: noqa: ASYNC109
# ``timeout=`` here is the Modbus response timeout, counted from the end of transmission
# by the master; a cancel scope around the call cannot express that.
"""The async Modbus RTU master: one line, one transaction at a time, shared by any number
of coroutines.

    async with aiortu.open_master("/dev/ttyUSB0", baudrate=19200, parity="E") as master:
        regs = await master.read_holding_registers(17, 0x6B, 3)
        await master.write_registers(17, 0x10, [1, 2, 3])
        bits = await master.slave(17).read_coils(0x13, 20)
        await master.broadcast.write_register(0x10, 7)

[`Master`][aiortu.master.Master] takes any `anyio.abc.ByteStream`;
[`open_master`][aiortu.master.open_master] opens one from a port name or URL first. The line engine
lives in [`aiortu.master`][aiortu.master], the state machine in
[`aiortu.core.machines`][aiortu.core.machines], the per-unit and broadcast handles in
[`aiortu.master`][aiortu.master].

Who runs a transaction. The line is owned by one transaction at a time: on an idle line a
call sends its request and waits for the reply itself, and a busy line hands itself to the
next queued call (FIFO, lower priority first) when the transaction in progress ends; on a
serial port (a line with an event loop) the engine runs that call's transaction for it and
completes the future the call awaits, elsewhere the call runs it in its own task.
Exchanges never overlap, and a caller cancelled after its request began to go out leaves
the attempt to the master's line task, which waits for its reply (so that it never
reaches a later request) and only then hands the line on. The line task also notices a
dead link and fails the queue. Why and where the transaction runs: see docs/architecture.md.
"""

from __future__ import annotations

import contextlib
from collections.abc import AsyncIterator, Awaitable, Callable, Mapping
from types import TracebackType
from typing import Any, Self, TypeVar

import anyio
import anyio.abc

from aiortu.core.codes import BROADCAST_UNIT, SERIAL_UNIT_IDS, UnitIds
from aiortu.core.machines import RetryPolicy, Transaction
from aiortu.core.pdu import (
    ExceptionPDU,
    RawPDU,
    Request,
    Response,
    decode_request,
)
from aiortu.core.rtu import Role
from aiortu.core.serial import LineSettings
from aiortu.errors import InvalidRequest, InvalidValue, MalformedPDU
from aiortu.line import Link
from aiortu.master._arguments import (
    UNIT_RANGE,
    check_at_least,
    check_int,
    check_priority,
    check_timeout,
    check_turnaround,
    check_unit,
)
from aiortu.master._config import MasterConfig
from aiortu.master._connection import LineConnection, StreamOpener, can_reconnect
from aiortu.master._engine import LineEngine, UnitOffline, UnitStats
from aiortu.master._handles import BroadcastHandle, UnitHandle
from aiortu.master._operations import Operations, answer
from aiortu.master._seam import Seam
from aiortu.transport import FramedStream

__all__ = ("Master", "UnitOffline", "UnitStats", "open_master")

_ResponseT = TypeVar("_ResponseT", bound=Response)
_SEND_ONCE = RetryPolicy(0)
"""The policy of a request without reply: nothing tells a failed attempt."""


def _unit_ids(stream: object) -> UnitIds:
    """The unit ids `stream`'s framing carries, as it declares them; a serial line's where it
    declares none (RTU frames on a byte stream, or a seam given in its place)."""
    return stream.unit_ids if isinstance(stream, FramedStream) else SERIAL_UNIT_IDS


def _known_form(pdu: object) -> Request:
    """`pdu` if it is a Request; a [`RawPDU`][aiortu.core.pdu.RawPDU] of a function code aiortu has
    a class for as that class, so that its reply (decoded as that code's) is checked as such."""
    if type(pdu) is RawPDU:
        try:
            return decode_request(pdu.encode())
        except MalformedPDU as error:
            raise InvalidRequest("pdu", pdu, "a request the spec allows", str(error)) from None
    if not isinstance(pdu, Request):
        raise InvalidRequest("pdu", pdu, "a Request PDU")
    return pdu


class Master(Operations):
    """A Modbus RTU master on `stream`; an async context manager.

    `stream` is any `anyio.abc.ByteStream`, or a [`Seam`][aiortu.master.Seam] that answers
    requests itself (a test's [`MockLine`][aiortu.testing.MockLine]). `settings` give the line
    timing. The options are a [`MasterConfig`][aiortu.master.MasterConfig] (`config`) and the
    everyday keywords on top of it (`timeout=`, `retries=`, `offline_after=`, ...: the names of
    `MasterConfig.KEYWORDS`, each setting one field of one of its policies; see there).
    `clock` is the master's time.

    Reconnecting (see [`ReconnectPolicy`][aiortu.master.ReconnectPolicy]): when the stream
    fails, the request in flight and the queued ones raise
    [`ConnectionLost`][aiortu.errors.ConnectionLost]. A master given only a stream cannot reopen
    it and stays failed. Given an `opener` (an async function returning a new stream for the
    same port; [`open_master`][aiortu.master.open_master] passes one), it reopens the port as its
    reconnect policy says.

    Every method takes the unit first, and `timeout=` (this call's response timeout)
    and `priority=` (lower goes first; equal priorities keep their order). Requests
    outside the spec raise [`InvalidRequest`][aiortu.errors.InvalidRequest] before anything is
    sent. An exception reply raises [`ExceptionResponse`][aiortu.errors.ExceptionResponse]; no reply
    raises [`ResponseTimeout`][aiortu.errors.ResponseTimeout]; bad bytes after the retries raise
    [`FrameError`][aiortu.errors.FrameError] ([`CRCError`][aiortu.errors.CRCError] for a CRC);
    a dead line raises [`ConnectionLost`][aiortu.errors.ConnectionLost].

    How a late reply is kept from a later request. RTU frames carry no transaction id,
    so a reply is matched by what it is and when it came:

    1. Before each request goes out, whatever the line delivered is dropped. Causality: where the
       line's wire times are real (a serial port, a paced virtual line: see `wire_timed`), a frame
       whose first byte arrived before the request had left the wire plus the unit's minimum
       turnaround plus that byte's own wire time (`min_turnaround` seconds, 0 by default;
       [`set_min_turnaround`][aiortu.master.Master.set_min_turnaround] per unit) is stale; elsewhere
       (TCP, ptys, unpaced virtual lines) a frame that ended before the request began to go out is.
    2. A frame must come from the unit asked, with the request's function code (or its
       exception form), and pass the request's checks of the reply (byte count, echoed
       address, count and values); anything else is skipped while the wait goes on.
    3. After a transaction in which an attempt failed, the line is kept quiet for
       `late_reply_guard` seconds (0.1 by default) before the next request, on top of
       the `frame_gap` silence: a reply that straggles in meanwhile is stale by rule 1.

    The limit: a reply later than that guard, from the same unit, that also passes the
    next request's checks (a read of the same count, say), cannot be told from the real
    reply. Raise `late_reply_guard` on lines with slow devices, or use per-call timeouts
    longer than the slowest device's reply time.

    Cancelling a caller never desynchronises the line: one transaction owns the line at
    a time; a cancelled request still queued (or not yet sent) is dropped, and one in
    flight has its attempt finished by the master's line task (its reply is consumed
    there) without retries, before the next request goes out.
    """

    def __init__(
        self,
        stream: anyio.abc.ByteStream | Seam,
        settings: LineSettings | None = None,
        *,
        config: MasterConfig | None = None,
        clock: Callable[[], float] = anyio.current_time,
        opener: StreamOpener | None = None,
        **options: Any,
    ) -> None:
        if settings is not None and not isinstance(settings, LineSettings):
            raise InvalidValue("settings", settings, "a LineSettings or None")
        if not callable(clock):
            raise InvalidValue("clock", clock, "a function returning the time in seconds")
        if opener is not None and not callable(opener):
            raise InvalidValue("opener", opener, "None or an async function returning a stream")
        if config is not None and not isinstance(config, MasterConfig):
            raise InvalidValue("config", config, "a MasterConfig or None")
        config = (config if config is not None else MasterConfig()).with_options(**options)
        self.config = config
        """The master's options (see [`MasterConfig`][aiortu.master.MasterConfig])."""
        self.settings = settings if settings is not None else LineSettings()
        self.timeout = config.timeout
        self.turnaround_delay = config.timings.turnaround_delay
        self.policy = config.retry
        timings = config.timings

        def make_link(stream: anyio.abc.ByteStream) -> Link:
            link = Link(
                stream, self.settings, role=Role.MASTER, timing=timings.mode,
                frame_gap=timings.frame_gap, clock=clock,
            )  # fmt: skip
            if timings.wire_timed is not None:
                link.wire_timed = timings.wire_timed
            return link

        self._engine: LineEngine | None = None
        self._connection: LineConnection | None = None
        self.seam: Seam
        """The one seam every request goes through (see [`Seam`][aiortu.master.Seam]): the
        line's engine, or the Seam given in place of a stream. A caller that builds its own
        [`Transaction`][aiortu.core.machines.Transaction]s (the line server) submits them
        here."""
        if isinstance(stream, Seam):
            self.seam = stream
        else:
            link = make_link(stream)
            reconnect = can_reconnect(opener, config.reconnection)
            engine = self.seam = self._engine = LineEngine(link, config, can_reconnect=reconnect)
            self._connection = LineConnection(engine, link, make_link, opener, config.reconnection)
        """Keeps the line up: reconnect counters, the current link."""
        self.unit_ids = _unit_ids(stream)
        """The unit ids the stream's framing carries (see
        [`FramedStream`][aiortu.transport.FramedStream])."""
        self.unit_range = self.unit_ids.unicast
        """The unit ids a request may go to: 1..247 on a serial line (RTU or ASCII); over
        Modbus TCP, UDP or TLS, whose MBAP header carries any byte, 0..255 as given (0 then
        awaits a reply like any other id; [`broadcast`][aiortu.master.Master] is the
        broadcast)."""
        self.broadcast = BroadcastHandle(self)
        """The writes that may go to every unit at once (unit 0); no reply is awaited."""
        self._exit_stack: contextlib.AsyncExitStack | None = None

    # -- lifetime --------------------------------------------------------------------

    async def __aenter__(self) -> Self:
        async with contextlib.AsyncExitStack() as stack:
            task_group = await stack.enter_async_context(anyio.create_task_group())
            stack.callback(task_group.cancel_scope.cancel)
            if self._connection is not None:
                task_group.start_soon(self._connection.run, name="aiortu master line task")
            self._exit_stack = stack.pop_all()
        self._entered_in = anyio.get_current_task().id
        return self

    async def __aexit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        traceback: TracebackType | None,
    ) -> bool | None:
        if self._exit_stack is None:
            return None
        if anyio.get_current_task().id != self._entered_in:
            # The line task runs in a task group of the entering task; no other may end it.
            raise RuntimeError(
                "a master must be left in the task that entered it, and this is another"
                " (the asyncio REPL runs each statement in a task of its own): use `async with`"
                " in one statement, or aiortu.blocking, whose masters close from any thread"
            )
        stack, self._exit_stack = self._exit_stack, None
        # The body's own exception propagates as it is, not wrapped in an ExceptionGroup.
        await stack.__aexit__(None, None, None)
        return None

    @property
    def engine(self) -> LineEngine:
        """The engine of the master's line (not on a [`Seam`][aiortu.master.Seam] given in
        place of a stream)."""
        if self._engine is None:
            raise InvalidValue("engine", self.seam, "a master on a byte stream", "no line")
        return self._engine

    @property
    def connection(self) -> LineConnection:
        """Keeps the line up: reconnect counters, the current link (not on a
        [`Seam`][aiortu.master.Seam] given in place of a stream)."""
        if self._connection is None:
            raise InvalidValue("connection", self.seam, "a master on a byte stream", "no line")
        return self._connection

    @property
    def link(self) -> Link:
        """The line the master talks on now (a new one after each reconnect)."""
        return self.connection.link

    @property
    def connected(self) -> bool:
        """Whether the line is up: False while reconnecting and once failed or closed
        (always True on a [`Seam`][aiortu.master.Seam] given in place of a stream)."""
        return self._connection is None or self._connection.connected

    def clock(self) -> float:
        """The master's time, in seconds (its line's clock)."""
        return self.seam.clock()

    # -- statistics ------------------------------------------------------------------

    @property
    def statistics(self) -> Mapping[int, UnitStats]:
        """[`UnitStats`][aiortu.master.UnitStats] by unit address, for units used so far."""
        return self.seam.stats

    def set_min_turnaround(self, unit: int, seconds: float | None) -> None:
        """Set the least time `unit` takes from the end of a request on the wire to the
        first byte of its reply (`None`: back to the master's *min_turnaround*).

        A frame that begins sooner cannot answer the request and is skipped as stale,
        where the line's wire times are real (see the class docstring). Set it from the
        device's documented turnaround; a spec-abiding device keeps at least t3.5 of
        silence. Too large a value drops the device's genuine replies.
        """
        check_unit(unit, self.unit_range)
        if self._engine is not None:
            self._engine.set_unit_turnaround(
                unit, None if seconds is None else check_turnaround(seconds)
            )

    def unit_stats(self, unit: int) -> UnitStats:
        """The statistics and health of `unit` (0..247, and up to 255 over Modbus TCP; on a
        serial line unit 0 counts the broadcasts)."""
        counted = self.unit_ids.ids
        return self.seam.unit_stats(check_int("unit", unit, counted, InvalidRequest))

    def is_online(self, unit: int) -> bool:
        """False once `unit` failed `offline_after` times in a row, until a success."""
        return self.unit_stats(unit).online

    def slave(self, unit: int) -> UnitHandle:
        """A handle on one unit: the same methods without the unit, plus typed values."""
        return UnitHandle(self, check_unit(unit, self.unit_range))

    # -- the core of every call ------------------------------------------------------

    async def execute(
        self, unit: int, pdu: Request, *, timeout: float | None = None, priority: int = 0
    ) -> Response | ExceptionPDU:
        """Send any request PDU (a [`RawPDU`][aiortu.core.pdu.RawPDU] for custom codes) and
        return the reply as it came, an exception reply included (not raised).

        A RawPDU of a function code aiortu has a class for is sent as that class, and
        its reply checked as such (a malformed one raises InvalidRequest). A request is
        sent again after a failure only if its code is in the master's *repeatable*.
        """
        check_unit(unit, self.unit_range)
        pdu = _known_form(pdu)
        policy = self.policy.for_function(pdu.function_code)
        transaction = Transaction(
            unit, pdu, self._timeout(timeout), policy, priority=check_priority(priority)
        )
        response = await self.seam.submit(transaction)
        assert response is not None
        return response

    async def send_without_reply(self, unit: int, pdu: Request, *, priority: int = 0) -> None:
        """Send `pdu` to `unit` (0 broadcasts it), then wait the turnaround delay.

        No reply is awaited. Unit 0 takes only requests the spec lets be broadcast.
        """
        pdu = _known_form(pdu)
        if type(unit) is int and unit == BROADCAST_UNIT:
            if not pdu.broadcastable:
                raise InvalidRequest(
                    "unit", unit, UNIT_RANGE, f"{type(pdu).__name__} may not be broadcast"
                )
        else:
            check_unit(unit, self.unit_range)
        transaction = Transaction(
            unit,
            pdu,
            self.timeout,
            _SEND_ONCE,
            expects_reply=False,
            turnaround=self.turnaround_delay,
            priority=check_priority(priority),
        )
        await self.seam.submit(transaction)

    async def request(
        self,
        unit: int,
        pdu: Request,
        expected: type[_ResponseT],
        *,
        timeout: float | None = None,
        priority: int = 0,
        retries: int | None = None,
    ) -> _ResponseT:
        """Send `pdu`, raise ExceptionResponse for an exception reply, return the reply.

        `retries` overrides the master's retry count for this call (a poller probing a
        unit that has stopped answering sends once).
        """
        # execute(), inlined: one coroutine less per call.
        if type(pdu) is RawPDU or not isinstance(pdu, Request):
            pdu = _known_form(pdu)
        if not isinstance(expected, type) or not issubclass(expected, Response):
            raise InvalidRequest("expected", expected, "a Response class")
        policy = self.policy
        if retries is not None:
            policy = policy.with_retries(check_at_least("retries", retries, 0, InvalidRequest))
        policy = policy.for_function(pdu.function_code)
        response = await self._submit(unit, pdu, timeout, priority, policy)
        assert response is not None
        return answer(response, pdu, unit, expected)

    def _submit(
        self,
        unit: int,
        request: Request,
        timeout: float | None,
        priority: int,
        policy: RetryPolicy | None = None,
    ) -> Awaitable[Response | ExceptionPDU | None]:
        """The engine's awaitable of `request` (`policy`: the master's retry policy by
        default), the unit and the timeout checked. An awaitable, not a coroutine: a read
        that goes out at once is then one coroutine (the caller's) waiting on the
        engine's future."""
        # The commonest call (a unicast unit, the master's timeout) makes no further call.
        if type(unit) is not int or unit not in self.unit_range:
            check_unit(unit, self.unit_range)  # raises, saying why
        if type(priority) is not int:
            priority = check_priority(priority)
        response_timeout = self.timeout if timeout is None else check_timeout(timeout)
        if policy is None:
            policy = self.policy
            if request.function_code not in policy.repeatable:
                policy = policy.for_function(request.function_code)
        return self.seam.submit(
            Transaction(unit, request, response_timeout, policy, priority=priority)
        )

    def _timeout(self, timeout: float | None) -> float:
        return self.timeout if timeout is None else check_timeout(timeout)


def _opener(port_or_url: str, settings: LineSettings, options: dict[str, Any]) -> StreamOpener:
    """Opens `port_or_url` with `settings` and the transport's `options`: the first time, and
    again when the master reconnects."""
    from aiortu.transport import ModbusTcpAddress, ModbusTcpCounters, open_stream, parse_port_url

    if isinstance(parse_port_url(port_or_url), ModbusTcpAddress):
        # One set of counters for every connection: ids go on after a reconnect.
        options.setdefault("counters", ModbusTcpCounters())
    return lambda: open_stream(port_or_url, settings, **options)


@contextlib.asynccontextmanager
async def open_master(
    port_or_url: str,
    *,
    baudrate: int = 19200,
    parity: str = "E",
    stopbits: float = 1,
    bytesize: int = 8,
    config: MasterConfig | None = None,
    **options: Any,
) -> AsyncIterator[Master]:
    """Open `port_or_url` (a serial device path, `rtu+tcp://host:port`, or `tcp://host:port` for
    Modbus TCP) and yield a [`Master`][aiortu.master.Master] on it; the port is closed on exit.

    The line settings come from `baudrate`, `parity`, `stopbits` and `bytesize`. `config` and the
    everyday keywords among `options` (those of
    [`MasterConfig.KEYWORDS`][aiortu.master.MasterConfig]: `timeout`, `retries`, ...) are the
    master's; the other `options` go to
    [`aiortu.transport.open_stream`][aiortu.transport.open_stream] (`exclusive`, `rs485`,
    `local_echo`, `connect_timeout`). Opening errors are [`PortError`][aiortu.errors.PortError]s.

    Over Modbus TCP the line settings are not used, no silence is kept before a request
    (`frame_gap` 0), each request carries the next transaction id and a reply with another id is
    dropped, and the response timeout starts when the request was written (see
    [`ModbusTcpStream`][aiortu.transport.ModbusTcpStream]). The transaction ids and the counters
    ([`ModbusTcpCounters`][aiortu.transport.ModbusTcpCounters], at `master.link.stream.counters`)
    go on across reconnects.

    With reconnecting on (the default) the master reopens the same port with the same
    settings after it disappears (a USB adapter unplugged); see
    [`ReconnectPolicy`][aiortu.master.ReconnectPolicy].
    """
    keywords = MasterConfig.KEYWORDS
    master_options = {name: value for name, value in options.items() if name in keywords}
    transport_options = {name: value for name, value in options.items() if name not in keywords}
    if config is not None and not isinstance(config, MasterConfig):
        raise InvalidValue("config", config, "a MasterConfig or None")
    # Checked before the port is opened: a bad option leaves it shut.
    config = (config if config is not None else MasterConfig()).with_options(**master_options)
    settings = LineSettings(baudrate, bytesize, parity, stopbits)
    opener = _opener(port_or_url, settings, transport_options)
    stream = await opener()
    master = Master(stream, settings, opener=opener, config=config)
    try:
        async with master:
            yield master
    finally:
        with anyio.CancelScope(shield=True):
            await stream.aclose()

"""The slave: serves one or many unit addresses on one line from data stores.

:class:`Slave` takes any byte stream (a serial port, a TCP connection to a serial device
server, a virtual line) and a mapping of unit addresses to data stores::

    store = aiortu.MemoryStore(holding_registers={0x6B: 3})
    async with aiortu.Slave(stream, {17: store}):
        ...                                   # the slave serves in the background

or ``await slave.serve()`` to serve in the current task. :func:`serve` opens a port or a
URL first. One line may carry a whole bus of simulated units.

Each frame goes through the core's :class:`~aiortu.core.slave_machine.SlaveMachine`,
which decides what the spec says: frames for other units are dropped and counted, frames
with a bad CRC never reach it (the link discards and counts them), broadcasts are
executed by every unit and never answered, and exceptions come in the spec's order
(01, 03, 02, 04). A request is dispatched by function code to a handler (see
:mod:`aiortu.slave._handlers`); users register their own with :meth:`Slave.set_handler`,
including for the user-defined codes 65-72 and 100-110, which arrive as
:class:`~aiortu.core.pdu.RawPDU`. A handler that raises
:class:`~aiortu.errors.ExceptionResponse` answers with its code; any other error answers
04, is logged, and the slave goes on serving. The reply goes out after ``frame_gap`` of
silence on the line (t3.5 by default; the link keeps it).

Beyond function codes: :meth:`Slave.route` serves an address range of one table with a
function (see :mod:`aiortu.slave._routes`); :meth:`Slave.before_request` and
:meth:`Slave.after_request` add hooks around every request; a handler or hook that
returns a :class:`~aiortu.slave._handlers.Reply` answers late, as another unit, or not at
all, to test masters. *trace* sees every frame received and sent.
"""

from __future__ import annotations

import inspect
import logging
from collections import deque
from collections.abc import AsyncIterator, Callable, Iterable, Mapping
from contextlib import asynccontextmanager
from types import TracebackType
from typing import Any, Final, Self

import anyio
import anyio.abc
import anyio.lowlevel

from aiortu.core.codes import BROADCAST_UNIT, EXCEPTION_BIT, ExceptionCode
from aiortu.core.data_model import AsyncDataStore, DataStore, Table
from aiortu.core.frame import encode_frame
from aiortu.core.pdu import Request, decode_request
from aiortu.core.receiver import DiscardReason, FrameReceived, Role, TimingMode
from aiortu.core.slave_machine import SerialLineCounters, SlaveMachine, SlaveState
from aiortu.core.timing import LineSettings
from aiortu.errors import ConnectionLost, ExceptionResponse, InvalidValue, MalformedPDU
from aiortu.line._link import Link, LinkEvent
from aiortu.slave._handlers import (
    BUILTIN_HANDLERS,
    FAST_PATHS,
    Answer,
    FastPath,
    Handler,
    HandlerResult,
    Reply,
    RequestContext,
)
from aiortu.slave._routes import RangeHandler, RoutedStore
from aiortu.slave._store import MemoryStore
from aiortu.transport import open_stream

__all__ = ("AfterHook", "BeforeHook", "Slave", "TraceCallback", "serve")

_log = logging.getLogger(__name__)

BeforeHook = Callable[[Any, RequestContext], Answer]
"""Called before the handler with (request, context): ``None`` goes on to the handler, a
response or :class:`~aiortu.slave._handlers.Reply` answers instead of it, and raising
:class:`~aiortu.errors.ExceptionResponse` refuses the request. May be async."""

AfterHook = Callable[[Any, RequestContext, HandlerResult], Answer]
"""Called after the handler with (request, context, its answer): ``None`` keeps the
answer, anything else replaces it. May be async. Not called when the handler raised."""

TraceCallback = Callable[[str, bytes], object]
"""Sees the line: ``("received", frame)`` for every frame whose CRC checks (for any
unit), ``("sent", frame)`` for every reply, ``("discarded", data)`` for bytes dropped."""

_UNIT_RANGE = range(1, 248)
_FUNCTION_CODE_RANGE = range(1, EXCEPTION_BIT)


class _Taken:
    """A request the read callback took (counted, the machine CHECKING) and left to the
    serve loop: to answer (*reply* None), or with its *reply* PDU to send."""

    __slots__ = ("frame", "reply")

    def __init__(self, frame: bytes, reply: bytes | None) -> None:
        self.frame = frame
        self.reply = reply


class Slave:
    """A Modbus RTU slave on one line (see the module docstring).

    *units* maps each unit address (1..247) to its data store. *settings* are the line
    settings; *frame_gap* is the silence kept before each reply (``None`` for t3.5 of the
    settings, 0 for lines without a wire such as TCP). *timing* and *frame_silence*
    configure the receiver (see :mod:`aiortu.core.receiver`). *handlers* adds or replaces
    handlers by function code, as :meth:`set_handler` does. *clock* is the link's clock.
    *trace* sees every frame (see :data:`TraceCallback`).

    Raises :class:`~aiortu.errors.InvalidValue` for a unit address outside 1..247 or a
    function code outside 1..127.
    """

    def __init__(
        self,
        stream: anyio.abc.ByteStream,
        units: Mapping[int, DataStore | AsyncDataStore],
        settings: LineSettings | None = None,
        *,
        frame_gap: float | None = None,
        timing: TimingMode | str = TimingMode.TOLERANT,
        frame_silence: float | None = None,
        handlers: Mapping[int, Handler] | None = None,
        clock: Callable[[], float] = anyio.current_time,
        trace: TraceCallback | None = None,
    ) -> None:
        for unit in units:
            if unit not in _UNIT_RANGE:
                raise InvalidValue("unit", unit, _UNIT_RANGE)
        self.units: dict[int, DataStore | AsyncDataStore] = dict(units)
        """The data store of each unit served."""
        self.link = Link(
            stream,
            settings,
            role=Role.SLAVE,
            units=self.units,
            timing=timing,
            frame_silence=frame_silence,
            frame_gap=frame_gap,
            clock=clock,
        )
        """The line this slave serves (its counters say what the receiver discarded)."""
        self.counters = SerialLineCounters()
        """The spec's diagnostic counters of this line."""
        self.machine = SlaveMachine(self.units, self.counters)
        """The state machine that decides what to answer."""
        self.connection_error: ConnectionLost | None = None
        """Why the background serve loop ended, when it ended because the line failed."""
        self._handlers: dict[int, Handler] = dict(BUILTIN_HANDLERS)
        for function_code, handler in (handlers or {}).items():
            self.set_handler(function_code, handler)
        self.trace = trace
        """The trace callback, or ``None``."""
        self._routed: dict[int, RoutedStore] = {}
        self._before: list[BeforeHook] = []
        self._after: list[AfterHook] = []
        self._contexts: dict[int, RequestContext] = {}
        self._broadcast_contexts: list[RequestContext] = []
        self._fast_stores: dict[int, MemoryStore] = {}
        self._fast_paths: dict[int, FastPath] = {}
        self._build_contexts()
        self._build_fast_paths()
        self._task_group: anyio.abc.TaskGroup | None = None
        self._stopped = anyio.Event()
        self._served = frozenset((BROADCAST_UNIT, *self.units))
        self._queue: deque[LinkEvent | _Taken] = deque()
        self._wake: anyio.Event | None = None
        self._waiter: Any = None
        """The event loop future the serve loop waits on, where the link has a loop."""
        self._link_closed = False

    # -- handlers --------------------------------------------------------------------

    def set_handler(self, function_code: int, handler: Handler | None) -> None:
        """Serve *function_code* with *handler*; ``None`` removes it (the code then gets 01).

        The handler is called as ``handler(request, context)`` with the decoded request
        (a :class:`~aiortu.core.pdu.RawPDU` for codes without a class) and a
        :class:`~aiortu.slave._handlers.RequestContext`; it returns the response PDU, or
        ``None`` to send nothing, and may be a coroutine function.
        """
        if function_code not in _FUNCTION_CODE_RANGE:
            raise InvalidValue("function_code", function_code, _FUNCTION_CODE_RANGE)
        if handler is None:
            self._handlers.pop(function_code, None)
        else:
            self._handlers[function_code] = handler
        self._build_fast_paths()

    def handler(self, function_code: int) -> Callable[[Handler], Handler]:
        """Decorator form of :meth:`set_handler`."""

        def register(handler: Handler) -> Handler:
            self.set_handler(function_code, handler)
            return handler

        return register

    def route(
        self,
        table: Table | str,
        addresses: range,
        handler: RangeHandler,
        *,
        units: Iterable[int] | None = None,
    ) -> None:
        """Serve *addresses* of *table* with *handler* on *units* (default: every unit).

        See :mod:`aiortu.slave._routes`. A later route wins where routes overlap.
        """
        table = Table(table)
        for unit in self.units if units is None else units:
            if unit not in self.units:
                raise InvalidValue("unit", unit, sorted(self.units))
            routed = self._routed.get(unit)
            if routed is None:
                routed = self._routed[unit] = RoutedStore(self.units[unit], unit)
            routed.add(table, addresses, handler)
        self._build_contexts()

    def before_request(self, hook: BeforeHook) -> Callable[[], None]:
        """Call *hook* before each request's handler (see :data:`BeforeHook`).

        Returns a function that removes the hook.
        """
        self._before.append(hook)
        return lambda: self._before.remove(hook) if hook in self._before else None

    def after_request(self, hook: AfterHook) -> Callable[[], None]:
        """Call *hook* after each request's handler (see :data:`AfterHook`).

        Returns a function that removes the hook.
        """
        self._after.append(hook)
        return lambda: self._after.remove(hook) if hook in self._after else None

    def _build_contexts(self) -> None:
        machine = self.machine
        stores: dict[int, DataStore | AsyncDataStore] = {
            unit: self._routed.get(unit, store) for unit, store in self.units.items()
        }
        self._contexts = {
            unit: RequestContext(unit, store, machine=machine) for unit, store in stores.items()
        }
        # The built-in MemoryStore (not a subclass, not routed) takes the fast paths.
        self._fast_stores = {
            unit: store for unit, store in stores.items() if type(store) is MemoryStore
        }
        # A broadcast runs once per store: units that share one store run it once.
        seen: set[int] = set()
        self._broadcast_contexts = []
        for unit, store in stores.items():
            if id(self.units[unit]) not in seen:
                seen.add(id(self.units[unit]))
                self._broadcast_contexts.append(
                    RequestContext(unit, store, broadcast=True, machine=machine)
                )

    def _build_fast_paths(self) -> None:
        # A fast path stands in for a built-in handler only while that handler serves
        # its function code (hooks are checked per request).
        handlers = self._handlers
        self._fast_paths = {
            code: fast
            for code, (handler, fast) in FAST_PATHS.items()
            if handlers.get(code) is handler
        }

    @property
    def function_codes(self) -> frozenset[int]:
        """The function codes this slave serves."""
        return frozenset(self._handlers)

    # -- lifetime --------------------------------------------------------------------

    @property
    def listen_only(self) -> bool:
        """In listen-only mode requests are monitored only: not executed, not answered."""
        return self.machine.listen_only

    @listen_only.setter
    def listen_only(self, value: bool) -> None:
        self.machine.listen_only = value

    async def serve(self) -> None:
        """Serve until cancelled.

        Raises :class:`~aiortu.errors.ConnectionLost` when the line fails or closes.
        """
        lost: ConnectionLost | None = None
        async with self.link:
            try:
                await self._serve_frames()
            except ConnectionLost as error:
                # Raised outside the link's task group, so that it is not wrapped in an
                # ExceptionGroup on the way out.
                lost = error
        if lost is not None:
            # A link that closed because this task is being cancelled is the
            # cancellation, not a lost line.
            await anyio.lowlevel.checkpoint_if_cancelled()
            raise lost

    async def __aenter__(self) -> Self:
        self._task_group = anyio.create_task_group()
        await self._task_group.__aenter__()
        self._task_group.start_soon(self._serve_in_background, name="aiortu slave")
        return self

    async def __aexit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        traceback: TracebackType | None,
    ) -> bool | None:
        assert self._task_group is not None
        self._task_group.cancel_scope.cancel()
        # The body's own exception propagates as it is, not wrapped in an ExceptionGroup.
        await self._task_group.__aexit__(None, None, None)
        return None

    async def wait_stopped(self) -> None:
        """Wait until the background serve loop has ended (the line failed or closed)."""
        await self._stopped.wait()

    async def _serve_in_background(self) -> None:
        try:
            await self.serve()
        except ConnectionLost as error:
            self.connection_error = error
        finally:
            self._stopped.set()

    # -- the serve loop --------------------------------------------------------------

    async def _serve_frames(self) -> None:
        """Take the link's events and answer the requests, until the link closes.

        The link hands its events to :meth:`_on_link_event` in its reader task. Discards
        and frames for other units are dealt with there at once when nothing is pending
        (they only count), so they never wake this task; a frame for one of our units is
        queued, and this task answers it. It drains the queue before it waits again, so a
        flood of events costs one wake-up per batch, not one per event.
        """
        link = self.link
        backend = link.backend
        queue = self._queue
        queue.clear()
        self._link_closed = False
        try:
            while (early := link.receive_nowait()) is not None:  # queued before we listened
                queue.append(early)
        except ConnectionLost:
            self._link_closed = True
        link.listen(self._on_link_event)
        link.expect_requests(_EIGHT_BYTE_FAST_PATHS, 8, self._on_whole_request)
        try:
            while True:
                if not queue:
                    if self._link_closed:
                        raise link.connection_lost_error()
                    if link.loop is not None:
                        # The link's stream pushes its bytes on this event loop: one of
                        # its futures is the cheapest wait.
                        waiter = self._waiter = link.loop.create_future()
                        await waiter
                        continue
                    wake = self._wake = anyio.Event() if backend is None else backend.create_event()
                    await wake.wait()
                    continue
                event = queue.popleft()
                if type(event) is FrameReceived:
                    if self._take_frame(event):
                        await self._serve_request(event.frame)
                elif type(event) is _Taken:
                    if event.reply is None:
                        await self._serve_request(event.frame)
                    else:
                        await self._send_reply(event.frame[0], event.reply)
                else:
                    self._take_discard(event)  # type: ignore[arg-type]
        finally:
            self._wake = self._waiter = None
            link.expect_requests((), 8, None)
            link.listen(None)

    def _on_link_event(self, event: LinkEvent | None) -> None:
        """The link's listener (in its reader task): count at once, or queue for the serve loop."""
        queue = self._queue
        if event is None:
            self._link_closed = True
        elif not queue and self.machine.state is SlaveState.IDLE:
            # Nothing pending and no request under way: a discard, or a frame for another
            # unit, only counts, and a request the store answers at once is answered
            # here, with no task wake-up; only the rest wakes the serve loop.
            if type(event) is not FrameReceived:
                self._take_discard(event)
                return
            if event.frame[0] not in self._served:
                self._take_frame(event)
                return
            self._answer_at_once(event)
            return
        else:
            if len(queue) >= self.link.queue_size:
                # A reader that falls behind never stalls the line; a request already
                # taken (only ever first in the queue) is never dropped: it is under way.
                drop = 1 if type(queue[0]) is _Taken else 0
                if drop < len(queue):
                    del queue[drop]
                    self.link.events_dropped += 1
            queue.append(event)
        self._wake_serve_loop()

    def _wake_serve_loop(self) -> None:
        waiter = self._waiter
        if waiter is not None:
            self._waiter = None
            if not waiter.done():
                waiter.set_result(None)
        wake = self._wake
        if wake is not None:
            self._wake = None
            wake.set()

    def _leave(self, taken: _Taken) -> None:
        """The serve loop finishes *taken*, in order."""
        self._queue.append(taken)
        self._wake_serve_loop()

    def _on_whole_request(self, frame: bytes, end: float) -> None:
        """The link's read callback got *frame*, a whole 8-byte request with a good CRC
        (see Link.expect_requests): answer it here when a fast path does, counted in one
        step when the reply goes out at once (SlaveMachine.answered_at_once); otherwise
        it is the FrameReceived the receiver would have made, and goes the usual way."""
        machine = self.machine
        answer = None
        if (
            not self._queue
            and self.trace is None
            and machine.state is SlaveState.IDLE
            and not machine.listen_only
        ):
            answer = self._fast_answer(frame)
        if answer is None:
            start = end - (len(frame) - 1) * self.link.char_time
            self._on_link_event(FrameReceived(frame, start, end))
            return
        # Counted step by step unless a normal reply goes out at once.
        if isinstance(answer, bytes):
            if self.link.send_now(encode_frame(frame[0], answer)) is not None:
                machine.answered_at_once(frame[0], frame[1])
                return
            machine.frame_received(frame[0], frame[1])
            self._count_fast(answer)
            self._leave(_Taken(frame, answer))  # the serve loop sends it after the gap
            return
        machine.frame_received(frame[0], frame[1])
        self._count_fast(answer)
        self._reply_at_once(frame, _exception_pdu(frame[1], answer))

    def _reply_at_once(self, frame: bytes, reply: bytes) -> None:
        """Send *reply*, the PDU answering *frame*, now if the line allows it, else leave
        it to the serve loop (the machine is FORMATTING_REPLY or FORMATTING_ERROR)."""
        out = encode_frame(frame[0], reply)
        if self.link.send_now(out) is None:
            self._leave(_Taken(frame, reply))
            return
        trace = self.trace
        if trace is not None:
            trace("sent", out)
        self.machine.reply_sent()

    def _take_discard(self, event: LinkEvent) -> None:
        trace = self.trace
        if trace is not None:
            trace("discarded", event.data)  # type: ignore[union-attr]
        reason = event.reason  # type: ignore[union-attr]
        if reason is DiscardReason.CRC:
            self.machine.frame_corrupt()
        elif reason is DiscardReason.OVERFLOW:
            self.machine.character_overrun()

    def _take_frame(self, event: FrameReceived) -> bool:
        """Count a frame; tell whether it is a request for this slave to serve."""
        frame = event.frame
        trace = self.trace
        if trace is not None:
            trace("received", frame)
        machine = self.machine
        if not machine.frame_received(frame[0], frame[1]):
            return False
        if machine.listen_only and frame[1:4] != _RESTART_COMMUNICATIONS:
            machine.ignore()
            return False
        return True

    def _answer_at_once(self, event: FrameReceived) -> None:
        """Serve a request for one of our units from the link's read callback, as far as
        that goes without a wait, and leave the rest to the serve loop.

        The request is counted (the machine is CHECKING). Without hooks, a built-in
        MemoryStore answers the common reads and writes at once (the fast paths); the
        reply then goes out at once too when the line allows it (frame gap 0, or already
        kept). Whatever needs a wait is left to the serve loop, in order.
        """
        frame = event.frame
        if not self._take_frame(event):
            return
        reply = self._fast_reply(frame)
        if reply is None:
            self._leave(_Taken(frame, None))
        elif self.machine.should_reply:
            self._reply_at_once(frame, reply)
        else:
            self.machine.no_reply()

    def _fast_answer(self, frame: bytes) -> bytes | int | None:
        """What a fast path (see slave_handlers) answers to *frame*: the reply PDU, or the
        exception code it raised (before changing anything); None where none applies
        (hooks, another store, or a request it leaves to the handler). Counts nothing."""
        fast = self._fast_paths.get(frame[1])
        if fast is None or self._before or self._after:
            return None
        store = self._fast_stores.get(frame[0])
        if store is None:
            return None
        try:
            return fast(store, frame[1:-2])
        except ExceptionResponse as error:
            return error.code

    def _count_fast(self, answer: bytes | int) -> None:
        """Count a fast path's *answer* (the machine is CHECKING)."""
        self.machine.check_request(supported=True)
        if isinstance(answer, bytes):
            self.machine.processed()
        else:
            self.machine.processing_failed(answer)

    def _fast_reply(self, frame: bytes) -> bytes | None:
        """The reply PDU from a fast path, counted by the machine; None where none
        applies (see _fast_answer)."""
        answer = self._fast_answer(frame)
        if answer is None:
            return None
        self._count_fast(answer)
        return answer if isinstance(answer, bytes) else _exception_pdu(frame[1], answer)

    async def _serve_request(self, frame: bytes) -> None:
        """Answer a request for one of our units (counted by the machine, now CHECKING)."""
        unit = frame[0]
        reply: bytes | Reply | None = self._fast_reply(frame)
        if reply is None:
            reply = await self._answer(unit, frame[1:-2])
        await self._send_reply(unit, reply)

    async def _send_reply(self, unit: int, reply: bytes | Reply | None) -> None:
        """Send *reply* (a PDU or a Reply) for *unit*, unless there is none to send."""
        machine = self.machine
        if reply is not None and machine.should_reply:
            if type(reply) is bytes:
                out = encode_frame(unit, reply)
            else:
                assert isinstance(reply, Reply)
                assert reply.response is not None
                if reply.delay > 0:
                    await anyio.sleep(reply.delay)
                answer_unit = unit if reply.unit is None else reply.unit
                out = encode_frame(answer_unit, reply.response.encode())
            await self.link.send(out)
            trace = self.trace
            if trace is not None:
                trace("sent", out)
            machine.reply_sent()
        else:
            machine.no_reply()

    async def _answer(self, unit: int, pdu: bytes) -> bytes | Reply | None:
        """Check and execute one request; return the reply PDU (or a Reply), or None."""
        machine = self.machine
        function_code = pdu[0]
        handler = self._handlers.get(function_code)
        request: Request | None = None
        violation: int | None = None
        if handler is not None:
            try:
                request = decode_request(pdu)
            except MalformedPDU as error:
                violation = error.exception_code
        if not machine.check_request(supported=handler is not None, violation=violation):
            return _exception_pdu(function_code, machine.exception_code)
        assert handler is not None
        try:
            if machine.broadcast:
                for context in self._broadcast_contexts:
                    await self._run(handler, request, context)
                result: HandlerResult = None
            else:
                result = await self._run(handler, request, self._contexts[unit])
        except ExceptionResponse as error:
            machine.processing_failed(error.code)
            return _exception_pdu(function_code, error.code)
        except Exception:
            _log.exception("unit %d: the handler of function 0x%02X failed", unit, function_code)
            machine.processing_failed(ExceptionCode.SERVER_DEVICE_FAILURE)
            return _exception_pdu(function_code, ExceptionCode.SERVER_DEVICE_FAILURE)
        machine.processed()
        if result is None:
            return None
        if isinstance(result, Reply):
            return None if result.response is None else result
        return result.encode()

    async def _run(
        self, handler: Handler, request: Request | None, context: RequestContext
    ) -> HandlerResult:
        """The handler's answer, with the hooks around it."""
        if not (self._before or self._after):
            return await _call(handler, request, context)
        for before in tuple(self._before):
            early = before(request, context)
            if inspect.isawaitable(early):
                early = await early
            if early is not None:
                return early
        result = await _call(handler, request, context)
        for after in tuple(self._after):
            replaced = after(request, context, result)
            if inspect.isawaitable(replaced):
                replaced = await replaced
            if replaced is not None:
                result = replaced
        return result


async def _call(
    handler: Handler, request: Request | None, context: RequestContext
) -> HandlerResult:
    result = handler(request, context)
    if inspect.isawaitable(result):
        awaited: HandlerResult = await result
        return awaited
    return result


_RESTART_COMMUNICATIONS = bytes((0x08, 0x00, 0x01))
"""Diagnostics, restart communications: the one request served in listen-only mode."""


_EIGHT_BYTE_FAST_PATHS: Final = frozenset(FAST_PATHS) & frozenset(range(0x01, 0x07))
"""Fast paths whose requests are always 8 bytes: 01 to 06."""


def _exception_pdu(function_code: int, exception_code: int | None) -> bytes:
    # Raw bytes, not ExceptionPDU: a request with code 0 must still get its 01 answer.
    code = ExceptionCode.SERVER_DEVICE_FAILURE if exception_code is None else exception_code
    return bytes((function_code | EXCEPTION_BIT, code & 0xFF))


@asynccontextmanager
async def serve(
    port_or_url: str,
    units: Mapping[int, DataStore | AsyncDataStore],
    *,
    baudrate: int = 19200,
    parity: str = "E",
    stopbits: float = 1,
    bytesize: int = 8,
    frame_gap: float | None = None,
    timing: TimingMode | str = TimingMode.TOLERANT,
    handlers: Mapping[int, Handler] | None = None,
    trace: TraceCallback | None = None,
    **options: Any,
) -> AsyncIterator[Slave]:
    """Open *port_or_url* and serve *units* on it for the duration of the ``async with``.

    *port_or_url* is a serial device path or ``rtu+tcp://host:port``; the line settings
    are the spec's 19200 8E1 by default; *options* go to
    :func:`aiortu.transport.open_stream` (``exclusive``, ``rs485``, ``local_echo``,
    ``connect_timeout``). Yields the running :class:`Slave`. Raises the transport's
    :class:`~aiortu.errors.PortError` subclasses when the port cannot be opened.
    """
    settings = LineSettings(baudrate, bytesize, parity, stopbits)
    stream = await open_stream(port_or_url, settings, **options)
    try:
        slave = Slave(
            stream,
            units,
            settings,
            frame_gap=frame_gap,
            timing=timing,
            handlers=handlers,
            trace=trace,
        )
    except BaseException:
        await stream.aclose()
        raise
    async with slave:
        yield slave

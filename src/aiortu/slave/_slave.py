"""The slave: serves one or many unit addresses on one line from data stores.

[`Slave`][aiortu.slave.Slave] takes any byte stream (a serial port, a TCP connection to a serial
device server, a virtual line) and a mapping of unit addresses to data stores:

    store = aiortu.MemoryStore(holding_registers={0x6B: 3})
    async with aiortu.Slave(stream, {17: store}):
        ...                                   # the slave serves in the background

or `await slave.serve()` to serve in the current task. [`serve`][aiortu.slave.serve] opens a port or
a URL first, or listens on one: `tcp://` for Modbus TCP
([`ModbusTcpServer`][aiortu.slave.ModbusTcpServer]), `rtu+tcp://` for RTU framing over TCP
([`RtuOverTcpServer`][aiortu.slave.RtuOverTcpServer], a [`Slave`][aiortu.slave.Slave] per
connection). One line may carry a whole bus of simulated units. The general route of a request
(checks, handler, hooks) is `Dispatcher`, shared with the Modbus TCP server.

Each frame goes through the core's [`SlaveMachine`][aiortu.core.machines.SlaveMachine], which
decides what the spec says: frames for other units are dropped and counted, frames with a bad CRC
never reach it (the link discards and counts them), broadcasts are executed by every unit and never
answered, and exceptions come in the spec's order (01, 03, 02, 04). A request is dispatched by
function code to a handler (see [`aiortu.slave`][aiortu.slave]); users register their own with
[`Slave.set_handler`][aiortu.slave.Slave.set_handler], including for the user-defined codes 65-72
and 100-110, which arrive as [`RawPDU`][aiortu.core.pdu.RawPDU]. A handler that raises
[`ExceptionResponse`][aiortu.errors.ExceptionResponse] answers with its code; any other error
answers 04, is logged, and the slave goes on serving. What a handler or hook returns is checked
here: a response, an [`ExceptionPDU`][aiortu.core.pdu.ExceptionPDU], a valid
[`Reply`][aiortu.slave.Reply] or `None`; anything else answers 04 and is logged once for that
handler or hook. The reply goes out after `frame_gap` of silence on the line (t3.5 by default; the
link keeps it).

That is the general route, through the serve loop. The commonest requests may instead be
answered at once where they arrive, without a task wake-up: every condition for that is
in `may_answer`.

Beyond function codes: [`Slave.route`][aiortu.slave.Slave.route] serves an address range of one
table with a function (see [`aiortu.slave`][aiortu.slave]);
[`Slave.before_request`][aiortu.slave.Slave.before_request] and
[`Slave.after_request`][aiortu.slave.Slave.after_request] add hooks around every request; a handler
or hook that returns a [`Reply`][aiortu.slave.Reply] answers late, as another unit, or not at all,
to test masters. `trace` sees every frame received and sent; a trace callback that raises is logged
and detached.
"""

from __future__ import annotations

from collections import deque
from collections.abc import Callable, Mapping
from types import TracebackType
from typing import Self

import anyio
import anyio.abc
import anyio.lowlevel

from aiortu._log import get_logger
from aiortu.core.codes import BROADCAST_UNIT
from aiortu.core.machines import SerialLineCounters, SlaveMachine, SlaveState
from aiortu.core.model import AsyncDataStore, DataStore
from aiortu.core.rtu import DiscardReason, FrameReceived, Role, TimingMode, encode_frame
from aiortu.core.serial import LineSettings
from aiortu.errors import ConnectionLost, InvalidValue
from aiortu.line import Link, LinkEvent, Waiter
from aiortu.slave._answer_at_once import LineAnswerAtOnce, Taken
from aiortu.slave._dispatch import RESTART_COMMUNICATIONS, AfterHook, BeforeHook, Dispatcher
from aiortu.slave._handlers import BUILTIN_HANDLERS, Handler, Reply
from aiortu.transport import AsciiStream

__all__ = ("AfterHook", "BeforeHook", "Slave", "TraceCallback")

_log = get_logger(__name__)

TraceCallback = Callable[[str, bytes], object]
"""Sees the line: `("received", frame)` for every frame whose CRC checks (for any
unit), `("sent", frame)` for every reply, `("discarded", data)` for bytes dropped."""

_UNIT_RANGE = range(1, 248)


class Slave(Dispatcher):
    """A Modbus RTU slave on one line (see the module docstring).

    `units` maps each unit address (1..247) to its data store. `settings` are the line settings;
    `frame_gap` is the silence kept before each reply (`None` for t3.5 of the settings, 0 for lines
    without a wire such as TCP). `timing` and `frame_silence` configure the receiver (see
    [`aiortu.core.rtu`][aiortu.core.rtu]). `handlers` adds or replaces handlers by
    function code, as [`set_handler`][aiortu.slave.Slave.set_handler] does. `clock` is the link's
    clock. `trace` sees every frame (see [`TraceCallback`][aiortu.slave.TraceCallback]).

    Raises [`InvalidValue`][aiortu.errors.InvalidValue] for a unit address outside 1..247 or a
    function code outside 1..127.
    """

    _at_once: LineAnswerAtOnce

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
        stores: dict[int, DataStore | AsyncDataStore] = dict(units)
        if isinstance(stream, AsciiStream):
            stream.answering = True  # 08/03 changes this end's input delimiter
        self.link = Link(
            stream,
            settings,
            role=Role.SLAVE,
            units=stores,
            timing=timing,
            frame_silence=frame_silence,
            frame_gap=frame_gap,
            clock=clock,
        )
        """The line this slave serves (its counters say what the receiver discarded)."""
        self.counters = SerialLineCounters()
        """The spec's diagnostic counters of this line."""
        self._init_dispatch(stores, SlaveMachine(stores, self.counters), BUILTIN_HANDLERS)
        self.connection_error: ConnectionLost | None = None
        """Why the background serve loop ended, when it ended because the line failed."""
        self._queue: deque[LinkEvent | Taken] = deque()
        self._at_once = LineAnswerAtOnce(
            self.machine,
            self.link,
            self._queue,
            before=self._before,
            after=self._after,
            serve_later=self._leave,
            to_listener=self._unanswered,
        )
        self._trace: TraceCallback | None = None
        self.trace = trace
        self._build_contexts()
        for function_code, handler in (handlers or {}).items():
            self.set_handler(function_code, handler)
        self._task_group: anyio.abc.TaskGroup | None = None
        self._stopped = anyio.Event()
        self._served = frozenset((BROADCAST_UNIT, *self.units))
        self._waiter: Waiter | None = None
        """What the serve loop waits on while its queue is empty."""
        self._link_closed = False

    @property
    def trace(self) -> TraceCallback | None:
        """The trace callback, or `None` (see [`TraceCallback`][aiortu.slave.TraceCallback]). One
        that raises is logged and detached."""
        return self._trace

    @trace.setter
    def trace(self, callback: TraceCallback | None) -> None:
        self._trace = callback
        self._at_once.trace_set = callback is not None

    def _traced(self, kind: str, data: bytes) -> None:
        """Show `data` to the trace callback; one that raises is logged and detached."""
        trace = self._trace
        if trace is None:
            return
        try:
            trace(kind, data)
        except Exception:
            _log.exception("the trace callback failed; it is detached")
            self.trace = None

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

        Raises [`ConnectionLost`][aiortu.errors.ConnectionLost] when the line fails or closes.
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

        The link hands its events to `_on_link_event` (from its reader task, or
        its read callback). Discards and frames for other units are dealt with there at
        once when nothing is pending (they only count), and a request may be answered
        there at once (see [`aiortu.slave`][aiortu.slave]), so they never wake this
        task; any other request for one of our units is queued, and this task answers it
        through the machine, the handler and the hooks. It drains the queue before it
        waits again, so a flood of events costs one wake-up per batch, not one per event.
        """
        link = self.link
        assert link.waits is not None  # the link is open
        new_waiter = link.waits.waiter
        queue = self._queue
        queue.clear()
        self._link_closed = False
        try:
            while (early := link.receive_nowait()) is not None:  # queued before we listened
                queue.append(early)
        except ConnectionLost:
            self._link_closed = True
        link.listen(self._on_link_event)
        self._at_once.attach()
        try:
            while True:
                if not queue:
                    if self._link_closed:
                        raise link.connection_lost_error()
                    # The backend's cheapest wake-up (an event loop future under asyncio).
                    waiter = self._waiter = new_waiter()
                    await waiter
                    continue
                event = queue.popleft()
                if type(event) is FrameReceived:
                    if self._take_frame(event):
                        await self._serve_request(event.frame)
                elif type(event) is Taken:
                    await self._send_reply(event.frame[0], event.reply)
                else:
                    self._take_discard(event)  # type: ignore[arg-type]
        finally:
            self._waiter = None
            self._at_once.detach()
            link.listen(None)

    def _on_link_event(self, event: LinkEvent | None) -> None:
        """The link's listener: count at once, answer at once, or queue for the serve loop."""
        if event is None:
            self._link_closed = True
            self._wake_serve_loop()
        elif not (
            # A request for us: answered at once where the shortcut's predicate allows it
            # (`AnswerAtOnce.may_answer` holds every condition: the order of requests,
            # the machine's state...), else left to the serve loop.
            type(event) is FrameReceived
            and event.frame[0] in self._served
            and self._at_once.answer_frame(event.frame)
        ):
            self._unanswered(event)

    def _unanswered(self, event: LinkEvent) -> None:
        """Queue `event`, not answered at once, for the serve loop; or only count it."""
        if type(event) is FrameReceived and event.frame[0] in self._served:
            self._queue_event(event)
        elif not self._queue and self.machine.state is SlaveState.IDLE:
            # Nothing pending and no request under way: a discard, or a frame for another
            # unit, only counts; it never wakes the serve loop.
            if type(event) is FrameReceived:
                self._take_frame(event)
            else:
                self._take_discard(event)
        else:
            self._queue_event(event)

    def _queue_event(self, event: LinkEvent) -> None:
        """Queue `event` for the serve loop, and wake it."""
        queue = self._queue
        if len(queue) >= self.link.queue_size:
            # A reader that falls behind never stalls the line; a request already
            # answered (only ever first in the queue) is never dropped: it is counted.
            drop = 1 if type(queue[0]) is Taken else 0
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

    def _leave(self, taken: Taken) -> None:
        """The serve loop sends `taken`'s reply, in order."""
        self._queue.append(taken)
        self._wake_serve_loop()

    def _take_discard(self, event: LinkEvent) -> None:
        self._traced("discarded", event.data)  # type: ignore[union-attr]
        reason = event.reason  # type: ignore[union-attr]
        if reason is DiscardReason.CRC:
            self.machine.frame_corrupt()
        elif reason is DiscardReason.OVERFLOW:
            self.machine.character_overrun()

    def _take_frame(self, event: FrameReceived) -> bool:
        """Count a frame; tell whether it is a request for this slave to serve."""
        frame = event.frame
        self._traced("received", frame)
        machine = self.machine
        if not machine.frame_received(frame[0], frame[1]):
            return False
        if machine.listen_only and frame[1:4] != RESTART_COMMUNICATIONS:
            machine.ignore()
            return False
        return True

    async def _serve_request(self, frame: bytes) -> None:
        """Answer a request for one of our units (counted by the machine, now CHECKING)."""
        unit = frame[0]
        await self._send_reply(unit, await self._answer(unit, frame[1:-2]))

    async def _send_reply(self, unit: int, reply: bytes | Reply | None) -> None:
        """Send `reply` (a PDU or a Reply) for `unit`, unless there is none to send."""
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
            self._traced("sent", out)
            machine.reply_sent()
        else:
            machine.no_reply()

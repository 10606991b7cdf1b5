"""One serial line: a byte stream pumped through the receiver with a clock.

A :class:`Link` owns a byte stream (a serial port, a TCP connection to a serial device
server, a virtual line). It timestamps every chunk with the link's clock, runs the
sans-IO :class:`~aiortu.core.receiver.Receiver`, wakes it at its deadlines, and queues
what it yields: frames, and the bytes it discarded with the reason.

Two ways in. A stream that pushes its bytes (a :class:`~aiortu.transport.PushStream`,
as the serial port's :class:`~aiortu.transport.SerialStream` is), on an event loop with
``call_at`` timers (asyncio), hands each chunk to the link from the loop's read callback,
and the receiver's silence deadline is one event loop timer, armed and cancelled by the
link; the reader task then only waits for the stream's end, so a chunk costs no task
wake-up. Any other byte stream (virtual
lines, TCP, file descriptors), and any stream under trio, is read by the reader task, with
the deadline as a cancel scope around ``receive()``.

:meth:`Link.send` keeps the spec's silence: it first waits until the line has been quiet,
in both directions, for ``frame_gap`` (t3.5 of the line settings by default; 0 is allowed
for virtual lines and TCP, where there is no wire to keep quiet), then writes the frame
and returns when, by the clock, its last byte will have left the wire. The master starts
its response timeout from that time, not from when ``write()`` returned. Under asyncio
on Linux the wait ends on a :class:`~aiortu.line._wake_timer.WakeTimer`, at the time itself
rather than on the loop's next whole millisecond. :meth:`Link.send_now` sends without a
wait or a yield when the line allows it (a push stream's ``send_nowait``, the gap kept):
a slave answers from the read callback that way.

On the push path a master can also tell the link the exact shape of the reply it waits
for (:meth:`Link.expect`: its first bytes and length); a chunk that is exactly that frame
with a good CRC goes straight to the master, with no event built or queued. Anything
else, a split or garbled reply included, takes the usual way through the receiver.

The master and the slave are built on this; users rarely need it directly, except to
watch a line (``role=Role.MONITOR``).

Events go to a queue that :meth:`Link.receive` reads, or, while a listener is set
(:meth:`Link.listen`), straight to that listener from the reader: the master's
line engine listens, so that a reply reaches the waiting transaction with no task hop in
between. The hot path avoids work that does nothing: the default clock is bound to the
running event loop's clock when the link opens, and :meth:`Link.send` yields to the loop
only when it has to wait (for the silence, for another sender, or for the stream).
"""

from __future__ import annotations

import contextlib
import math
import sys
import time
from collections import Counter
from collections.abc import Callable, Container, Iterable
from types import TracebackType
from typing import Any, Self, cast

import anyio
import anyio.abc
import anyio.lowlevel
from anyio.streams.memory import MemoryObjectReceiveStream, MemoryObjectSendStream

from aiortu.core.receiver import (
    DiscardReason,
    FrameDiscarded,
    FrameReceived,
    Receiver,
    Role,
    TimingMode,
)
from aiortu.core.timing import LineSettings
from aiortu.errors import ConnectionLost
from aiortu.line._wake_timer import WakeTimer, create_wake_timer
from aiortu.transport import PushStream

__all__ = ("Link", "LinkEvent", "LinkListener")

LinkEvent = FrameReceived | FrameDiscarded
"""What a link delivers: a frame whose CRC checks, or bytes discarded with a reason."""

LinkListener = Callable[[LinkEvent | None], None]
"""Called by the reader with each event, and with ``None`` once the reader stops."""

_STREAM_ERRORS = (
    anyio.EndOfStream,
    anyio.BrokenResourceError,
    anyio.ClosedResourceError,
    OSError,
)


def _loop_clock(token: anyio.lowlevel.EventLoopToken) -> Callable[[], float]:
    """The running backend's clock, as cheap to read as it gets: :func:`time.monotonic`
    under asyncio's own event loops (which tell that time), else the event loop's own
    ``time`` method where the loop has one that tells the backend's time, else the
    backend's ``current_time``."""
    backend_time = token.backend_class.current_time
    native = token.native_token
    loop_time = getattr(native, "time", None)
    base_loop = getattr(sys.modules.get("asyncio"), "BaseEventLoop", None)
    if base_loop is not None and getattr(type(native), "time", None) is base_loop.time:
        # asyncio's own loops tell time.monotonic(): read it without the method call.
        return time.monotonic
    if callable(loop_time):
        with contextlib.suppress(Exception):
            if abs(float(loop_time()) - backend_time()) < 0.1:
                return cast(Callable[[], float], loop_time)
    return backend_time


class Link:
    """One serial line (see the module docstring). Use it as an async context manager.

    *settings* are the line settings (timing for the receiver and the frame gap).
    *role*, *units*, *timing* and *frame_silence* configure the receiver.
    *frame_gap* is the silence kept before each transmission: ``None`` for t3.5 of the
    settings. *clock* returns seconds (default :func:`anyio.current_time`, which the link
    replaces, when it opens, with the running backend's own clock: the same time, read
    without looking the backend up on every call).
    *queue_size* bounds the events waiting to be received; when it is full the oldest
    event is dropped and counted, so a reader that falls behind never stalls the line.
    """

    def __init__(
        self,
        stream: anyio.abc.ByteStream,
        settings: LineSettings | None = None,
        *,
        role: Role = Role.MASTER,
        units: Iterable[int] = (),
        timing: TimingMode | str = TimingMode.TOLERANT,
        frame_silence: float | None = None,
        frame_gap: float | None = None,
        clock: Callable[[], float] = anyio.current_time,
        queue_size: int = 64,
    ) -> None:
        self.stream = stream
        self.settings = settings if settings is not None else LineSettings()
        self.char_time = self.settings.char_time
        """Seconds one character takes on the wire, from :attr:`settings`."""
        self.frame_gap = self.settings.t3_5 if frame_gap is None else frame_gap
        if self.frame_gap < 0 or math.isnan(self.frame_gap):
            raise ValueError(f"frame_gap must be >= 0 seconds, not {frame_gap}")
        self.clock = clock
        self.wire_timed: bool = getattr(stream, "wire_timed", False) is True
        """Whether the wire times the link computes from :attr:`settings` are real: a
        frame sent cannot have left the wire sooner, so no reply can begin sooner. True
        where the stream says so (a serial port that is not a pseudo-terminal, a paced
        virtual line); false on TCP, unpaced virtual lines and ptys, which deliver at once.
        The master may set it (``Master(wire_timed=...)``)."""
        self.receiver = Receiver(
            self.settings, role=role, units=units, timing=timing, frame_silence=frame_silence
        )
        self.queue_size = queue_size
        """The most events kept waiting to be received (by a listener too)."""
        self._send_events: MemoryObjectSendStream[LinkEvent]
        self._receive_events: MemoryObjectReceiveStream[LinkEvent]
        self._send_events, self._receive_events = anyio.create_memory_object_stream[LinkEvent](
            queue_size
        )
        self._task_group: anyio.abc.TaskGroup | None = None
        self._listener: LinkListener | None = None
        self._sending = False
        self._send_waiters: list[anyio.Event] = []
        self.backend: type[anyio.abc.AsyncBackend] | None = None
        """The async backend the link runs on (set when it opens): its events, cancel
        scopes and clock cost no backend lookup."""
        self.backend_clock = False
        """Whether :attr:`clock` is the backend's own clock, so that its times can be
        used as cancel scope deadlines as they are."""
        self.writes_begun = 0
        """Writes :meth:`send` has begun: a caller cancelled inside :meth:`send` can tell
        whether its frame may have gone out."""
        self.last_write_start = -math.inf
        """When the last write began, in the link's clock."""
        self._last_received = -math.inf
        self._transmit_end = -math.inf
        self._error: BaseException | None = None
        self._closed = anyio.Event()
        self._stopped = False
        self.loop: Any = None
        """The event loop, where the link reads a stream that pushes its bytes (see
        :meth:`_push`); ``None`` otherwise. Its futures and :meth:`call_at` timers are the
        cheapest way to wait for the link there."""
        # Checked once here (an isinstance against a runtime protocol takes microseconds):
        # the chunk and send paths use the bound methods kept.
        self._set_receiver: Callable[..., None] | None = None
        """A push stream's ``set_receiver``, used where the event loop has ``call_at``."""
        self._send_nowait: Callable[[bytes], bool] | None = None
        """A push stream's write without a yield (the serial port's), tried before ``send``."""
        if isinstance(stream, PushStream):
            self._set_receiver = stream.set_receiver
            self._send_nowait = stream.send_nowait
        self._timer: Any = None
        self._timer_deadline = -math.inf
        self._expected: tuple[bytes, int, Callable[[bytes, float], None], bytes | None] | None = (
            None
        )
        self._requests: tuple[Container[int], int, Callable[[bytes, float], None]] | None = None
        self._push_lost: anyio.Event | None = None
        self._push_error: BaseException | None = None
        self.frames_received = 0
        self.frames_sent = 0
        self.discarded: Counter[DiscardReason] = Counter()
        self.events_dropped = 0
        self._silence_timer: WakeTimer | None = None
        self._silence_timer_tried = False
        self._silence_loop: Any = None
        self._silence_waiters: list[Any] = []

    # -- lifetime --------------------------------------------------------------------

    async def __aenter__(self) -> Self:
        token = anyio.lowlevel.current_token()
        backend = self.backend = token.backend_class
        if self.clock is anyio.current_time:
            self.clock = _loop_clock(token)
            self.backend_clock = True
        else:
            self.backend_clock = self.clock == backend.current_time
        self.receiver.reset(self.clock())
        self._task_group = anyio.create_task_group()
        await self._task_group.__aenter__()
        set_receiver = self._set_receiver
        native = token.native_token
        # Push only where the loop has call_at timers for the receiver's deadline (asyncio).
        if set_receiver is not None and callable(getattr(native, "call_at", None)):
            self.loop = native
            self._task_group.start_soon(self._push, set_receiver, name="aiortu link reader")
        else:
            self._task_group.start_soon(self._pump, name="aiortu link reader")
        return self

    async def __aexit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        traceback: TracebackType | None,
    ) -> bool | None:
        await self.aclose()
        assert self._task_group is not None
        # The body's own exception propagates as it is; the reader task has been
        # cancelled and only needs collecting, so it must not wrap that exception. No
        # shield around it: a task group's scope must be exited as the host's innermost
        # scope, and its own cancellation already keeps the collection short.
        await self._task_group.__aexit__(None, None, None)
        return None

    async def aclose(self) -> None:
        """Stop reading and close the stream."""
        if self._task_group is not None:
            self._task_group.cancel_scope.cancel()
        self._close_silence_timer()
        self._send_events.close()
        with anyio.CancelScope(shield=True):
            await self.stream.aclose()

    # -- receiving -------------------------------------------------------------------

    @property
    def last_activity(self) -> float:
        """When the line was last busy: the later of the last byte received and the last sent."""
        return max(self._last_received, self._transmit_end)

    @property
    def closed(self) -> bool:
        """True once the reader has stopped: the stream failed or the link was closed."""
        return self._closed.is_set()

    async def wait_closed(self) -> None:
        """Return once the reader has stopped (see :attr:`closed`)."""
        await self._closed.wait()

    def listen(self, listener: LinkListener | None) -> None:
        """Hand every event to *listener* from now on, instead of queueing it (``None``
        queues again). The listener runs in the reader task, or in the event loop's read
        callback for a stream that pushes its bytes, and must not block; it is called with
        ``None`` once the reader has stopped (at once if it already has)."""
        self._listener = listener
        if listener is not None and self._closed.is_set():
            listener(None)

    async def receive(self) -> LinkEvent:
        """The next frame or discard, oldest first.

        Raises :class:`~aiortu.errors.ConnectionLost` once the stream has failed or closed
        and every queued event has been received.
        """
        try:
            return await self._receive_events.receive()
        except (anyio.EndOfStream, anyio.ClosedResourceError):
            raise self._connection_lost() from self._error

    def receive_nowait(self) -> LinkEvent | None:
        """The next queued event, or ``None`` if there is none yet."""
        try:
            return self._receive_events.receive_nowait()
        except anyio.WouldBlock:
            return None
        except (anyio.EndOfStream, anyio.ClosedResourceError):
            raise self._connection_lost() from self._error

    def connection_lost_error(self) -> ConnectionLost:
        """The :class:`~aiortu.errors.ConnectionLost` that stands for the link's end."""
        return self._connection_lost()

    def _connection_lost(self) -> ConnectionLost:
        if self._error is None:
            return ConnectionLost("the link is closed")
        return ConnectionLost(f"the line failed: {self._error!r}")

    async def _pump(self) -> None:
        receiver = self.receiver
        clock = self.clock
        stream = self.stream
        backend = self.backend
        assert backend is not None
        cancel_scope = backend.create_cancel_scope
        backend_time = backend.current_time
        native = self.backend_clock
        try:
            while True:
                deadline = receiver.next_deadline()
                if deadline is None:
                    chunk = await stream.receive()
                else:
                    chunk = b""
                    if not native:
                        deadline = backend_time() + max(0.0, deadline - clock())
                    with cancel_scope(deadline=deadline):
                        chunk = await stream.receive()
                now = clock()
                if chunk:
                    self._last_received = now
                    # The line is half duplex: a byte received proves our own frame has
                    # left it, even where the wire time estimate says otherwise (virtual
                    # lines deliver faster than the baud rate).
                    self._transmit_end = min(self._transmit_end, now)
                    self._deliver(receiver.feed(chunk, now))
                else:
                    self._deliver(receiver.expire(now))
        except _STREAM_ERRORS as error:
            self._error = error
        finally:
            self._send_events.close()
            self._stopped = True
            self._closed.set()
            if self._listener is not None:
                self._listener(None)

    # The push path: a PushStream (the serial port) calls :meth:`_on_chunk` from the event
    # loop's read callback, and the receiver's silence deadline is one loop timer
    # (:meth:`_arm_timer`). The reader task only waits for the stream's end, so a chunk
    # costs no task wake-up.

    async def _push(self, set_receiver: Callable[..., None]) -> None:
        backend = self.backend
        assert backend is not None
        lost = self._push_lost = backend.create_event()
        try:
            set_receiver(self._on_chunk, lost.set)
            self._arm_timer()
            await lost.wait()
            if self._push_error is not None:
                raise self._push_error
            await self.stream.receive()  # raises why the stream ended
        except _STREAM_ERRORS as error:
            self._error = error
        finally:
            set_receiver(None)
            if self._timer is not None:
                self._timer.cancel()
                self._timer = None
            self._send_events.close()
            self._stopped = True
            self._closed.set()
            if self._listener is not None:
                self._listener(None)

    def _on_chunk(self, chunk: bytes) -> None:
        try:
            now = self.clock()
            self._last_received = now
            # Half duplex: see _pump.
            self._transmit_end = min(self._transmit_end, now)
            # A chunk of the layout the master expects (once) or the slave takes (each
            # time) goes straight to them once the receiver has checked its CRC.
            expected = self._expected
            requests = self._requests
            take = checked = None
            if expected is not None and len(chunk) == expected[1] and chunk.startswith(expected[0]):
                take = expected[2]
                checked = expected[3]
            elif requests is not None and len(chunk) == requests[1] and chunk[1] in requests[0]:
                take = requests[2]
            if take is not None and self.receiver.take_expected_frame(chunk, now, checked):
                if expected is not None and take is expected[2]:
                    self._expected = None  # expect() hands over one frame only
                self.frames_received += 1
                take(chunk, now)
                if self._timer is None:
                    return  # an idle receiver has no deadline: no timer to arm
            else:
                events = self.receiver.feed(chunk, now)
                if events:
                    self._deliver(events)
            self._arm_timer()
        except BaseException as error:  # a bug: the reader task raises it
            self._fail_push(error)

    def expect(
        self,
        prefix: bytes,
        length: int,
        on_frame: Callable[[bytes, float], None],
        checked: bytes | None = None,
    ) -> None:
        """Hand the next chunk that is exactly one good frame of *length* bytes starting
        with *prefix* straight to ``on_frame(frame, end)``, once, instead of to the listener
        as a :class:`~aiortu.core.receiver.FrameReceived`; :meth:`forget_expected` undoes it.
        *prefix* and *length* must fit one frame layout (the receiver checks the CRC only).
        *checked* is a frame of that layout whose CRC is known to be good (the last reply
        to the same request): a chunk equal to it is not checked again.

        Only where the stream pushes its bytes (see :meth:`_push`); anything else takes
        the usual way. A master waiting for the reply it knows the shape of (a register
        read's) saves the event and the queue this way.
        """
        self._expected = (prefix, length, on_frame, checked)

    def expect_requests(
        self,
        function_codes: Container[int],
        length: int,
        on_request: Callable[[bytes, float], None] | None,
    ) -> None:
        """Hand every chunk that is exactly one good request of *length* bytes with one
        of *function_codes* straight to ``on_request(frame, end)``, from the read
        callback, instead of to the listener as a
        :class:`~aiortu.core.receiver.FrameReceived`; ``None`` stops it. Every request
        with those function codes must be *length* bytes long (01 to 06 are 8), whatever
        its unit: the receiver checks the CRC only.

        Like :meth:`expect`, only where the stream pushes its bytes. A slave answers the
        commonest requests this way without building an event.
        """
        self._requests = None if on_request is None else (function_codes, length, on_request)

    def forget_expected(self) -> None:
        """Undo :meth:`expect`, if the frame has not come."""
        self._expected = None

    def _on_timer(self) -> None:
        self._timer = None
        try:
            events = self.receiver.expire(self.clock())
            if events:
                self._deliver(events)
            self._arm_timer()
        except BaseException as error:
            self._fail_push(error)

    def _fail_push(self, error: BaseException) -> None:
        if self._push_error is None:
            self._push_error = error
        if self._push_lost is not None:
            self._push_lost.set()

    def _arm_timer(self) -> None:
        """Keep one loop timer at the receiver's next deadline (none without one)."""
        deadline = self.receiver.next_deadline()
        timer = self._timer
        if timer is not None:
            if deadline == self._timer_deadline:
                return
            timer.cancel()
            self._timer = None
        if deadline is None:
            return
        self._timer_deadline = deadline
        self._timer = self.call_at(deadline, self._on_timer)

    def call_at(self, when: float, callback: Callable[..., object], *args: object) -> Any:
        """Have the event loop call ``callback(*args)`` at *when* (the link's clock);
        return a handle with ``cancel()``. Only where :attr:`loop` is set."""
        loop = self.loop
        assert loop is not None
        if self.backend_clock:
            return loop.call_at(when, callback, *args)
        return loop.call_later(max(0.0, when - self.clock()), callback, *args)

    def _deliver(self, events: list[LinkEvent]) -> None:
        for event in events:
            if isinstance(event, FrameReceived):
                self.frames_received += 1
            else:
                self.discarded[event.reason] += 1
            listener = self._listener
            if listener is not None:
                listener(event)
                continue
            try:
                self._send_events.send_nowait(event)
            except anyio.WouldBlock:
                # Drop the oldest: the newest frame is the one a waiting master wants.
                self._receive_events.receive_nowait()
                self.events_dropped += 1
                self._send_events.send_nowait(event)

    # -- sending ---------------------------------------------------------------------

    async def send(self, frame: bytes) -> float:
        """Send *frame* after ``frame_gap`` of silence; return when it will have left the wire.

        The returned time is in the link's clock: the moment the write began plus the
        frame's wire time at the line's character rate. Raises
        :class:`~aiortu.errors.ConnectionLost` if the stream fails.
        """
        # One sender at a time, in order; no yield when nobody else is sending (a
        # master's line has a single sender).
        if self._sending:
            await self._wait_turn_to_send()
        else:
            self._sending = True
        try:
            clock = self.clock
            last = max(self._last_received, self._transmit_end)
            if last + self.frame_gap > clock():
                await self.wait_for_silence(self.frame_gap)
            if self._error is not None or self._stopped:
                raise self._connection_lost()
            start = self.last_write_start = clock()
            self.writes_begun += 1
            send_nowait = self._send_nowait
            if send_nowait is None or not send_nowait(frame):
                try:
                    await self.stream.send(frame)
                except _STREAM_ERRORS as error:
                    self._error = error
                    raise self._connection_lost() from error
            return self._sent(frame, start, self.clock())
        finally:
            if self._send_waiters:
                self._pass_turn_to_send()
            else:
                self._sending = False

    def send_now(self, frame: bytes) -> float | None:
        """Send *frame* at once if the line lets it go without a wait, else send nothing.

        It goes when nobody else is sending, ``frame_gap`` of silence has already passed,
        and the stream writes without a yield (the serial port does); then the return is
        what :meth:`send` returns. ``None`` means nothing was sent: use :meth:`send`. A
        slave answers this way from the link's read callback, with no task wake-up.
        """
        send_nowait = self._send_nowait
        if send_nowait is None or self._sending or self._error is not None or self._stopped:
            return None
        start = self.clock()
        if max(self._last_received, self._transmit_end) + self.frame_gap > start:
            return None
        if not send_nowait(frame):
            return None
        self.last_write_start = start
        self.writes_begun += 1
        # The write took microseconds, far less than the wire time: no second clock read.
        return self._sent(frame, start, start)

    def _sent(self, frame: bytes, start: float, now: float) -> float:
        """*frame* began to go out at *start*, and the write returned at *now*."""
        self.frames_sent += 1
        # The OS may buffer the write, so it returns early; the wire is busy until the
        # last character has gone, whichever is later.
        end = max(start + len(frame) * self.char_time, now)
        self._transmit_end = end
        return end

    async def _wait_turn_to_send(self) -> None:
        turn = anyio.Event() if self.backend is None else self.backend.create_event()
        self._send_waiters.append(turn)
        try:
            await turn.wait()
        except BaseException:
            if turn.is_set():
                self._pass_turn_to_send()  # handed the turn, yet gone: pass it on
            else:
                self._send_waiters.remove(turn)
            raise

    def _pass_turn_to_send(self) -> None:
        if self._send_waiters:
            self._send_waiters.pop(0).set()  # the turn passes; _sending stays true
        else:
            self._sending = False

    async def wait_for_silence(self, silence: float) -> None:
        """Wait until neither side has used the line for *silence* seconds (no yield when
        it already has).

        Under asyncio on Linux the wait ends on a :class:`~aiortu.line._wake_timer.WakeTimer`,
        at the time itself: the event loop's own timers end on the next whole millisecond,
        a large share of t3.5 at high baud rates. Elsewhere it sleeps on the loop's timers.
        """
        while True:
            # Bytes that arrive meanwhile move the end of the silence: look again on waking.
            quiet_at = max(self._last_received, self._transmit_end) + silence
            remaining = quiet_at - self.clock()
            if remaining <= 0:
                return
            if not self._silence_timer_tried:
                self._make_silence_timer()
            timer = self._silence_timer
            if timer is None:
                await anyio.sleep(remaining)
            elif self.clock is time.monotonic:
                await self._wait_for_timer(timer, quiet_at)
            else:
                await self._wait_for_timer(timer, time.monotonic() + remaining)

    def _make_silence_timer(self) -> None:
        """Make the timer :meth:`wait_for_silence` ends on: once per link, on first use."""
        self._silence_timer_tried = True
        timer = create_wake_timer(self._on_silence_timer)
        if timer is not None:
            self._silence_loop = anyio.lowlevel.current_token().native_token
            self._silence_timer = timer

    async def _wait_for_timer(self, timer: WakeTimer, when: float) -> None:
        """Wait until *timer* goes off: at *when* (``time.monotonic()`` seconds), or
        earlier for another waiter's deadline, or when the link closes."""
        loop = self._silence_loop
        woken = loop.create_future()
        timer.begin(loop, when)
        self._silence_waiters.append(woken)
        try:
            await woken
        finally:
            self._silence_waiters.remove(woken)
            timer.end()

    def _on_silence_timer(self) -> None:
        for woken in self._silence_waiters:
            if not woken.done():
                woken.set_result(None)

    def _close_silence_timer(self) -> None:
        timer = self._silence_timer
        self._silence_timer = None
        self._silence_timer_tried = True  # a closing link makes no new one
        if timer is not None:
            timer.close()
            # Whoever waits on it finishes the wait on the event loop's timers.
            self._on_silence_timer()

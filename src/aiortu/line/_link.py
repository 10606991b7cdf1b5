"""One serial line: a byte stream pumped through the receiver with a clock.

A [`Link`][aiortu.line.Link] owns a byte stream (a serial port, a TCP connection to a serial device
server, a virtual line). It timestamps every chunk with the link's clock, runs the
sans-IO [`Receiver`][aiortu.core.rtu.Receiver], wakes it at its deadlines, and queues
what it yields: frames, and the bytes it discarded with the reason.

Two ways in. A stream that pushes its bytes (a [`PushStream`][aiortu.transport.PushStream],
as the serial port's [`SerialStream`][aiortu.transport.SerialStream] is), on an event loop with
`call_at` timers (asyncio), hands each chunk to the link from the loop's read callback,
and the receiver's silence deadline is one event loop timer, armed and cancelled by the
link; the reader task then only waits for the stream's end, so a chunk costs no task
wake-up. Any other byte stream (virtual
lines, TCP, file descriptors), and any stream under trio, is read by the reader task, with
the deadline as a cancel scope around `receive()`.

[`Link.send`][aiortu.line.Link.send] keeps the spec's silence: it first waits until the line has
been quiet, in both directions, for `frame_gap` (t3.5 of the line settings by default; 0 is allowed
for virtual lines and TCP, where there is no wire to keep quiet), then writes the frame and returns
when, by the clock, its last byte will have left the wire. The master starts its response timeout
from that time, not from when `write()` returned. Under asyncio on Linux the wait ends on a
[`WakeTimer`][aiortu.line.WakeTimer], at the time itself rather than on the loop's next whole
millisecond. [`Link.send_now`][aiortu.line.Link.send_now] sends without a wait or a yield when the
line allows it (a push stream's `send_nowait`, the gap kept): a slave answers from the read callback
that way.

On the push path a master can also tell the link the exact shape of the reply it waits for
([`Link.expect`][aiortu.line.Link.expect]: its first bytes and length); a chunk that is exactly that
frame with a good CRC goes straight to the master, with no event built or queued. Anything else, a
split or garbled reply included, takes the usual way through the receiver.

A link is direct ([`Link.direct`][aiortu.line.Link], one predicate, `_direct`) where its stream
pushes whole frames and no frame gap is kept: a master's Modbus TCP, Modbus/TCP Security or Modbus
UDP stream on asyncio. Such a line has no timing to keep, so `send_now` asks no silence and the
push reader takes the expected reply with the receiver's check only (`PushReader.on_frame`);
everything else goes the usual way. A differential test runs the same exchanges with the predicate
forced off.

The master and the slave are built on this; users rarely need it directly, except to
watch a line (`role=Role.MONITOR`).

Three modules beside this one hold the link's parts: `_push_reader.py` the push path (the chunk
callback, its timer, and the taps of [`expect`][aiortu.line.Link.expect] and
[`expect_requests`][aiortu.line.Link.expect_requests]), `_sender.py` the send turns and the
silence waits, and `_native.py` the backend's cheapest waits
([`native_waits`][aiortu.line.native_waits]).

Events go to a queue that [`Link.receive`][aiortu.line.Link.receive] reads, or, while a listener is
set ([`Link.listen`][aiortu.line.Link.listen]), straight to that listener from the reader: the
master's line engine listens, so that a reply reaches the waiting transaction with no task hop in
between. The hot path avoids work that does nothing: the default clock is bound to the running event
loop's clock when the link opens, and [`Link.send`][aiortu.line.Link.send] yields to the loop only
when it has to wait (for the silence, for another sender, or for the stream).
"""

from __future__ import annotations

import math
from collections import Counter
from collections.abc import Callable, Container, Iterable
from types import TracebackType
from typing import Any, Self, cast

import anyio
import anyio.abc
import anyio.lowlevel
from anyio.streams.memory import MemoryObjectReceiveStream, MemoryObjectSendStream

from aiortu.core.rtu import (
    DiscardReason,
    FrameDiscarded,
    FrameReceived,
    Receiver,
    Role,
    TimingMode,
)
from aiortu.core.serial import LineSettings
from aiortu.errors import ConnectionLost
from aiortu.line._native import NativeWaits, loop_clock, native_waits
from aiortu.line._push_reader import PushReader, ReplyTap, RequestTap
from aiortu.line._sender import LineActivity, SendTurns, SilenceWaits
from aiortu.transport import FramedStream, PushStream

__all__ = ("Link", "LinkEvent", "LinkListener")

LinkEvent = FrameReceived | FrameDiscarded
"""What a link delivers: a frame whose CRC checks, or bytes discarded with a reason."""

LinkListener = Callable[[LinkEvent | None], None]
"""Called by the reader with each event, and with `None` once the reader stops."""

_STREAM_ERRORS = (
    anyio.EndOfStream,
    anyio.BrokenResourceError,
    anyio.ClosedResourceError,
    OSError,
)


def _describe(error: BaseException) -> str:
    """Why the stream ended, in words: what happened to the port, then the detail it gave."""
    if isinstance(error, anyio.EndOfStream):
        return "the port closed"
    if isinstance(error, anyio.ClosedResourceError):
        return "the port was closed"
    detail = _detail(error)
    return f"the port is gone ({detail})" if detail else "the port is gone"


def _detail(error: BaseException | None) -> str:
    """What `error` says, without its class name; its cause's words where it says nothing."""
    if error is None:
        return ""
    if isinstance(error, OSError) and error.strerror:
        name = error.filename
        return f"{name}: {error.strerror}" if name is not None else error.strerror
    return str(error) or _detail(error.__cause__ or error.__context__)


class Link:
    """One serial line (see the module docstring). Use it as an async context manager.

    `settings` are the line settings (timing for the receiver and the frame gap).
    `role`, `units`, `timing` and `frame_silence` configure the receiver.
    `frame_gap` is the silence kept before each transmission: `None` for t3.5 of the
    settings. `clock` returns seconds (default `anyio.current_time`, which the link
    replaces, when it opens, with the running backend's own clock: the same time, read
    without looking the backend up on every call).
    A stream of whole frames (a [`FramedStream`][aiortu.transport.FramedStream] such as
    [`ModbusTcpStream`][aiortu.transport.ModbusTcpStream]) has no wire: its frame gap and
    `frame_silence` default to 0 (each chunk is a frame that ends at once, whatever its
    function code) and its wire time is 0, so a response timeout starts when the write returned.
    `queue_size` bounds the events waiting to be received; when it is full the oldest
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
        # A stream that hands over whole frames (Modbus TCP) has no wire: nothing to keep
        # quiet, no wire time, and each chunk is a frame that ends at once.
        whole_frames = isinstance(stream, FramedStream) and stream.whole_frames
        self.whole_frames = whole_frames
        """Whether each chunk the stream delivers is one whole frame (see
        [`FramedStream`][aiortu.transport.FramedStream])."""
        self.char_time = 0.0 if whole_frames else self.settings.char_time
        """Seconds one character takes on the wire, from [`settings`][aiortu.line.Link] (0 for a
        stream of whole frames)."""
        if frame_gap is None:
            frame_gap = 0.0 if whole_frames else self.settings.t3_5
        if whole_frames and frame_silence is None:
            frame_silence = 0.0
        self.frame_gap = frame_gap
        if self.frame_gap < 0 or math.isnan(self.frame_gap):
            raise ValueError(f"frame_gap must be >= 0 seconds, not {frame_gap}")
        self.clock = clock
        self.wire_timed: bool = _wire_timed(stream, self.settings)
        """Whether the wire times the link computes from [`settings`][aiortu.line.Link] are real: a
        frame sent cannot have left the wire sooner, so no reply can begin sooner. True
        where the stream says so (a serial port that is not a pseudo-terminal, a paced
        virtual line); false on TCP, unpaced virtual lines and ptys, which deliver at once.
        A stream whose own settings are faster than the link's is not: the link would date
        its frames later than they left the wire. The master may set it
        (`Master(wire_timed=...)`)."""
        # No wire time in the receiver of whole frames either: two frames handed over in one
        # read (the same clock reading) are two, the first ended when the second begins.
        self.receiver = Receiver(
            self.settings, role=role, units=units, timing=timing, frame_silence=frame_silence,
            whole_frames=whole_frames,
        )  # fmt: skip
        self._init_events(queue_size)
        self._init_runtime()
        self._init_sender(stream)
        self._init_counters()

    def _init_events(self, queue_size: int) -> None:
        """The queue of events for `receive`, and the listener that may take them instead."""
        self.queue_size = queue_size
        """The most events kept waiting to be received (by a listener too)."""
        self._send_events: MemoryObjectSendStream[LinkEvent]
        self._receive_events: MemoryObjectReceiveStream[LinkEvent]
        self._send_events, self._receive_events = anyio.create_memory_object_stream[LinkEvent](
            queue_size
        )
        self._listener: LinkListener | None = None

    def _init_runtime(self) -> None:
        """What the link learns of the running backend when it opens, and its run state."""
        self._task_group: anyio.abc.TaskGroup | None = None
        self.backend: type[anyio.abc.AsyncBackend] | None = None
        """The async backend the link runs on (set when it opens): its events, cancel
        scopes and clock cost no backend lookup."""
        self.backend_clock = False
        """Whether [`clock`][aiortu.line.Link] is the backend's own clock, so that its times can be
        used as cancel scope deadlines as they are."""
        self.loop: Any = None
        """The event loop, where the link reads a stream that pushes its bytes (see `_push`); `None`
        otherwise. Its futures and [`call_at`][aiortu.line.Link.call_at] timers are the cheapest way
        to wait for the link there."""
        self.direct = False
        """Whether the link is direct (set when it opens; see `PushReader.on_frame`): its stream
        pushes whole frames (a master's Modbus TCP, Modbus/TCP Security or Modbus UDP stream on
        asyncio) and no frame gap is kept. Such a line has no timing to keep: a frame has left
        once written, and each chunk is one frame. So [`send_now`][aiortu.line.Link.send_now]
        asks no silence, and the reply [`expect`][aiortu.line.Link.expect] waits for is taken
        without the receiver's chunk path."""
        self.waits: NativeWaits | None = None
        """The running backend's cheapest waits (set when the link opens): a
        [`Waiter`][aiortu.line.Waiter] is what a listener sets to wake a task."""
        self._error: BaseException | None = None
        self._closed = anyio.Event()
        self._stopped = False

    def _init_sender(self, stream: anyio.abc.ByteStream) -> None:
        """The sender's state, and the push reader where the stream pushes its bytes."""
        self._activity = LineActivity()
        self._turns = SendTurns()
        self._silence = SilenceWaits()
        self.writes_begun = 0
        """Writes [`send`][aiortu.line.Link.send] has begun: a caller cancelled inside
        [`send`][aiortu.line.Link.send] can tell whether its frame may have gone out."""
        self.last_write_start = -math.inf
        """When the last write began, in the link's clock."""
        # Checked once here (an isinstance against a runtime protocol takes microseconds):
        # the chunk and send paths use what is kept.
        self._push_reader: PushReader | None = None
        self._send_nowait: Callable[[bytes], bool] | None = None
        """A push stream's write without a yield (the serial port's), tried before `send`."""
        if isinstance(stream, PushStream):
            self._push_reader = PushReader(self)
            self._send_nowait = stream.send_nowait

    def _init_counters(self) -> None:
        self.frames_received = 0
        """Frames received whose CRC checks."""
        self.frames_sent = 0
        """Frames sent."""
        self.discarded: Counter[DiscardReason] = Counter()
        """Discards by reason."""
        self.events_dropped = 0
        """Events dropped because the queue was full."""

    # -- lifetime --------------------------------------------------------------------

    async def __aenter__(self) -> Self:
        token = anyio.lowlevel.current_token()
        backend = self.backend = token.backend_class
        if self.clock is anyio.current_time:
            self.clock = loop_clock(token)
            self.backend_clock = True
        else:
            self.backend_clock = self.clock == backend.current_time
        now = self.clock()
        if not (self.whole_frames or getattr(self.stream, "starts_between_frames", False)):
            # A wire may be mid-frame when the port opens: wait for silence first (INIT).
            # A stream of whole frames (Modbus TCP, UDP) never is: its first reply may come
            # sooner than a t3.5 after the open, and is a reply, not noise.
            self.receiver.reset(now)
        # A port just opened has heard nothing: someone may be mid-frame (a master whose
        # port came back after an unplug), so the first frame waits frame_gap too.
        activity = self._activity
        activity.last_received = max(activity.last_received, now)
        self._task_group = anyio.create_task_group()
        await self._task_group.__aenter__()
        waits = self.waits = native_waits()
        # Push only where the loop has call_at timers for the receiver's deadline (asyncio).
        if self._push_reader is not None and waits.call_at is not None:
            self.loop = waits.loop
            self.direct = _direct(self)
            self._task_group.start_soon(self._push, name="aiortu link reader")
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
        self._silence.close()
        self._send_events.close()
        with anyio.CancelScope(shield=True):
            await self.stream.aclose()

    # -- receiving -------------------------------------------------------------------

    @property
    def last_activity(self) -> float:
        """When the line was last busy: the later of the last byte received and the last sent."""
        activity = self._activity
        return max(activity.last_received, activity.transmit_end)

    @property
    def closed(self) -> bool:
        """True once the reader has stopped: the stream failed or the link was closed."""
        return self._closed.is_set()

    async def wait_closed(self) -> None:
        """Return once the reader has stopped (see [`closed`][aiortu.line.Link.closed])."""
        await self._closed.wait()

    def listen(self, listener: LinkListener | None) -> None:
        """Hand every event to `listener` from now on, instead of queueing it (`None`
        queues again). The listener runs in the reader task, or in the event loop's read
        callback for a stream that pushes its bytes, and must not block; it is called with
        `None` once the reader has stopped (at once if it already has)."""
        self._listener = listener
        if listener is not None and self._closed.is_set():
            listener(None)

    async def receive(self) -> LinkEvent:
        """The next frame or discard, oldest first.

        Raises [`ConnectionLost`][aiortu.errors.ConnectionLost] once the stream has failed or closed
        and every queued event has been received.
        """
        try:
            return await self._receive_events.receive()
        except (anyio.EndOfStream, anyio.ClosedResourceError):
            raise self._connection_lost() from self._error

    def receive_nowait(self) -> LinkEvent | None:
        """The next queued event, or `None` if there is none yet."""
        try:
            return self._receive_events.receive_nowait()
        except anyio.WouldBlock:
            return None
        except (anyio.EndOfStream, anyio.ClosedResourceError):
            raise self._connection_lost() from self._error

    def connection_lost_error(self) -> ConnectionLost:
        """The [`ConnectionLost`][aiortu.errors.ConnectionLost] that stands for the link's end.

        Its message says what happened to the port in words; the stream's own error is its
        `__cause__`.
        """
        return self._connection_lost()

    def _connection_lost(self) -> ConnectionLost:
        error = self._error
        if error is None:
            return ConnectionLost("the link is closed")
        lost = ConnectionLost(f"the line failed: {_describe(error)}")
        lost.__cause__ = error
        return lost

    async def _pump(self) -> None:
        """The reader task for a stream read with `receive()`."""
        receiver = self.receiver
        clock = self.clock
        stream = self.stream
        backend = self.backend
        assert backend is not None
        cancel_scope = backend.create_cancel_scope
        backend_time = backend.current_time
        native = self.backend_clock
        activity = self._activity
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
                    activity.received(now)
                    self._deliver(receiver.feed(chunk, now))
                else:
                    self._deliver(receiver.expire(now))
        except _STREAM_ERRORS as error:
            self._error = error
        finally:
            self._reader_stopped()

    async def _push(self) -> None:
        """The reader task for a stream that pushes its bytes: it waits for the stream's end
        (see `PushReader`)."""
        assert self._push_reader is not None
        set_receiver = cast(PushStream, self.stream).set_receiver
        try:
            await self._push_reader.run(set_receiver)
        except _STREAM_ERRORS as error:
            self._error = error
        finally:
            self._reader_stopped()

    def _reader_stopped(self) -> None:
        self._send_events.close()
        self._stopped = True
        self._closed.set()
        if self._listener is not None:
            self._listener(None)

    def expect(self, tap: ReplyTap) -> None:
        """Hand the next chunk that is exactly one good frame of `tap.length` bytes starting
        with `tap.prefix` straight to `tap.on_frame(frame, end)`, once, instead of to the
        listener as a [`FrameReceived`][aiortu.core.rtu.FrameReceived];
        [`forget_expected`][aiortu.line.Link.forget_expected] undoes it. `prefix` and `length`
        must fit one frame layout (the receiver checks the CRC only). `tap.checked` is a frame of
        that layout whose CRC is known to be good (the last reply to the same request): a chunk
        equal to it is not checked again. A tap may be given again (a master keeps one per
        reply shape).

        Only where the stream pushes its bytes (see `_push`); anything else takes
        the usual way. A master waiting for the reply it knows the shape of (a register
        read's) saves the event and the queue this way.
        """
        if self._push_reader is not None:
            self._push_reader.reply_tap = tap

    def expect_requests(
        self,
        function_codes: Container[int],
        length: int,
        on_request: Callable[[bytes, float], None] | None,
    ) -> None:
        """Hand every chunk that is exactly one good request of `length` bytes with one
        of `function_codes` straight to `on_request(frame, end)`, from the read
        callback, instead of to the listener as a
        [`FrameReceived`][aiortu.core.rtu.FrameReceived]; `None` stops it. Every request
        with those function codes must be `length` bytes long (01 to 06 are 8), whatever
        its unit: the receiver checks the CRC only.

        Like [`expect`][aiortu.line.Link.expect], only where the stream pushes its bytes. A slave
        answers the commonest requests this way without building an event.
        """
        if self._push_reader is not None:
            tap = None if on_request is None else RequestTap(function_codes, length, on_request)
            self._push_reader.request_tap = tap

    def forget_expected(self) -> None:
        """Undo [`expect`][aiortu.line.Link.expect], if the frame has not come."""
        if self._push_reader is not None:
            self._push_reader.reply_tap = None

    def call_at(self, when: float, callback: Callable[..., object], *args: object) -> Any:
        """Have the event loop call `callback(*args)` at `when` (the link's clock);
        return a handle with `cancel()`. Only where [`loop`][aiortu.line.Link] is set."""
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
        """Send `frame` after `frame_gap` of silence; return when it will have left the wire.

        The returned time is in the link's clock: the moment the write began plus the
        frame's wire time at the line's character rate. Raises
        [`ConnectionLost`][aiortu.errors.ConnectionLost] if the stream fails.
        """
        # One sender at a time, in order; no yield when nobody else is sending (a
        # master's line has a single sender).
        turns = self._turns
        if turns.busy:
            await turns.wait(self.backend)
        else:
            turns.busy = True
        try:
            clock = self.clock
            activity = self._activity
            if max(activity.last_received, activity.transmit_end) + self.frame_gap > clock():
                await self._silence.wait(activity, clock, self.frame_gap)
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
            turns.pass_on()

    @property
    def sends_at_once(self) -> bool:
        """Whether [`send_now`][aiortu.line.Link.send_now] may write a frame without a yield:
        the stream pushes its bytes and writes without one (a serial port), nobody else is
        sending, and the stream has not failed. The silence is asked apart
        ([`quiet_at`][aiortu.line.Link.quiet_at])."""
        return (
            self._send_nowait is not None
            and not self._turns.busy
            and self._error is None
            and not self._stopped
        )

    def quiet_at(self) -> float:
        """When `frame_gap` of silence will have passed, in the link's clock, unless bytes
        arrive before then (they move it)."""
        activity = self._activity
        return max(activity.last_received, activity.transmit_end) + self.frame_gap

    def call_when_quiet(self, callback: Callable[[], object]) -> None:
        """Have the event loop call `callback()` once `frame_gap` of silence has passed (bytes
        that arrive meanwhile move it): at the time itself where a
        [`WakeTimer`][aiortu.line.WakeTimer] can watch it. One callback at a time (a second
        replaces the first); [`cancel_quiet_call`][aiortu.line.Link.cancel_quiet_call] undoes
        it. Only where [`loop`][aiortu.line.Link] is set: a sender that is no task (the
        master's fast path) waits for the silence this way."""
        self._silence.call_when_quiet(
            self.loop, self._activity, self.clock, self.frame_gap, callback
        )

    def cancel_quiet_call(self) -> None:
        """Undo [`call_when_quiet`][aiortu.line.Link.call_when_quiet], if it has not called."""
        self._silence.cancel_call()

    def send_now(self, frame: bytes) -> float | None:
        """Send `frame` at once if the line lets it go without a wait, else send nothing.

        It goes when nobody else is sending, `frame_gap` of silence has already passed, and the
        stream writes without a yield (the serial port does); then the return is what
        [`send`][aiortu.line.Link.send] returns. `None` means nothing was sent: use
        [`send`][aiortu.line.Link.send]. A slave answers this way from the link's read callback,
        with no task wake-up.
        """
        send_nowait = self._send_nowait
        if send_nowait is None or self._turns.busy or self._error is not None or self._stopped:
            return None
        start = self.clock()
        activity = self._activity
        direct = self.direct  # no gap and no wire: quiet, and the frame gone once written
        if (
            not direct
            and max(activity.last_received, activity.transmit_end) + self.frame_gap > start
        ):
            return None
        if not send_nowait(frame):
            return None
        self.last_write_start = start
        self.writes_begun += 1
        if direct:
            self.frames_sent += 1
            activity.transmit_end = start
            return start
        # The write took microseconds, far less than the wire time: no second clock read.
        return self._sent(frame, start, start)

    def _sent(self, frame: bytes, start: float, now: float) -> float:
        """`frame` began to go out at `start`, and the write returned at `now`."""
        self.frames_sent += 1
        # The OS may buffer the write, so it returns early; the wire is busy until the
        # last character has gone, whichever is later.
        end = max(start + len(frame) * self.char_time, now)
        self._activity.transmit_end = end
        return end

    async def wait_for_silence(self, silence: float) -> None:
        """Wait until neither side has used the line for `silence` seconds (no yield when
        it already has).

        Under asyncio on Linux the wait ends on a [`WakeTimer`][aiortu.line.WakeTimer],
        at the time itself: the event loop's own timers end on the next whole millisecond,
        a large share of t3.5 at high baud rates. Elsewhere it sleeps on the loop's timers.
        """
        await self._silence.wait(self._activity, self.clock, silence)


def _direct(link: Link) -> bool:
    """The direct route's one predicate, for a link whose stream pushes its bytes (see
    [`Link.direct`][aiortu.line.Link]): each chunk is one whole frame, and no frame gap is
    kept (nor is there a wire time: a stream of whole frames has none)."""
    return link.whole_frames and link.frame_gap == 0


def _wire_timed(stream: object, settings: LineSettings) -> bool:
    """Whether the wire times computed from `settings` are real on `stream` (see
    [`Link.wire_timed`][aiortu.line.Link.wire_timed])."""
    if getattr(stream, "wire_timed", False) is not True:
        return False
    paced = getattr(stream, "settings", None)
    # Bytes that go faster than `settings` leave the wire sooner than computed.
    return not isinstance(paced, LineSettings) or paced.char_time >= settings.char_time

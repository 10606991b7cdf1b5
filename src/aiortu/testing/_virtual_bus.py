"""In-memory serial buses: RS-485 wires between byte streams, paced, chunked and noisy on demand.

A [`VirtualBus`][aiortu.testing.VirtualBus] has N endpoints, each an `anyio.abc.ByteStream`. What
one endpoint sends reaches every other endpoint and is never echoed to its sender, as on a two-wire
RS-485 bus; a pair ([`virtual_pair`][aiortu.testing.virtual_pair]) is a bus of two.

The wire model:

- One shared wire, half duplex. Transmissions go on it one after the other, in the order they were
  sent. If an endpoint sends while another endpoint's bytes are still on the wire, the bus counts a
  collision in [`VirtualBus.collisions`][aiortu.testing.VirtualBus.collisions] and queues the new
  bytes after the ones on the wire, unchanged, as if the transceiver had waited. A test that wants
  collisions to garble frames adds a [`FaultPlan`][aiortu.testing.FaultPlan].
- Pacing: with `settings`, bytes leave at the character rate of those line settings:
  byte k of a transmission starting at t0 arrives at `t0 + (k + 1) * char_time`. Due
  times are absolute, so a slow scheduler delays single deliveries but never accumulates
  drift. Without `settings` the line is unpaced and bytes arrive at once.
- Adapter chunking: `latency` models the receive timer of a USB serial adapter: bytes are
  held and handed over `latency` seconds after the first of them arrived, at most
  `chunk_size` bytes at a time (a full chunk goes at once). Every receiver's adapter runs in
  step, so all see the same chunk boundaries.
- Faults: one [`FaultInjector`][aiortu.testing.FaultInjector] per bus, applied to each transmission
  as it goes on the wire; every receiver sees the same corrupted bytes, as with noise on
  the cable. Faults are reproducible from the plan's seed, for a given sequence of sends.
- [`VirtualBus.trace`][aiortu.testing.VirtualBus.trace] keeps the last `trace_size` transmissions
  with their paced wire times. A transmission that continues the same sender's previous one without
  a pause is merged into its entry, so one entry is one burst on the wire.
- Receive buffers are bounded (`receive_buffer_size` bytes per endpoint). An endpoint that does not
  read loses its oldest bytes, counted in
  [`VirtualEndpoint.overrun_bytes`][aiortu.testing.VirtualEndpoint.overrun_bytes], like a UART
  overrun; it never stalls the bus.
- Send buffers: on a paced bus [`VirtualEndpoint.send`][aiortu.testing.VirtualEndpoint.send] returns
  once the bytes are queued, and waits first while more than `send_buffer_size` bytes are waiting
  for the wire, like a kernel transmit buffer.

Wake-ups: a receiver waiting for paced bytes sleeps until they are due. asyncio's event
loop waits in whole milliseconds (rounded up), which would hand over the last byte of a
frame up to a millisecond late; so under asyncio on Linux the bus wakes its receivers
with a [`WakeTimer`][aiortu.line.WakeTimer] (a `timerfd` at the due time, to the
nanosecond) and never before the due time. Bytes in the middle of a transmission are
handed over at most about a millisecond apart (all that are due at each wake-up, as a
UART's FIFO would), the last byte of each run of bytes at its due time. Elsewhere (trio,
other systems) the receivers sleep with the event loop's own timers.

There is no background task: the wire is a schedule computed when bytes are sent, and
deliveries happen when a receiver (or sender) looks at the clock. The endpoints therefore
work with or without `async with`, under asyncio and trio alike; `async with` (or
[`VirtualBus.aclose`][aiortu.testing.VirtualBus.aclose]) closes every endpoint at the end.

The push extension: on a bus where nothing is ever held on the wire (unpaced, no adapter model, no
faults: [`VirtualBus.pushes`][aiortu.testing.VirtualBus.pushes]), the endpoints also have the serial
port's `set_receiver(receiver, on_lost)` and `send_nowait(data)`. The master's and the slave's link
then take their push path, as on a serial port: a transmission reaches the receiving link from one
event loop callback in the loop pass after it was sent (never inside the sender's call, so no
consumer is re-entered), and a link writes without a yield; no task wakes up per frame. Paced,
chunked and faulted buses keep the plain byte stream, which the link reads from a task. Reads
through [`VirtualEndpoint.receive`][aiortu.testing.VirtualEndpoint.receive] work on both.

Cancellation: [`VirtualEndpoint.receive`][aiortu.testing.VirtualEndpoint.receive] is cancelled only
before it takes bytes off the bus. A reader whose deadline comes due in the loop pass that delivered
a frame gets the frame on its next call; the bytes are never taken and dropped.
"""

from __future__ import annotations

import asyncio
import math
from collections import deque
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from types import TracebackType

import anyio
import anyio.abc
import anyio.lowlevel

from aiortu.core.serial import LineSettings
from aiortu.errors import InvalidValue
from aiortu.line import WakeTimer, create_wake_timer, native_waits
from aiortu.testing._faults import FaultedChunk, FaultInjector, FaultPlan

__all__ = ("TraceEntry", "VirtualBus", "VirtualEndpoint", "virtual_pair")

# Bytes due within this many seconds of now count as arrived: float rounding of due times
# must never leave a receiver waking up to find nothing.
_EPSILON = 1e-6


# A receiver woken for bytes in the middle of a transmission takes all that are due and
# sleeps again for at least this long (but never past the last byte of the run): about the
# event loop's own timer granularity, so precise wake-ups cost no more wake-ups than before.
_BATCH = 1e-3


@dataclass(frozen=True, slots=True)
class TraceEntry:
    """One burst on the wire: `sender` put `data` on it from `start` to `end` (clock seconds).

    `data` is what went on the wire, after any faults. Times come from
    `anyio.current_time` and are the paced wire times, including pauses inside the
    burst; on an unpaced line `start` equals `end`.
    """

    start: float
    end: float
    sender: int
    data: bytes


class _Segment:
    """A run of bytes sent back to back, starting at `start`; `done` of them have arrived."""

    __slots__ = ("data", "done", "sender", "start")

    def __init__(self, start: float, data: bytes, sender: int) -> None:
        self.start = start
        self.data = data
        self.sender = sender
        self.done = 0


def _check_int(name: str, value: object, minimum: int) -> None:
    if isinstance(value, bool) or not isinstance(value, int) or value < minimum:
        raise InvalidValue(name, value, f"an integer >= {minimum}")


class VirtualEndpoint(anyio.abc.ByteStream):
    """One device's connection to a [`VirtualBus`][aiortu.testing.VirtualBus]. Created by the bus.

    [`receive`][aiortu.testing.VirtualEndpoint.receive] returns whatever has arrived, up to
    *max_bytes*; it raises `anyio.EndOfStream` once every other endpoint is closed and everything
    they sent was received, and `anyio.ClosedResourceError` after
    [`aclose`][aiortu.testing.VirtualEndpoint.aclose]. On a bus whose
    [`pushes`][aiortu.testing.VirtualBus.pushes] is true the endpoints also have `set_receiver` and
    `send_nowait`, the serial port's push extension (see the module docs).
    """

    def __init__(self, bus: VirtualBus, index: int, buffer_size: int) -> None:
        self.bus = bus
        """The bus this endpoint is on."""
        self.index = index
        """This endpoint's position on the bus, as used in
        [`TraceEntry.sender`][aiortu.testing.TraceEntry]."""
        self.overrun_bytes = 0
        """Bytes lost because the receive buffer was full (the oldest go first)."""
        self._buffer = bytearray()
        self._buffer_size = buffer_size
        self._closed = False
        self._receive_guard = anyio.ResourceGuard("reading from")
        self._on_lost: Callable[[], None] | None = None

    @property
    def closed(self) -> bool:
        """True once this endpoint (or its bus) was closed."""
        return self._closed

    @property
    def settings(self) -> LineSettings | None:
        """The line settings the bus paces at, or None for an unpaced bus."""
        return self.bus.settings

    @property
    def wire_timed(self) -> bool:
        """Whether bytes take their wire time here (a paced bus): then a master may trust the wire
        time it computes (see [`aiortu.line.Link.wire_timed`][aiortu.line.Link.wire_timed])."""
        return self.bus.char_time > 0

    @property
    def pending(self) -> int:
        """The number of bytes that arrived and wait to be received."""
        return len(self._buffer)

    def _push(self, data: bytes) -> None:
        if self._closed:
            return
        self._buffer += data
        excess = len(self._buffer) - self._buffer_size
        if excess > 0:
            del self._buffer[:excess]
            self.overrun_bytes += excess

    async def receive(self, max_bytes: int = 65536) -> bytes:
        """Wait for bytes from the other endpoints and return up to `max_bytes` of them."""
        with self._receive_guard:
            bus = self.bus
            # A cancellation (a reader's deadline) may only end the call before it takes
            # bytes: once taken out of the buffer they must reach the caller.
            await anyio.lowlevel.checkpoint_if_cancelled()
            while True:
                if self._closed:
                    raise anyio.ClosedResourceError
                now = anyio.current_time()
                bus._advance(now)
                if self._buffer:
                    data = bytes(self._buffer[:max_bytes])
                    del self._buffer[:max_bytes]
                    await anyio.lowlevel.cancel_shielded_checkpoint()
                    return data
                if bus._exhausted_for(self.index):
                    raise anyio.EndOfStream
                await bus._wait(now)

    def _take(self, max_bytes: int = 65536) -> bytes:
        """Return up to `max_bytes` of the bytes that already arrived (`b""` if none).

        Does not look at the clock: on a paced bus, bytes that are due but not yet delivered stay on
        the wire. For relays that deliver outside
        [`receive`][aiortu.testing.VirtualEndpoint.receive].
        """
        buffer = self._buffer
        if not buffer:
            return b""
        data = bytes(buffer[:max_bytes])
        del buffer[:max_bytes]
        return data

    async def send(self, item: bytes) -> None:
        """Put `item` on the wire after what is already there (see the module docs)."""
        await anyio.lowlevel.checkpoint()
        if self._closed:
            raise anyio.ClosedResourceError
        await self.bus._transmit(self, bytes(item))

    async def send_eof(self) -> None:
        """Not supported: a serial line has no half-close. Always raises NotImplementedError."""
        raise NotImplementedError("a serial line cannot send an end of file")

    def close(self) -> None:
        """Close this endpoint now; the others get nothing more from it. Safe to repeat."""
        if self._closed:
            return
        self._closed = True
        self._buffer.clear()
        self.bus._closing = True
        self.bus._notify()
        for endpoint in self.bus.endpoints:
            endpoint._check_lost()

    def _check_lost(self) -> None:
        """Tell a pushing endpoint's consumer, once, that
        [`receive`][aiortu.testing.VirtualEndpoint.receive] would now raise."""
        on_lost = self._on_lost
        if on_lost is None:
            return
        if self._closed or (not self._buffer and self.bus._exhausted_for(self.index)):
            self._on_lost = None
            on_lost()

    async def aclose(self) -> None:
        """Close this endpoint (see [`close`][aiortu.testing.VirtualEndpoint.close])."""
        self.close()
        await anyio.lowlevel.checkpoint()


class _PushingEndpoint(VirtualEndpoint):
    """An endpoint of a bus where nothing is ever held on the wire (see
    [`VirtualBus.pushes`][aiortu.testing.VirtualBus.pushes]): besides the byte stream, the push
    extension of the serial port (`set_receiver`, `send_nowait`), so that a link reads and writes it
    without a task wake-up per frame."""

    starts_between_frames = True
    """No frame is ever under way when a link starts reading: transmissions arrive whole,
    so its receiver need not wait for a first silence (INIT) and take the first request
    for the tail of an earlier frame."""

    def __init__(self, bus: VirtualBus, index: int, buffer_size: int) -> None:
        super().__init__(bus, index, buffer_size)
        self._receiver: Callable[[bytes], None] | None = None
        self._call_soon: Callable[[Callable[[], object]], object] | None = None
        self._clock: Callable[[], float] = anyio.current_time
        self._handing_over = False

    def set_receiver(
        self,
        receiver: Callable[[bytes], None] | None,
        on_lost: Callable[[], None] | None = None,
    ) -> None:
        """Hand what arrives to `receiver` from an event loop callback, instead of keeping it for
        [`receive`][aiortu.testing.VirtualEndpoint.receive] (`None` keeps it again). Call it in the
        event loop.

        The callback runs in the loop pass after the bytes were sent, never inside the sender's
        call, and hands over everything that arrived meanwhile in one chunk: a whole transmission,
        as a serial port's read would. Bytes already kept go to `receiver` at once. `on_lost` is
        called once [`receive`][aiortu.testing.VirtualEndpoint.receive] would raise (this endpoint
        closed, or every other one closed and everything they sent handed over), at once if it
        already would.
        """
        self._receiver = receiver
        self._on_lost = on_lost if receiver is not None else None
        if receiver is None:
            return
        waits = native_waits()  # the event loop's own call_soon and clock under asyncio
        self._call_soon, self._clock = waits.call_soon, waits.time
        if self._buffer:
            receiver(self._take(len(self._buffer)))
        self._check_lost()

    def send_nowait(self, item: bytes) -> bool:
        """Put `item` on the wire now, without a yield; return False (nothing sent) once
        this endpoint is closed. The other endpoints have it when this returns."""
        if self._closed:
            return False
        if item:
            self.bus._transmit_now(self, bytes(item), self._clock())
        return True

    def _push(self, data: bytes) -> None:
        super()._push(data)
        # One callback per loop pass, whatever arrived meanwhile: what a port's read does.
        if self._receiver is not None and not self._handing_over and not self._closed:
            assert self._call_soon is not None
            self._handing_over = True
            self._call_soon(self._hand_over)

    def _hand_over(self) -> None:
        self._handing_over = False
        receiver = self._receiver
        if receiver is None or self._closed:
            return
        if self._buffer:
            receiver(self._take(len(self._buffer)))
        if self.bus._closing:  # the end waits for the bytes sent before it
            self._check_lost()


class VirtualBus:
    """An in-memory multi-drop serial bus with `ports` endpoints (see the module docs).

    Raises [`InvalidValue`][aiortu.errors.InvalidValue] (caused by the caller) for a bad number
    of ports, chunk size, latency or buffer size.
    """

    def __init__(
        self,
        ports: int = 2,
        *,
        settings: LineSettings | None = None,
        chunk_size: int | None = None,
        latency: float = 0.0,
        faults: FaultPlan | None = None,
        receive_buffer_size: int = 65536,
        send_buffer_size: int = 4096,
        trace_size: int = 1000,
    ) -> None:
        _check_int("ports", ports, 1)
        if chunk_size is not None:
            _check_int("chunk_size", chunk_size, 1)
        if isinstance(latency, bool) or not isinstance(latency, int | float):
            raise InvalidValue("latency", latency, "a number of seconds >= 0")
        if not 0 <= latency < math.inf:
            raise InvalidValue("latency", latency, "a number of seconds >= 0")
        _check_int("receive_buffer_size", receive_buffer_size, 1)
        _check_int("send_buffer_size", send_buffer_size, 1)
        _check_int("trace_size", trace_size, 0)
        self.settings = settings
        """The line settings the bus paces at, or None for an unpaced bus."""
        self.chunk_size = chunk_size
        self.latency = float(latency)
        self.faults = faults
        self.injector: FaultInjector | None = (
            FaultInjector(faults) if faults is not None and not faults.is_clean else None
        )
        """The bus's fault injector (None without faults); its `stats` count the faults."""
        self.collisions = 0
        """Transmissions that started while another endpoint's bytes were on the wire."""
        self.trace: deque[TraceEntry] = deque(maxlen=trace_size)
        """The last bursts on the wire, oldest first."""
        # The one predicate of the shortcut: every condition under which it may run.
        self._pushes = (
            settings is None and self.injector is None and chunk_size is None and latency == 0
        )
        endpoint_class = _PushingEndpoint if self._pushes else VirtualEndpoint
        self.endpoints: tuple[VirtualEndpoint, ...] = tuple(
            endpoint_class(self, index, receive_buffer_size) for index in range(ports)
        )
        """The endpoints, by index."""
        self._char_time = settings.char_time if settings is not None else 0.0
        self._send_backlog = send_buffer_size * self._char_time
        self._segments: deque[_Segment] = deque()
        self._busy_until = -math.inf
        self._last_sender: int | None = None
        self._pending: list[tuple[int, bytes]] = []
        self._pending_count = 0
        self._pending_since = 0.0
        self._event: anyio.Event | None = None
        self._closed = False
        self._closing = False  # an endpoint was closed: pushing ones look for their end
        self._timer: WakeTimer | bool | None = False  # False: not made yet; None: none

    @property
    def pushes(self) -> bool:
        """Whether nothing is ever held on the wire (unpaced, no adapter model, no faults):
        then every byte sent is delivered before the send returns, and the endpoints also
        offer the serial port's push extension (`set_receiver`, `send_nowait`), which
        the master and the slave read and write without a task wake-up per frame."""
        return self._pushes

    @property
    def char_time(self) -> float:
        """Seconds per character on the wire (0 on an unpaced bus)."""
        return self._char_time

    @property
    def closed(self) -> bool:
        """True once the bus was closed."""
        return self._closed

    def __len__(self) -> int:
        return len(self.endpoints)

    def __getitem__(self, index: int) -> VirtualEndpoint:
        return self.endpoints[index]

    def __iter__(self) -> Iterator[VirtualEndpoint]:
        return iter(self.endpoints)

    async def __aenter__(self) -> VirtualBus:
        return self

    async def __aexit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        await self.aclose()

    def close(self) -> None:
        """Close every endpoint now. Safe to call from synchronous code and to repeat."""
        if self._closed:
            return
        self._closed = True
        for endpoint in self.endpoints:
            endpoint.close()
        self._segments.clear()
        self._pending.clear()
        self._pending_count = 0
        if isinstance(self._timer, WakeTimer):
            self._timer.close()
        self._timer = None

    async def aclose(self) -> None:
        """Close every endpoint (see [`close`][aiortu.testing.VirtualBus.close])."""
        self.close()
        await anyio.lowlevel.checkpoint()

    # --- the wire -------------------------------------------------------------------------

    def _changed(self) -> anyio.Event:
        if self._event is None:
            self._event = anyio.Event()
        return self._event

    async def _wait(self, now: float) -> None:
        """Wait until something changes or the next bytes are due (`now` is the time)."""
        event = self._changed()
        timer = self._timer
        if timer is False:
            timer = self._timer = self._make_timer()
        if timer is None or self._closed:
            with anyio.move_on_at(self._next_event_time()):
                await event.wait()
            return
        assert isinstance(timer, WakeTimer)
        timer.begin(asyncio.get_running_loop(), self._wake_time(now))
        try:
            await event.wait()
        finally:
            timer.end()

    def _make_timer(self) -> WakeTimer | None:
        """A precise wake-up timer if the bus runs in a standard asyncio loop on Linux."""
        if self._char_time == 0 and self.latency == 0:
            return None  # nothing is ever due later than it is sent
        return create_wake_timer(self._notify)

    def _wake_time(self, now: float) -> float:
        """When a receiver should look again: see "Wake-ups" in the module docs."""
        deadline = math.inf
        if self._segments:
            segment = self._segments[0]
            due = self._arrival(segment, segment.done)
            last = self._arrival(segment, len(segment.data) - 1)
            deadline = max(due, min(last, now + _BATCH))
        if self._pending and self.latency > 0:
            deadline = min(deadline, self._pending_since + self.latency)
        return deadline

    def _notify(self) -> None:
        event, self._event = self._event, None
        if event is not None:
            event.set()

    def _exhausted_for(self, index: int) -> bool:
        if self._segments or self._pending:
            return False
        return all(e.closed for e in self.endpoints if e.index != index)

    async def _transmit(self, sender: VirtualEndpoint, data: bytes) -> None:
        if not data:
            return
        while self._send_backlog and self._busy_until - anyio.current_time() > self._send_backlog:
            await anyio.sleep_until(self._busy_until - self._send_backlog)
            if sender.closed:
                raise anyio.ClosedResourceError
        self._transmit_now(sender, data, anyio.current_time())

    def _transmit_now(self, sender: VirtualEndpoint, data: bytes, now: float) -> None:
        """Put `data` on the wire at `now`, without waiting for room in the send buffer.

        On an unpaced bus without adapter model or faults, everything is delivered to the
        other endpoints' receive buffers before this returns.
        """
        if self._pushes:
            # Nothing is ever held on such a wire (no pacing, adapter or faults), so the
            # schedule below would deliver the bytes at once: do it without building it.
            index = sender.index
            self._record(now, now, index, data)
            self._busy_until = now
            self._last_sender = index
            self._deliver(index, data)
            self._notify()
            return
        self._advance(now)
        chunk = (
            self.injector.apply(data, self._char_time)
            if self.injector is not None
            else FaultedChunk(0.0, [data])
        )
        ready = now + chunk.delay
        if self._busy_until > ready + _EPSILON and self._last_sender not in (None, sender.index):
            self.collisions += 1
        start = max(ready, self._busy_until)
        moment = start
        for item in chunk.items:
            if isinstance(item, float):
                moment += item
            else:
                self._segments.append(_Segment(moment, item, sender.index))
                moment += len(item) * self._char_time
        self._record(start, moment, sender.index, chunk.data)
        self._busy_until = moment
        self._last_sender = sender.index
        self._advance(now)
        self._notify()

    def _record(self, start: float, end: float, sender: int, data: bytes) -> None:
        if self.trace.maxlen == 0:
            return
        if self.trace:
            last = self.trace[-1]
            if last.sender == sender and start <= last.end + _EPSILON:
                self.trace[-1] = TraceEntry(last.start, end, sender, last.data + data)
                return
        self.trace.append(TraceEntry(start, end, sender, data))

    def _arrival(self, segment: _Segment, index: int) -> float:
        return segment.start + (index + 1) * self._char_time

    def _next_event_time(self) -> float:
        deadline = math.inf
        if self._segments:
            segment = self._segments[0]
            deadline = self._arrival(segment, segment.done)
        if self._pending and self.latency > 0:
            deadline = min(deadline, self._pending_since + self.latency)
        return deadline

    def _advance(self, now: float) -> None:
        """Deliver everything due by `now`, in wire order."""
        delivered = False
        char_time = self._char_time
        while self._segments:
            segment = self._segments[0]
            size = len(segment.data)
            if char_time == 0:
                arrived = size if now + _EPSILON >= segment.start else 0
            else:
                arrived = min(size, math.floor((now - segment.start) / char_time + _EPSILON))
            if arrived <= segment.done:
                break
            self._feed(segment, segment.done, arrived)
            segment.done = arrived
            delivered = True
            if arrived < size:
                break
            self._segments.popleft()
        if self._pending and now + _EPSILON >= self._pending_since + self.latency:
            self._flush()
            delivered = True
        if delivered:
            self._notify()

    def _feed(self, segment: _Segment, first: int, stop: int) -> None:
        """Pass bytes [first, stop) of `segment` through the adapter model."""
        data = segment.data
        if self.chunk_size is None and self.latency == 0:
            self._deliver(segment.sender, data[first:stop])
            return
        char_time = self._char_time
        index = first
        while index < stop:
            arrival = self._arrival(segment, index)
            expired = arrival > self._pending_since + self.latency + _EPSILON
            if self._pending and self.latency > 0 and expired:
                self._flush()
            if not self._pending:
                self._pending_since = arrival
            take = stop - index
            if self.chunk_size is not None:
                take = min(take, self.chunk_size - self._pending_count)
            if self.latency > 0 and char_time > 0:
                deadline = self._pending_since + self.latency
                in_time = math.floor((deadline - segment.start) / char_time + _EPSILON) - index
                take = max(1, min(take, in_time))
            self._pending.append((segment.sender, data[index : index + take]))
            self._pending_count += take
            index += take
            if self.chunk_size is not None and self._pending_count >= self.chunk_size:
                self._flush()
        if self.latency == 0:
            self._flush()

    def _flush(self) -> None:
        pieces = self._pending
        self._pending = []
        self._pending_count = 0
        for endpoint in self.endpoints:
            data = b"".join(piece for sender, piece in pieces if sender != endpoint.index)
            if data:
                endpoint._push(data)

    def _deliver(self, sender: int, data: bytes) -> None:
        for endpoint in self.endpoints:
            if endpoint.index != sender:
                endpoint._push(data)


def virtual_pair(
    *,
    settings: LineSettings | None = None,
    chunk_size: int | None = None,
    latency: float = 0.0,
    faults: FaultPlan | None = None,
) -> tuple[VirtualEndpoint, VirtualEndpoint]:
    """Return the two endpoints of a new two-port [`VirtualBus`][aiortu.testing.VirtualBus] (a
    point-to-point line).

    The options are the bus's; each endpoint's `bus` attribute reaches the bus (for its
    trace, collisions and fault statistics).
    """
    bus = VirtualBus(2, settings=settings, chunk_size=chunk_size, latency=latency, faults=faults)
    return bus.endpoints[0], bus.endpoints[1]

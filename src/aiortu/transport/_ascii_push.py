"""Modbus ASCII on a stream that pushes its bytes: each frame handed over from the event loop's
read callback.

An [`AsciiStream`][aiortu.transport.AsciiStream] is read by a task: the link's reader awaits
`receive()`, which awaits the port. Where the stream underneath pushes its bytes (the serial
port; see [`PushStream`][aiortu.transport.PushStream]) and the loop is asyncio,
[`ascii_stream`][aiortu.transport.ascii_stream] makes a
[`PushAsciiStream`][aiortu.transport.PushAsciiStream] instead. It implements the push extension
itself, so the [`Link`][aiortu.line.Link] takes its push path over ASCII as it does over RTU:
each chunk goes through the same ASCII receiver from the port's read callback, and each frame
whose LRC checks reaches the link there, as one RTU frame, with no task wake-up; frames go out
without a yield. The master's usual exchange and the slave's answer-at-once then run over ASCII.

Nothing else differs: the same receiver table and its inter-character timeout (one event loop
timer, armed while a frame is under way), the same counters, the same 08/03 delimiter rules
(the shared [`frames`][aiortu.transport.AsciiStream.frames] and
[`sent`][aiortu.transport.AsciiStream.sent]). `pushes_ascii` is the one predicate that picks
this stream; the differential tests run the same exchanges through both.
"""

from __future__ import annotations

import asyncio
import math
import time
from collections.abc import Callable

import anyio.abc

from aiortu.core.ascii import DEFAULT_ASCII_TIMEOUT, LF, AsciiState
from aiortu.core.serial import LineSettings
from aiortu.transport._ascii_stream import AsciiStream
from aiortu.transport._push import PushStream

__all__ = ("PushAsciiStream", "ascii_stream", "pushes_ascii")


def pushes_ascii(stream: anyio.abc.ByteStream) -> bool:
    """Whether Modbus ASCII on `stream` is pushed: every condition is a line here."""
    try:
        asyncio.get_running_loop()
    except RuntimeError:
        return False  # the timer of the inter-character timeout is an asyncio one
    # The stream underneath hands over its bytes from a callback (the serial port does).
    return isinstance(stream, PushStream)


def ascii_stream(
    stream: anyio.abc.ByteStream,
    settings: LineSettings | None = None,
    *,
    timeout: float = DEFAULT_ASCII_TIMEOUT,
    delimiter: int = LF,
    answering: bool = False,
) -> AsciiStream:
    """Modbus ASCII on `stream`: a [`PushAsciiStream`][aiortu.transport.PushAsciiStream] where
    `pushes_ascii` allows it, else an [`AsciiStream`][aiortu.transport.AsciiStream] (the same
    arguments)."""
    kind = PushAsciiStream if pushes_ascii(stream) else AsciiStream
    return kind(stream, settings, timeout=timeout, delimiter=delimiter, answering=answering)


class PushAsciiStream(AsciiStream, PushStream):
    """An [`AsciiStream`][aiortu.transport.AsciiStream] that pushes its frames (see the module
    docstring). Made by [`ascii_stream`][aiortu.transport.ascii_stream]; `receive()` and `send()`
    work as well, as the push extension asks."""

    def __init__(
        self,
        stream: anyio.abc.ByteStream,
        settings: LineSettings | None = None,
        *,
        timeout: float = DEFAULT_ASCII_TIMEOUT,
        delimiter: int = LF,
        answering: bool = False,
    ) -> None:
        super().__init__(
            stream, settings, timeout=timeout, delimiter=delimiter, answering=answering
        )
        assert isinstance(stream, PushStream)
        self._inner: PushStream = stream
        self._on_frame: Callable[[bytes], None] | None = None
        self._on_lost: Callable[[], None] | None = None
        self._loop: asyncio.AbstractEventLoop | None = None
        self._clock: Callable[[], float] = time.monotonic
        self._timer: asyncio.TimerHandle | None = None
        self._timer_deadline = -math.inf
        self._failure: BaseException | None = None

    def set_receiver(
        self,
        receiver: Callable[[bytes], None] | None,
        on_lost: Callable[[], None] | None = None,
    ) -> None:
        """The push extension: hand each frame received, as an RTU frame, to `receiver` from the
        read callback (`None`: keep them for `receive()` again)."""
        self._on_frame = receiver
        self._on_lost = on_lost
        self._cancel_timer()
        if receiver is None:
            self._inner.set_receiver(None)
            return
        loop = self._loop = asyncio.get_running_loop()
        # asyncio's own loops tell time.monotonic(): read it without the method call.
        own_time = type(loop).time is asyncio.BaseEventLoop.time
        self._clock = time.monotonic if own_time else loop.time
        while self._ready:
            receiver(self._ready.popleft())
        self._inner.set_receiver(self._on_chunk, on_lost)
        self._arm_timer()

    def send_nowait(self, item: bytes) -> bool:
        """The push extension: send the RTU frame `item` as one ASCII frame now, if the stream
        underneath takes it without a yield."""
        if not self._inner.send_nowait(self.encode(item)):
            return False
        if self.answering:  # only a slave's replies change anything (08/03)
            self.sent(item)
        return True

    async def receive(self, max_bytes: int = 65536) -> bytes:
        """As [`AsciiStream.receive`][aiortu.transport.AsciiStream.receive]; raises what failed in
        the read callback (a bug), once the link asks why the stream ended."""
        if self._failure is not None:
            raise self._failure
        return await super().receive(max_bytes)

    def _on_chunk(self, data: bytes) -> None:
        """The read callback of the stream underneath; with no `data`, the timer's."""
        try:
            outputs = self.receiver.feed(data, self._clock())  # no data: expire, if due
            if outputs:
                for frame in self.frames(outputs):
                    on_frame = self._on_frame  # the link may stop taking them meanwhile
                    if on_frame is None:
                        self._ready.append(frame)
                    else:
                        on_frame(frame)
            if self._timer is not None or self.receiver.state is not AsciiState.IDLE:
                self._arm_timer()  # a frame under way, or one that just ended
        except BaseException as error:  # a bug: end the link's reader with it
            self._failure = error
            self._inner.set_receiver(None)
            if self._on_lost is not None:
                self._on_lost()

    def _on_timer(self) -> None:
        """The inter-character timeout of the frame under way has come."""
        self._timer = None
        self._on_chunk(b"")

    def _arm_timer(self) -> None:
        """Keep one loop timer at the receiver's next deadline (none while idle)."""
        deadline = self.receiver.next_deadline()
        if deadline == self._timer_deadline and self._timer is not None:
            return
        self._cancel_timer()
        if deadline is not None and self._loop is not None:
            self._timer_deadline = deadline
            self._timer = self._loop.call_at(deadline, self._on_timer)

    def _cancel_timer(self) -> None:
        if self._timer is not None:
            self._timer.cancel()
            self._timer = None

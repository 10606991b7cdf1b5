"""The link's push reader: chunks handed over from the event loop's read callback.

A stream that pushes its bytes (a [`PushStream`][aiortu.transport.PushStream], as the serial port
is) calls `PushReader.on_chunk` with each chunk, and the receiver's silence deadline is one event
loop timer, armed and cancelled here. The link's reader task only waits for the stream's end, so a
chunk costs no task wake-up.

Two taps take frames of a known layout before the receiver builds an event for them: the reply a
master waits for ([`Link.expect`][aiortu.line.Link.expect], once) and the requests a slave answers
at once ([`Link.expect_requests`][aiortu.line.Link.expect_requests], every time). On a direct link
(whole frames, no frame gap: [`Link.direct`][aiortu.line.Link]) the stream calls `on_frame`
instead, which takes the reply expected with the receiver's check alone and hands anything else
to `on_chunk`.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Container
from dataclasses import dataclass
from typing import Any, Protocol

import anyio
import anyio.abc

from aiortu.core.rtu import FrameDiscarded, FrameReceived, Receiver
from aiortu.line._sender import LineActivity

__all__ = ("PushReader", "ReplyTap", "RequestTap")

FrameTaker = Callable[[bytes, float], None]
"""Called with a frame whose CRC checks and the time its last byte arrived."""


@dataclass(slots=True)
class ReplyTap:
    """The one reply a master waits for (see [`Link.expect`][aiortu.line.Link.expect]):
    `on_frame(frame, end)` takes it."""

    prefix: bytes
    """The reply's first bytes."""
    length: int
    """The reply's length in bytes."""
    on_frame: FrameTaker
    checked: bytes | None
    """A reply of the same layout whose CRC is known to be good (not checked again)."""


@dataclass(slots=True)
class RequestTap:
    """The requests a slave answers at once (see
    [`Link.expect_requests`][aiortu.line.Link.expect_requests])."""

    codes: Container[int]
    """The function codes taken."""
    length: int
    """The length of every request with one of those codes."""
    on_request: FrameTaker


class _Link(Protocol):
    """What the push reader uses of its [`Link`][aiortu.line.Link]."""

    stream: anyio.abc.ByteStream
    clock: Callable[[], float]
    receiver: Receiver
    backend: type[anyio.abc.AsyncBackend] | None
    frames_received: int
    direct: bool
    _activity: LineActivity

    def _deliver(self, events: list[FrameReceived | FrameDiscarded]) -> None: ...

    def call_at(self, when: float, callback: Callable[..., object], *args: object) -> Any: ...


class PushReader:
    """Takes the chunks a push stream hands over, for one link."""

    __slots__ = ("error", "link", "lost", "reply_tap", "request_tap", "timer", "timer_deadline")

    def __init__(self, link: _Link) -> None:
        self.link = link
        self.reply_tap: ReplyTap | None = None
        self.request_tap: RequestTap | None = None
        self.timer: Any = None
        """The event loop timer at the receiver's next deadline, if it has one."""
        self.timer_deadline = -math.inf
        self.lost: anyio.Event | None = None
        """Set when the stream ends, or a callback failed."""
        self.error: BaseException | None = None
        """What failed in a callback (a bug): the reader task raises it."""

    async def run(self, set_receiver: Callable[..., None]) -> None:
        """Take chunks until the stream ends; raise what ended it."""
        link = self.link
        assert link.backend is not None
        lost = self.lost = link.backend.create_event()
        try:
            set_receiver(self.on_frame if link.direct else self.on_chunk, lost.set)
            self.arm_timer()
            await lost.wait()
            if self.error is not None:
                raise self.error
            await link.stream.receive()  # raises why the stream ended
        finally:
            set_receiver(None)
            if self.timer is not None:
                self.timer.cancel()
                self.timer = None

    def on_chunk(self, chunk: bytes) -> None:
        """The stream's read callback."""
        link = self.link
        try:
            now = link.clock()
            link._activity.received(now)
            # A chunk of the layout the master expects (once) or the slave takes (each
            # time) goes straight to them once the receiver has checked its CRC.
            reply = self.reply_tap
            request = self.request_tap
            take = checked = None
            if reply is not None and len(chunk) == reply.length and chunk.startswith(reply.prefix):
                take = reply.on_frame
                checked = reply.checked
            elif request is not None and len(chunk) == request.length and chunk[1] in request.codes:
                take = request.on_request
                reply = None
            if take is not None and link.receiver.take_expected_frame(chunk, now, checked):
                if reply is not None:
                    self.reply_tap = None  # expect() hands over one frame only
                link.frames_received += 1
                take(chunk, now)
                if self.timer is None:
                    return  # an idle receiver has no deadline: no timer to arm
            else:
                events = link.receiver.feed(chunk, now)
                if events:
                    link._deliver(events)
            self.arm_timer()
        except BaseException as error:  # a bug: the reader task raises it
            self.fail(error)

    def on_frame(self, frame: bytes) -> None:
        """A direct link's read callback (see [`Link.direct`][aiortu.line.Link]): each chunk is
        one whole frame. The reply the master expects is taken as `on_chunk` takes it, without
        the rest of its work; anything else goes to `on_chunk`. The receiver's timer is not
        touched: the receiver takes the reply only while IDLE, when it has no deadline, and
        so no timer (`arm_timer` keeps one exactly while it has one). A reply right behind a
        frame that armed the timer finds the receiver mid-frame and goes to `on_chunk`."""
        tap = self.reply_tap
        if tap is None or len(frame) != tap.length or not frame.startswith(tap.prefix):
            self.on_chunk(frame)
            return
        link = self.link
        try:
            now = link.clock()
            if not link.receiver.take_expected_frame(frame, now, tap.checked):
                self.on_chunk(frame)
                return
            # No wire: our own frame has left the line (`LineActivity.received`).
            link._activity.last_received = now
            self.reply_tap = None
            link.frames_received += 1
            tap.on_frame(frame, now)  # an idle receiver has no timer to move
        except BaseException as error:  # a bug: the reader task raises it
            self.fail(error)

    def on_timer(self) -> None:
        """The receiver's deadline has come."""
        self.timer = None
        link = self.link
        try:
            events = link.receiver.expire(link.clock())
            if events:
                link._deliver(events)
            self.arm_timer()
        except BaseException as error:
            self.fail(error)

    def fail(self, error: BaseException) -> None:
        """A callback failed: end the reader with `error`."""
        if self.error is None:
            self.error = error
        if self.lost is not None:
            self.lost.set()

    def arm_timer(self) -> None:
        """Keep one loop timer at the receiver's next deadline (none without one)."""
        deadline = self.link.receiver.next_deadline()
        timer = self.timer
        if timer is not None:
            if deadline == self.timer_deadline:
                return
            timer.cancel()
            self.timer = None
        if deadline is None:
            return
        self.timer_deadline = deadline
        self.timer = self.link.call_at(deadline, self.on_timer)

"""The link's sender side: whose turn it is to send, and waits for the line to fall silent.

[`Link.send`][aiortu.line.Link.send] takes a turn from `SendTurns` (no yield when nobody
else is sending: a master's line has a single sender), and waits for the spec's silence with
`SilenceWaits`, which ends the wait on a [`WakeTimer`][aiortu.line.WakeTimer] where the loop
can watch one, and calls back once the silence has passed for a sender that is no task (the
master's fast path, run from the link's read callback). `LineActivity` is when the line was
last busy in each direction, which the reader moves on every chunk and the sender on every
frame.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import anyio
import anyio.abc
import anyio.lowlevel

from aiortu.line._wake_timer import WakeTimer, create_wake_timer

__all__ = ("LineActivity", "QuietCall", "SendTurns", "SilenceWaits")


@dataclass(slots=True)
class LineActivity:
    """When the line was last busy, in the link's clock."""

    last_received: float = -math.inf
    """When the last chunk arrived."""
    transmit_end: float = -math.inf
    """When the last frame sent will have left the wire (or earlier, once a byte came back)."""

    def received(self, now: float) -> None:
        """A chunk arrived at `now`."""
        self.last_received = now
        # The line is half duplex: a byte received proves our own frame has left it, even
        # where the wire time estimate says otherwise (virtual lines deliver faster than the
        # baud rate).
        self.transmit_end = min(self.transmit_end, now)


class SendTurns:
    """One sender at a time, in the order they came."""

    __slots__ = ("busy", "waiters")

    def __init__(self) -> None:
        self.busy = False
        """Whether someone holds the turn (it stays true while it passes from one to the next)."""
        self.waiters: list[anyio.Event] = []

    async def wait(self, backend: type[anyio.abc.AsyncBackend] | None) -> None:
        """Wait until the turn is handed over (call only while `busy`)."""
        turn = anyio.Event() if backend is None else backend.create_event()
        self.waiters.append(turn)
        try:
            await turn.wait()
        except BaseException:
            if turn.is_set():
                self.pass_on()  # handed the turn, yet gone: pass it on
            else:
                self.waiters.remove(turn)
            raise

    def pass_on(self) -> None:
        """The holder is done: hand the turn to the next waiter, or free it."""
        if self.waiters:
            self.waiters.pop(0).set()  # the turn passes; busy stays true
        else:
            self.busy = False


class SilenceWaits:
    """Waits for the line to have been quiet long enough (see
    [`Link.wait_for_silence`][aiortu.line.Link.wait_for_silence])."""

    __slots__ = ("__weakref__", "call", "loop", "timer", "tried", "waiters")

    def __init__(self) -> None:
        self.timer: WakeTimer | None = None
        self.tried = False
        """Whether a timer was tried: once per link, on first use."""
        self.loop: Any = None
        """The event loop the timer is watched by."""
        self.waiters: list[Any] = []
        """The loop futures of the waits under way on the timer."""
        self.call: QuietCall | None = None
        """The callback waiting for the silence (see `call_when_quiet`)."""

    async def wait(
        self, activity: LineActivity, clock: Callable[[], float], silence: float
    ) -> None:
        """Wait until neither side has used the line for `silence` seconds (no yield when it
        already has)."""
        while True:
            # Bytes that arrive meanwhile move the end of the silence: look again on waking.
            quiet_at = max(activity.last_received, activity.transmit_end) + silence
            remaining = quiet_at - clock()
            if remaining <= 0:
                return
            if not self.tried:
                self._make_timer()
            timer = self.timer
            if timer is None:
                await anyio.sleep(remaining)
            elif clock is time.monotonic:
                await self._wait_for_timer(timer, quiet_at)
            else:
                await self._wait_for_timer(timer, time.monotonic() + remaining)

    def _make_timer(self, loop: Any = None) -> None:
        """Make the wake timer, on the running loop (`loop`: from a callback, where anyio
        cannot tell the backend)."""
        self.tried = True
        timer = create_wake_timer(self._on_timer)
        if timer is not None:
            self.loop = loop if loop is not None else anyio.lowlevel.current_token().native_token
            self.timer = timer

    def call_when_quiet(
        self, loop: Any, activity: LineActivity, clock: Callable[[], float], silence: float,
        callback: Callable[[], object],
    ) -> None:  # fmt: skip
        """Have `loop` call `callback()` once neither side has used the line for `silence`
        seconds: on the wake timer where there is one (at the time itself), else on the
        loop's timers. One call at a time (a second replaces the first); `cancel_call`
        undoes it."""
        self.cancel_call()
        self.call = QuietCall(loop, activity, clock, silence, callback)
        self._arm_call()

    def _arm_call(self) -> None:
        """Call the waiting callback if the silence has passed, else wait for it (bytes
        that arrived meanwhile move its end: look again on waking)."""
        call = self.call
        assert call is not None
        call.handle = None
        activity = call.activity
        remaining = max(activity.last_received, activity.transmit_end) + call.silence - call.clock()
        if remaining <= 0:
            self.call = None
            call.callback()
            return
        if not self.tried:
            self._make_timer(call.loop)
        timer = self.timer
        if timer is None:
            call.handle = call.loop.call_later(remaining, self._arm_call)
        else:
            timer.begin(self.loop, time.monotonic() + remaining)
            call.on_timer = True

    def cancel_call(self) -> None:
        """Forget the callback waiting for the silence, if any."""
        call, self.call = self.call, None
        if call is None:
            return
        if call.on_timer and self.timer is not None:
            self.timer.end()
        if call.handle is not None:
            call.handle.cancel()

    async def _wait_for_timer(self, timer: WakeTimer, when: float) -> None:
        """Wait until `timer` goes off: at `when` (`time.monotonic()` seconds), or earlier for
        another waiter's deadline, or when the link closes."""
        loop = self.loop
        woken = loop.create_future()
        timer.begin(loop, when)
        self.waiters.append(woken)
        try:
            await woken
        finally:
            self.waiters.remove(woken)
            timer.end()

    def _on_timer(self) -> None:
        for woken in self.waiters:
            if not woken.done():
                woken.set_result(None)
        call = self.call
        if call is not None and call.on_timer:
            call.on_timer = False
            if self.timer is not None:
                self.timer.end()
            self._arm_call()

    def close(self) -> None:
        """Close the timer; whoever waits on it finishes the wait on the event loop's timers."""
        timer = self.timer
        self.timer = None
        self.tried = True  # a closing link makes no new one
        if timer is not None:
            timer.close()
            call = self.call
            if call is not None:
                call.on_timer = False  # the closed timer has no waiter to end
            self._on_timer()
            if self.call is not None:
                self._arm_call()  # on the loop's timers now


@dataclass(slots=True)
class QuietCall:
    """A callback waiting for the line to fall silent (see `SilenceWaits.call_when_quiet`)."""

    loop: Any
    activity: LineActivity
    clock: Callable[[], float]
    silence: float
    callback: Callable[[], object]
    on_timer: bool = False
    """Whether it waits on the wake timer (one of its waiters)."""
    handle: Any = None
    """The loop timer it waits on instead."""

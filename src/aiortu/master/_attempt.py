"""One attempt on a master's line, through the machine: the request sent, the wait for what
answers it with its timer, and the late-reply guard kept after a failed attempt.

`Attempts` feeds what the link delivered (`Attempts.deliver`, from the engine's link
listener) and the clock to the [`MasterMachine`][aiortu.core.machines.MasterMachine]
until it has an outcome. One event loop timer serves every wait (`Attempts.arm`): armed for
the earliest deadline, it is armed again for the current one if it fires before it, so a
read that ends in time costs no timer of its own. Without an event loop (trio) a wait is a
cancel scope with a deadline.

After a failed attempt (timeout or frame error) nothing goes out, the retry included, until
the line has been silent for the late-reply guard (`guard_ends`).
"""

from __future__ import annotations

import math
from collections import deque
from collections.abc import Callable
from typing import Any

import anyio

from aiortu.core.machines import (
    MasterMachine,
    Outcome,
    OutcomeKind,
    SkipReason,
    frame_error_from_discard,
)
from aiortu.core.rtu import FrameReceived
from aiortu.errors import ConnectionLost
from aiortu.line import Link, LinkEvent
from aiortu.master._stats import UnitStats

__all__ = ("NO_GUARD", "Attempts", "guard_ends")

NO_GUARD = -math.inf
"""`Attempts.guard_until` when no guard is pending."""


def guard_ends(quiet_until: float, last_activity: float, guard: float) -> float:
    """When the late-reply guard is kept: `guard` seconds of silence on the line after
    the failure that set `quiet_until` (the failure plus `guard`).

    Bytes that arrive meanwhile (`last_activity`: the line's last byte) start the silence
    again, at most once over: a line that never falls silent delays a request by two
    guards, not for ever.
    """
    return max(quiet_until, min(last_activity, quiet_until) + guard)


class Attempts:
    """The attempts on one line, one at a time (see the module docstring).

    `on_time_up` is called when the timer reaches `deadline` and no attempt of the machine
    waits (the fast path's exchange is on the wire then: see
    [`aiortu.master`][aiortu.master]).
    """

    __slots__ = (
        "_on_time_up",
        "_timer",
        "arrival",
        "deadline",
        "events",
        "guard_seconds",
        "guard_until",
        "link",
        "machine",
        "timer_at",
        "waiter",
    )

    def __init__(
        self,
        link: Link,
        machine: MasterMachine,
        late_reply_guard: float,
        on_time_up: Callable[[], None],
    ) -> None:
        self.link = link
        self.machine = machine
        self.events: deque[LinkEvent] = deque()
        """What the link delivered, not yet examined."""
        self.waiter: Any = None
        """The event loop future an attempt waits on, where the link has a loop."""
        self.arrival: anyio.Event | None = None
        """The event an attempt waits on elsewhere."""
        self.deadline = math.inf
        """When the wait in progress ends."""
        self._timer: Any = None
        self.timer_at = math.inf
        """When the timer fires (infinity: not armed)."""
        self._on_time_up = on_time_up
        self.guard_seconds = late_reply_guard
        self.guard_until = NO_GUARD
        """The failure plus the guard, until a request has kept the guard."""

    # -- what the link delivers, and the clock ------------------------------------------------

    def deliver(self, event: LinkEvent | None) -> None:
        """Keep `event` (None: the link is closed) and wake the attempt that waits."""
        if event is not None:
            events = self.events
            if len(events) >= self.link.queue_size:
                events.popleft()  # the newest frame is the one a waiting master wants
                self.link.events_dropped += 1
            events.append(event)
        waiter = self.waiter
        if waiter is not None and not waiter.done():
            waiter.set_result(None)
        arrival = self.arrival
        if arrival is not None:
            arrival.set()

    def arm(self, deadline: float) -> None:
        """End the wait in progress at `deadline`."""
        self.deadline = deadline
        if deadline < self.timer_at:
            timer = self._timer
            if timer is not None:
                timer.cancel()
            self.timer_at = deadline
            self._timer = self.link.call_at(deadline, self._fire)

    def _fire(self) -> None:
        self._timer, self.timer_at = None, math.inf
        deadline = self.deadline
        if deadline == math.inf:
            return  # nothing waits
        if self.link.clock() < deadline:
            self.arm(deadline)  # fired for an earlier wait
            return
        waiter = self.waiter
        if waiter is not None:
            if not waiter.done():
                waiter.set_result(None)
        else:
            self.deadline = math.inf
            self._on_time_up()

    def stop_timer(self) -> None:
        """Nothing waits any more: leave no timer armed on the loop."""
        self.deadline = math.inf
        if self._timer is not None:
            self._timer.cancel()
            self._timer, self.timer_at = None, math.inf

    # -- sending ------------------------------------------------------------------------------

    def start_guard(self) -> None:
        """An attempt failed: nothing goes out until the late-reply guard is kept."""
        self.guard_until = self.link.clock() + self.guard_seconds

    async def keep_guard(self) -> None:
        """Wait until the line has been silent for the guard after the last failed attempt
        (see `guard_ends`), then clear the guard. Raises the link's ConnectionLost at once
        if it closes meanwhile, as a wait for a reply does, and clears the guard then too:
        no late reply comes on the line that replaces it."""
        link = self.link
        while True:
            if link.closed:
                self.guard_until = NO_GUARD
                raise link.connection_lost_error()
            end = guard_ends(self.guard_until, link.last_activity, self.guard_seconds)
            delay = end - link.clock()
            if delay <= 0:
                break
            # Not a bare sleep: `deliver` wakes it, a byte (the guard starts again) or the
            # link's close (the request fails now, not once the guard is over).
            arrival = self.arrival = anyio.Event()
            try:
                with anyio.move_on_after(delay):
                    await arrival.wait()
            finally:
                self.arrival = None
        self.guard_until = NO_GUARD

    def send_at_once(self) -> bool:
        """Send the machine's frame now where the line lets it go without a wait, and tell
        the machine; else send nothing."""
        machine = self.machine
        link = self.link
        frame = machine.frame
        self.events.clear()  # nothing that came before can answer it
        end = link.send_now(frame)
        if end is None:
            return False
        machine.sent(end - len(frame) * link.char_time, end)
        return True

    async def send(self) -> None:
        """Send the machine's frame once the guard is kept and the line lets it go, and
        tell the machine when it went out.

        Cancelled after the frame began to go out, it tells the machine all the same (the
        machine then waits for the reply, which the caller must see to) and raises."""
        if self.guard_until != NO_GUARD:
            await self.keep_guard()
        if self.send_at_once():
            return
        machine = self.machine
        link = self.link
        frame = machine.frame
        wire_time = len(frame) * link.char_time
        writes = link.writes_begun
        try:
            end = await link.send(frame)
        except ConnectionLost:
            raise
        except BaseException:
            if link.writes_begun != writes:
                start = link.last_write_start  # the frame may be on its way
                machine.sent(start, start + wire_time)
            raise
        machine.sent(end - wire_time, end)

    # -- waiting ------------------------------------------------------------------------------

    async def outcome(self, stats: UnitStats) -> Outcome:
        """Wait for the outcome of the attempt on the wire, counting the frames skipped
        meanwhile in `stats`. Raises the link's ConnectionLost if it closes."""
        machine = self.machine
        link = self.link
        clock = link.clock
        events = self.events
        while True:
            while events:
                outcome = self._examine(events.popleft())
                skipped = outcome.skipped
                if skipped is not None:
                    stats.skipped_frames += 1
                    if skipped is SkipReason.LATE:
                        stats.late_replies += 1
                if outcome.kind is not OutcomeKind.WAIT:
                    return outcome
            if link.closed:
                raise link.connection_lost_error()
            deadline = machine.deadline
            assert deadline is not None
            now = clock()
            if now >= deadline:
                outcome = machine.expired(now)
                if outcome.kind is not OutcomeKind.WAIT:
                    return outcome
                continue
            loop = link.loop
            if loop is not None:
                # A future of the link's loop, completed by `deliver` or the timer (here,
                # not in a coroutine of its own: one frame less on every wake-up).
                waiter = self.waiter = loop.create_future()
                self.arm(deadline)
                try:
                    await waiter
                finally:
                    self.waiter = None
                    self.deadline = math.inf
                continue
            await self._wait_without_loop(deadline, now)

    async def _wait_without_loop(self, deadline: float, now: float) -> None:
        """Wait until something is delivered or `deadline` passes, on a backend without
        an asyncio loop (trio): an anyio event and a cancel scope."""
        link = self.link
        backend = link.backend
        assert backend is not None
        if not link.backend_clock:
            deadline = backend.current_time() + (deadline - now)
        arrival = self.arrival = backend.create_event()
        try:
            with backend.create_cancel_scope(deadline=deadline):
                await arrival.wait()
        finally:
            self.arrival = None

    def _examine(self, event: LinkEvent) -> Outcome:
        """Feed `event` to the machine."""
        if isinstance(event, FrameReceived):
            frame = event.frame
            return self.machine.frame_received(frame[0], frame[1:-2], event.start, event.end)
        error = frame_error_from_discard(event.data, str(event.reason))
        return self.machine.frame_error(error, event.end)

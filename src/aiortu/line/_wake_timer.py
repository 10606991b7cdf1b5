"""A wake-up timer for asyncio on Linux that fires at the exact time, not on the next millisecond.

asyncio's selector event loops hand their timeout to `epoll_wait`, which counts whole
milliseconds, and round it up so as never to wake early: a wait of 1.75 ms ends after 2 ms.
On a serial line that is a large share of a frame gap (t3.5 is 1.75 ms from 19200 baud
up), added to every wait. A [`WakeTimer`][aiortu.line.WakeTimer] is a Linux `timerfd` that the loop
watches as a reader: the kernel makes it readable at the deadline, to the nanosecond,
and epoll returns at once.

Deadlines are `time.monotonic()` seconds, the clock of asyncio's own event loops (both are
`CLOCK_MONOTONIC`). [`create_wake_timer`][aiortu.line.create_wake_timer] returns a timer only where
all of that holds; elsewhere (other systems, trio, uvloop and other loops with their own clock or
selector) it returns `None` and the caller waits with the event loop's own timers.

The link ends its frame gap on one
([`aiortu.line.Link.wait_for_silence`][aiortu.line.Link.wait_for_silence]), and a paced
[`VirtualBus`][aiortu.testing.VirtualBus] wakes its receivers with one.
"""

from __future__ import annotations

import asyncio
import ctypes
import functools
import math
import os
import sys
import time
import weakref
from collections.abc import Callable

__all__ = ("WakeTimer", "create_wake_timer")


class _Timespec(ctypes.Structure):
    _fields_ = (("tv_sec", ctypes.c_long), ("tv_nsec", ctypes.c_long))


class _Itimerspec(ctypes.Structure):
    _fields_ = (("it_interval", _Timespec), ("it_value", _Timespec))


_CLOCK_MONOTONIC = 1
_TFD_TIMER_ABSTIME = 1


@functools.cache
def _timerfd_libc() -> ctypes.CDLL | None:
    """The C library, if it has timerfd and the loop clock is CLOCK_MONOTONIC."""
    implementation = time.get_clock_info("monotonic").implementation
    if not sys.platform.startswith("linux") or "CLOCK_MONOTONIC" not in implementation:
        return None
    try:
        libc = ctypes.CDLL(None, use_errno=True)
        libc.timerfd_create.argtypes = (ctypes.c_int, ctypes.c_int)
        libc.timerfd_settime.argtypes = (
            ctypes.c_int,
            ctypes.c_int,
            ctypes.POINTER(_Itimerspec),
            ctypes.c_void_p,
        )
    except (OSError, AttributeError):
        return None
    return libc


def create_wake_timer(on_fire: Callable[[], None]) -> WakeTimer | None:
    """A [`WakeTimer`][aiortu.line.WakeTimer] calling `on_fire` (a bound method, held weakly), if
    the running event loop can watch one: a standard asyncio selector loop on Linux. `None`
    otherwise, also when called outside an asyncio loop (under trio, say)."""
    if _timerfd_libc() is None:
        return None
    try:
        loop = asyncio.get_running_loop()
    except RuntimeError:  # another event loop (trio), or none
        return None
    if not isinstance(loop, asyncio.SelectorEventLoop):
        return None
    if type(loop).time is not asyncio.BaseEventLoop.time:  # a loop with its own clock
        return None
    try:
        return WakeTimer(on_fire)
    except OSError:
        return None


class WakeTimer:
    """Calls `on_fire` at an exact `time.monotonic()` time, in an asyncio event loop.

    `on_fire` must be a bound method; it is held weakly, so the timer does not keep its owner alive
    (the descriptor is closed when the timer is collected, if not by
    [`close`][aiortu.line.WakeTimer.close]). The timer is one-shot and shared: each waiter calls
    [`begin`][aiortu.line.WakeTimer.begin] with its deadline and [`end`][aiortu.line.WakeTimer.end]
    when it stops waiting, and the timer is armed for the earliest deadline; the last
    [`end`][aiortu.line.WakeTimer.end] disarms it. The loop watches the descriptor from the first
    [`begin`][aiortu.line.WakeTimer.begin] until [`close`][aiortu.line.WakeTimer.close] (call it: a
    timer that is watched is not collected). `on_fire` runs in the loop's reader callback when the
    timer goes off; waiters with later deadlines look at the clock and begin again.

    Raises `OSError` where there is no timerfd (see
    [`create_wake_timer`][aiortu.line.create_wake_timer], which checks the event loop too).
    """

    __slots__ = (
        "__weakref__",
        "_armed",
        "_fd",
        "_finalizer",
        "_libc",
        "_loop",
        "_on_fire",
        "_spec",
        "_waiters",
    )

    def __init__(self, on_fire: Callable[[], None]) -> None:
        libc = _timerfd_libc()
        if libc is None:
            raise OSError("timerfd is not available")
        on_fire_weakly = weakref.WeakMethod(on_fire)
        fd = libc.timerfd_create(_CLOCK_MONOTONIC, os.O_NONBLOCK | os.O_CLOEXEC)
        if fd < 0:
            raise OSError(ctypes.get_errno(), "timerfd_create failed")
        self._fd: int = fd
        self._libc = libc
        self._on_fire = on_fire_weakly
        self._spec = _Itimerspec()
        self._loop: asyncio.AbstractEventLoop | None = None
        self._waiters = 0
        self._armed = math.inf
        self._finalizer = weakref.finalize(self, os.close, fd)

    def fileno(self) -> int:
        """The timerfd."""
        return self._fd

    @property
    def deadline(self) -> float:
        """When the timer goes off next, in `time.monotonic()` seconds (`math.inf`: it
        is disarmed)."""
        return self._armed

    @property
    def closed(self) -> bool:
        """True once the descriptor was closed."""
        return not self._finalizer.alive

    def begin(self, loop: asyncio.AbstractEventLoop, deadline: float) -> None:
        """A waiter starts waiting, until `deadline` at the latest (`math.inf`: no limit). Each call
        that returns needs one [`end`][aiortu.line.WakeTimer.end] (in a `finally`, so that a
        cancelled wait leaves too); a call that raises has counted no waiter.
        """
        self._waiters += 1
        try:
            if self._loop is not loop:
                self._watch(loop)
            if deadline < self._armed:
                self._arm(deadline)
        except BaseException:
            self.end()
            raise

    def end(self) -> None:
        """A waiter stops waiting; the last one disarms the timer if it has not gone off."""
        self._waiters = max(0, self._waiters - 1)
        if self._waiters == 0 and self._armed < math.inf:
            self._arm(0.0)

    def _watch(self, loop: asyncio.AbstractEventLoop) -> None:
        """Have `loop` watch the descriptor, from now until [`close`][aiortu.line.WakeTimer.close]:
        once, not per wait, since adding and removing a reader costs more than the wait it
        serves."""
        self._unwatch()
        loop.add_reader(self._fd, self._fire)
        self._loop = loop

    def _unwatch(self) -> None:
        loop, self._loop = self._loop, None
        if loop is not None and not loop.is_closed():
            loop.remove_reader(self._fd)

    def _arm(self, deadline: float) -> None:
        value = self._spec.it_value
        if deadline <= 0:  # disarm
            deadline = math.inf
            value.tv_sec = value.tv_nsec = 0
        else:
            seconds = math.floor(deadline)
            nanoseconds = math.ceil((deadline - seconds) * 1e9)  # never before the deadline
            if nanoseconds >= 1_000_000_000:
                seconds, nanoseconds = seconds + 1, nanoseconds - 1_000_000_000
            value.tv_sec = seconds
            # All zeros would disarm the timer instead of firing it at once.
            value.tv_nsec = max(nanoseconds, 1) if seconds == 0 else nanoseconds
        if self._libc.timerfd_settime(self._fd, _TFD_TIMER_ABSTIME, ctypes.byref(self._spec), None):
            raise OSError(ctypes.get_errno(), "timerfd_settime failed")
        self._armed = deadline

    def _fire(self) -> None:
        try:
            os.read(self._fd, 8)
        except BlockingIOError:  # re-armed since it went off
            return
        self._armed = math.inf
        callback = self._on_fire()
        if callback is not None:
            callback()

    def close(self) -> None:
        """Stop watching and close the descriptor; the timer is not used again (a later
        [`end`][aiortu.line.WakeTimer.end] does nothing)."""
        self._unwatch()
        self._waiters = 0
        self._armed = math.inf
        self._finalizer()

"""The waits and the clock the line layer needs, in the running backend's cheapest form.

A wake-up that a callback sets and a task awaits, a callback soon, and, where the event loop
has them, callbacks at a time. Under asyncio they are the event loop's own (a future,
`call_soon`, `call_at`): no anyio object in between, which matters once per frame. Under any
other backend (trio) the wake-up is an anyio event and "soon" is the backend's own
`run_sync_soon`; there are no timed callbacks (`loop` and `call_at` are `None`), and a link
waits for its deadlines with cancel scopes instead.

Ask [`native_waits`][aiortu.line.native_waits] once, from inside the event loop, and keep what
it returns. [`loop_clock`][aiortu.line.loop_clock] is the backend's clock in its cheapest form, for
those that read the time once per frame or per request (the link, the line server).
"""

from __future__ import annotations

import contextlib
import sys
import time
from collections.abc import Callable, Generator
from dataclasses import dataclass
from typing import Any, Protocol, cast

import anyio
import anyio.lowlevel

__all__ = ("NativeWaits", "Waiter", "loop_clock", "native_waits")


class Waiter(Protocol):
    """A one-shot wake-up: a callback sets it, one task awaits it (an asyncio future is one)."""

    def done(self) -> bool:
        """Whether it has been set."""
        ...

    def set_result(self, result: None, /) -> None:
        """Wake the task awaiting it; once only (see [`done`][aiortu.line.Waiter.done])."""
        ...

    def __await__(self) -> Generator[Any, None, Any]: ...


class _EventWaiter:
    """A [`Waiter`][aiortu.line.Waiter] on an anyio event, for backends without futures."""

    __slots__ = ("_event",)

    def __init__(self) -> None:
        self._event = anyio.Event()

    def done(self) -> bool:
        return self._event.is_set()

    def set_result(self, result: None, /) -> None:
        self._event.set()

    def __await__(self) -> Generator[Any, None, Any]:
        return self._event.wait().__await__()


@dataclass(frozen=True, slots=True)
class NativeWaits:
    """The running backend's waits (see [`native_waits`][aiortu.line.native_waits])."""

    waiter: Callable[[], Waiter]
    """Make a new [`Waiter`][aiortu.line.Waiter]."""
    call_soon: Callable[[Callable[[], object]], object]
    """Have the event loop call a function soon, in its own thread, outside the caller."""
    time: Callable[[], float]
    """The backend's clock (the time `anyio.current_time` tells)."""
    loop: Any = None
    """The asyncio event loop, or `None` under another backend."""
    call_at: Callable[..., Any] | None = None
    """The loop's `call_at(when, callback, *args)` (a handle with `cancel()`), or `None`."""


def native_waits() -> NativeWaits:
    """The running backend's [`NativeWaits`][aiortu.line.NativeWaits]; call it in the event loop."""
    native: Any = anyio.lowlevel.current_token().native_token
    call_at = getattr(native, "call_at", None)
    create_future = getattr(native, "create_future", None)
    if callable(call_at) and callable(create_future):  # an asyncio event loop
        return NativeWaits(create_future, native.call_soon, native.time, native, call_at)
    # trio's token runs a function soon from anywhere, its own thread included.
    run_sync_soon = native.run_sync_soon
    return NativeWaits(_EventWaiter, run_sync_soon, anyio.current_time)


def loop_clock(token: anyio.lowlevel.EventLoopToken | None = None) -> Callable[[], float]:
    """The clock of the running backend (the time `anyio.current_time` tells: virtual on an event
    loop or trio clock that is), as cheap to read as it gets: `time.monotonic` under asyncio's own
    event loops (which tell that time), else the event loop's own `time` method where the loop has
    one that tells the backend's time, else the backend's `current_time`. Call it in the event
    loop (`token`: that of the running loop by default) and keep what it returns."""
    if token is None:
        token = anyio.lowlevel.current_token()
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

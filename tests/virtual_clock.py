"""Tests on a virtual clock: time jumps to the next deadline as soon as every task waits,
so a test of timeouts, retries, guards and probe intervals takes no real time and its
times are exact.

`on_virtual_clock` runs an async test twice: under asyncio on `VirtualTimeLoop` (an event
loop whose `time()` is virtual; its selector never blocks while a timer is pending, it
moves the time on to it instead) and under trio on trio's `MockClock`. Everything the
master, the poller and the virtual bus wait on goes through the loop's clock (the link
reads the loop's `time`, and a loop with a clock of its own gets no timerfd wake timer),
so a scenario on a `VirtualBus` runs under it unchanged. Streams of the operating system
(ptys, sockets) do not: their bytes come in real time.
"""

from __future__ import annotations

import asyncio
import selectors
from collections.abc import Awaitable, Callable
from typing import Any

import anyio
import pytest
import trio.testing

__all__ = ("VirtualTimeLoop", "on_virtual_clock")


class _JumpingSelector(selectors.DefaultSelector):
    """Polls without blocking; where it would block until a timer, moves the loop's virtual
    time on to that timer instead."""

    def __init__(self) -> None:
        super().__init__()
        self.loop: VirtualTimeLoop | None = None

    def select(self, timeout: float | None = None) -> list[Any]:
        ready = super().select(0)
        if ready or timeout == 0:
            return ready
        if timeout is None:
            return super().select(None)  # no timer: only real I/O (a thread) can wake it
        assert self.loop is not None
        self.loop.now += timeout
        return ready


class VirtualTimeLoop(asyncio.SelectorEventLoop):
    """An asyncio event loop on a virtual clock (see the module docstring)."""

    def __init__(self) -> None:
        selector = _JumpingSelector()
        super().__init__(selector)
        selector.loop = self
        self.now = 0.0

    def time(self) -> float:
        return self.now


def on_virtual_clock(test: Callable[[], Awaitable[None]]) -> Callable[[str], None]:
    """Make `test`, an async test without fixtures, a test that runs on a virtual clock
    under asyncio and under trio. The scenario stays reachable as `.scenario`."""

    @pytest.mark.parametrize("virtual_backend", ["asyncio", "trio"])
    def run(virtual_backend: str) -> None:
        if virtual_backend == "trio":
            options: dict[str, object] = {"clock": trio.testing.MockClock(autojump_threshold=0)}
        else:
            options = {"loop_factory": VirtualTimeLoop}
        anyio.run(test, backend=virtual_backend, backend_options=options)

    run.__name__ = test.__name__
    run.__qualname__ = test.__qualname__
    run.__doc__ = test.__doc__
    run.__module__ = test.__module__
    run.scenario = test  # type: ignore[attr-defined]
    return run

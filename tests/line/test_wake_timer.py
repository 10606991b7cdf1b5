"""The precise wake-up timer: a timerfd the asyncio loop watches; never early, disarmed after."""

from __future__ import annotations

import asyncio
import math
import os
import time

import anyio
import pytest

from aiortu.line import WakeTimer, create_wake_timer
from aiortu.line import _wake_timer as wake_timer


class _Owner:
    def __init__(self) -> None:
        self.fired = 0
        self.event = asyncio.Event()

    def on_fire(self) -> None:
        self.fired += 1
        self.event.set()


def _timer(owner: _Owner) -> WakeTimer:
    if wake_timer._timerfd_libc() is None:
        pytest.skip("this system has no timerfd")
    timer = create_wake_timer(owner.on_fire)
    assert timer is not None, "no timer on a standard asyncio loop with timerfd"
    return timer


def test_there_is_no_timer_outside_an_event_loop() -> None:
    assert create_wake_timer(_Owner().on_fire) is None


async def test_there_is_no_timer_without_timerfd(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(wake_timer, "_timerfd_libc", lambda: None)
    assert create_wake_timer(_Owner().on_fire) is None
    with pytest.raises(OSError, match="timerfd"):
        WakeTimer(_Owner().on_fire)


async def test_fires_at_the_deadline_never_before() -> None:
    owner = _Owner()
    timer = _timer(owner)
    loop = asyncio.get_running_loop()
    try:
        for _ in range(20):
            owner.event.clear()
            deadline = time.monotonic() + 0.0015
            timer.begin(loop, deadline)
            try:
                with anyio.fail_after(2):
                    await owner.event.wait()
            finally:
                timer.end()
            assert time.monotonic() >= deadline
            assert timer.deadline == math.inf
    finally:
        timer.close()
    assert owner.fired == 20


async def test_the_earliest_deadline_of_several_waiters_is_armed() -> None:
    owner = _Owner()
    timer = _timer(owner)
    loop = asyncio.get_running_loop()
    now = time.monotonic()
    timer.begin(loop, now + 10)
    timer.begin(loop, now + 5)
    assert timer.deadline == now + 5
    timer.end()
    assert timer.deadline == now + 5  # a waiter is left
    timer.end()
    assert timer.deadline == math.inf
    timer.close()


async def test_the_last_waiter_leaving_disarms_the_timer() -> None:
    owner = _Owner()
    timer = _timer(owner)
    loop = asyncio.get_running_loop()
    timer.begin(loop, time.monotonic() + 0.005)
    timer.end()
    assert timer.deadline == math.inf
    await anyio.sleep(0.02)
    # Disarmed in the kernel too: it never expired, so there is nothing to read.
    with pytest.raises(BlockingIOError):
        os.read(timer.fileno(), 8)
    assert owner.fired == 0
    timer.close()


async def test_the_loop_watches_from_the_first_wait_until_close() -> None:
    owner = _Owner()
    timer = _timer(owner)
    loop = asyncio.get_running_loop()
    fd = timer.fileno()
    for _ in range(3):  # one reader for every wait, not one each
        timer.begin(loop, time.monotonic() + 0.001)
        await anyio.sleep(0.02)
        timer.end()
    assert owner.fired == 3
    assert loop.remove_reader(fd)  # still watched between the waits
    timer.close()


async def test_close_stops_watching_and_closes_the_descriptor() -> None:
    owner = _Owner()
    timer = _timer(owner)
    loop = asyncio.get_running_loop()
    timer.begin(loop, time.monotonic() + 10)
    fd = timer.fileno()
    timer.close()
    assert timer.closed
    assert timer.deadline == math.inf
    assert not loop.remove_reader(fd)
    timer.end()  # a waiter leaving after the close changes nothing
    timer.close()  # and closing twice is harmless


async def test_the_owner_is_held_weakly() -> None:
    owner = _Owner()
    timer = _timer(owner)
    loop = asyncio.get_running_loop()
    timer.begin(loop, time.monotonic() + 0.001)
    del owner
    await anyio.sleep(0.02)  # fires with nobody to call
    timer.end()
    timer.close()

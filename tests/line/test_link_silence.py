"""The link's wait for silence: never before the silence has elapsed, on the precise timer
where there is one, cancellable, and closed with the link."""

from __future__ import annotations

import math
import time

import anyio
import anyio.abc
import pytest

import aiortu.line._sender
from aiortu.core.rtu import FrameReceived, encode_frame
from aiortu.core.serial import LineSettings
from aiortu.line import Link, WakeTimer
from aiortu.line._wake_timer import _timerfd_libc
from aiortu.testing import virtual_pair

REPLY = encode_frame(0x11, bytes.fromhex("03 06 AE 41 56 52 43 40"))
FAST = LineSettings(115200)
GAP = 0.050
"""A silence far longer than scheduling noise, for the waits that other events interrupt."""


async def _settle() -> None:
    """Let the link's reader open: it ignores what arrives in its first frame silence."""
    await anyio.sleep(0.03)


async def _receive_a_frame(link: Link, far: anyio.abc.ByteStream) -> None:
    await far.send(REPLY)
    with anyio.fail_after(2):
        event = await link.receive()
    assert isinstance(event, FrameReceived)


needs_timer = pytest.mark.skipif(
    _timerfd_libc() is None, reason="this system has no timerfd: the link sleeps instead"
)


async def _timer_made(link: Link, far: anyio.abc.ByteStream) -> WakeTimer:
    """Have *link* wait for a silence long enough to be waited for on any machine (a
    t3.5 at 115200 may be over before the wait begins), and return its timer."""
    await _receive_a_frame(link, far)
    await link.wait_for_silence(GAP)
    timer = link._silence.timer
    assert timer is not None, "the link waited without its precise timer"
    return timer


@pytest.mark.parametrize(
    "clock",
    [anyio.current_time, lambda: time.monotonic() + 1000.0],
    ids=["loop clock", "own clock"],
)
async def test_never_returns_before_the_silence_has_elapsed(clock) -> None:
    near, far = virtual_pair()
    async with Link(near, FAST, frame_gap=0, clock=clock) as link:
        await _settle()
        for _ in range(20):
            await _receive_a_frame(link, far)
            quiet_at = link.last_activity + FAST.t3_5
            await link.wait_for_silence(FAST.t3_5)
            assert link.clock() >= quiet_at
        if _timerfd_libc() is not None:
            await _timer_made(link, far)  # the waits above had the timer to end on


@needs_timer
async def test_one_timer_per_link_made_on_first_use() -> None:
    near, far = virtual_pair()
    async with Link(near, FAST, frame_gap=0) as link:
        await _settle()
        assert link._silence.timer is None
        timer = await _timer_made(link, far)
        await _timer_made(link, far)
        assert link._silence.timer is timer


async def test_bytes_arriving_meanwhile_restart_the_wait() -> None:
    near, far = virtual_pair()
    async with Link(near, FAST, frame_gap=0) as link:
        await _settle()
        await _receive_a_frame(link, far)
        first_quiet_at = link.last_activity + GAP
        returned_at = math.nan

        async def wait() -> None:
            nonlocal returned_at
            await link.wait_for_silence(GAP)
            returned_at = link.clock()

        with anyio.fail_after(2):
            async with anyio.create_task_group() as tg:
                tg.start_soon(wait)
                await anyio.sleep(GAP / 2)
                await _receive_a_frame(link, far)
                quiet_at = link.last_activity + GAP
        assert quiet_at > first_quiet_at
        assert returned_at >= quiet_at


@needs_timer
async def test_a_cancelled_wait_leaves_the_timer_disarmed() -> None:
    near, far = virtual_pair()
    async with Link(near, FAST, frame_gap=0) as link:
        await _settle()
        timer = await _timer_made(link, far)
        await _receive_a_frame(link, far)
        async with anyio.create_task_group() as tg:
            tg.start_soon(link.wait_for_silence, 10.0)
            await anyio.sleep(0.01)
            assert timer.deadline < math.inf  # the wait is on the timer
            tg.cancel_scope.cancel()
        assert timer.deadline == math.inf
        assert link._silence.waiters == []
        # The timer still serves the next wait.
        await _receive_a_frame(link, far)
        quiet_at = link.last_activity + FAST.t3_5
        await link.wait_for_silence(FAST.t3_5)
        assert link.clock() >= quiet_at
        assert link._silence.timer is timer


async def test_falls_back_to_the_loop_timers_without_the_precise_timer(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    monkeypatch.setattr(aiortu.line._sender, "create_wake_timer", lambda on_fire: None)
    near, far = virtual_pair()
    async with Link(near, FAST, frame_gap=0) as link:
        await _settle()
        for _ in range(3):
            await _receive_a_frame(link, far)
            quiet_at = link.last_activity + FAST.t3_5
            await link.wait_for_silence(FAST.t3_5)
            assert link.clock() >= quiet_at
        assert link._silence.timer is None


@needs_timer
async def test_the_timer_is_closed_when_the_link_stops() -> None:
    near, far = virtual_pair()
    async with Link(near, FAST, frame_gap=0) as link:
        await _settle()
        timer = await _timer_made(link, far)
        assert not timer.closed
    assert timer.closed
    assert link._silence.timer is None


@needs_timer
async def test_a_wait_outlasting_the_link_still_ends_after_the_silence() -> None:
    near, far = virtual_pair()
    returned_at = math.nan

    async def wait(link: Link) -> None:
        nonlocal returned_at
        await link.wait_for_silence(GAP)
        returned_at = link.clock()

    with anyio.fail_after(2):
        # The waiter's task is outside the link's scope, so closing the link does not
        # cancel it: it goes on waiting with the timer closed under it.
        async with anyio.create_task_group() as tg:
            async with Link(near, FAST, frame_gap=0) as link:
                await _settle()
                timer = await _timer_made(link, far)
                await _receive_a_frame(link, far)
                quiet_at = link.last_activity + GAP
                tg.start_soon(wait, link)
                await anyio.sleep(GAP / 5)
                assert timer.deadline < math.inf
            assert timer.closed
    assert returned_at >= quiet_at


# -- a callback once the line is quiet (Link.call_when_quiet) -------------------------------


async def _called_when_quiet(link: Link, gap_after: float = 0) -> float:
    """Ask for a call once the frame gap has passed; return when it came (the link's clock)."""
    called = anyio.Event()
    when = math.nan

    def callback() -> None:
        nonlocal when
        when = link.clock()
        called.set()

    link.call_when_quiet(callback)
    with anyio.fail_after(2):
        await called.wait()
    return when


@pytest.mark.parametrize("timer", [True, False], ids=["wake timer", "loop timers"])
async def test_a_quiet_call_comes_once_the_gap_has_passed(
    timer: bool, monkeypatch: pytest.MonkeyPatch
) -> None:
    if not timer:
        monkeypatch.setattr(aiortu.line._sender, "create_wake_timer", lambda on_fire: None)
    near, far = virtual_pair()
    async with Link(near, FAST, frame_gap=GAP) as link:
        assert link.loop is not None  # a stream that pushes its bytes
        await _settle()
        for _ in range(3):
            await _receive_a_frame(link, far)
            quiet_at = link.quiet_at()
            assert quiet_at == link.last_activity + GAP
            assert await _called_when_quiet(link) >= quiet_at
        assert (link._silence.timer is not None) == (timer and _timerfd_libc() is not None)


async def test_bytes_arriving_before_a_quiet_call_move_it() -> None:
    near, far = virtual_pair()
    async with Link(near, FAST, frame_gap=GAP) as link:
        await _settle()
        await _receive_a_frame(link, far)
        first_quiet_at = link.quiet_at()
        async with anyio.create_task_group() as tg:

            async def more_bytes() -> None:
                await anyio.sleep(GAP / 2)
                await _receive_a_frame(link, far)

            tg.start_soon(more_bytes)
            called_at = await _called_when_quiet(link)
        assert link.quiet_at() > first_quiet_at
        assert called_at >= link.quiet_at()


async def test_a_cancelled_quiet_call_never_comes_and_leaves_the_timer_disarmed() -> None:
    near, far = virtual_pair()
    async with Link(near, FAST, frame_gap=GAP) as link:
        await _settle()
        await _receive_a_frame(link, far)
        await _called_when_quiet(link)  # the timer made
        await _receive_a_frame(link, far)
        calls: list[float] = []
        link.call_when_quiet(lambda: calls.append(link.clock()))
        timer = link._silence.timer
        if timer is not None:
            assert timer.deadline < math.inf  # the call waits on it
        link.cancel_quiet_call()
        if timer is not None:
            assert timer.deadline == math.inf
        await anyio.sleep(GAP * 2)
        assert calls == []

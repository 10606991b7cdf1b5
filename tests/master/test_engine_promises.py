"""Promises of the master's engine that hold whatever its internals: one transaction on the
line at a time, whoever is cancelled while waiting for it, and the late-reply guard after
a transaction whose retry succeeded.

Through behaviour on the line only: a master and a slave (or a scripted fake device) on a
virtual line, the slave holding a request until the test lets it go, and the frames on the
line; times are asserted as lower bounds the engine guarantees, or exactly on a virtual clock.
Each scenario runs under asyncio and trio (where the engine waits on anyio events, not on
futures of a loop).
"""

from __future__ import annotations

from collections.abc import AsyncIterator, Awaitable, Callable
from contextlib import asynccontextmanager

import anyio
import pytest

from aiortu.core.rtu import FrameReceived, encode_frame
from aiortu.core.serial import LineSettings
from aiortu.master import Master
from aiortu.slave import RequestContext, Slave
from aiortu.testing import VirtualBus
from tests.master.fakes import line, silent
from tests.slave.tcp_helpers import UNIT, device
from tests.virtual_clock import on_virtual_clock

pytestmark = pytest.mark.timeout(30)

BACKENDS = ("asyncio", "trio")


class Hold:
    """A slave hook that holds every request until `release`."""

    def __init__(self) -> None:
        self.released = anyio.Event()
        self.held = 0

    async def __call__(self, request: object, context: RequestContext) -> None:
        self.held += 1
        await self.released.wait()


async def _until(condition: Callable[[], bool]) -> None:
    with anyio.fail_after(10):
        while not condition():  # noqa: ASYNC110
            await anyio.sleep(0.001)


@asynccontextmanager
async def _held_line() -> AsyncIterator[tuple[Master, VirtualBus, Hold]]:
    """Unit 17 on a fast virtual line whose slave holds every request until released."""
    hold = Hold()
    bus = VirtualBus(2)
    slave = Slave(bus.endpoints[1], {UNIT: device()}, frame_gap=0.0, frame_silence=0.005)
    slave.before_request(hold)
    master = Master(bus.endpoints[0], LineSettings(1_000_000), frame_gap=0, timeout=10.0,
                    retries=0, turnaround_delay=0.005)  # fmt: skip
    async with slave, master:
        yield master, bus, hold


def _addresses_on_the_line(bus: VirtualBus) -> list[int]:
    """The (low byte of the) address of each request the master sent, oldest first."""
    return [entry.data[3] for entry in bus.trace if entry.sender == 0]


def _run(backend: str, scenario: Callable[[], Awaitable[None]]) -> None:
    anyio.run(scenario, backend=backend)


async def _cancelled_while_queued() -> None:
    results: dict[str, list[int]] = {}
    async with _held_line() as (master, bus, hold):

        async def read(name: str, address: int) -> None:
            results[name] = await master.read_holding_registers(UNIT, address, 1)

        queued = anyio.CancelScope()

        async def given_up() -> None:
            with queued:
                await read("given up", 1)

        async with anyio.create_task_group() as tasks:
            tasks.start_soon(read, "first", 0)
            await _until(lambda: hold.held == 1)  # the first read on the line, held
            tasks.start_soon(given_up)
            await anyio.wait_all_tasks_blocked()
            queued.cancel()  # its caller leaves while it waits for the line
            await anyio.wait_all_tasks_blocked()
            tasks.start_soon(read, "third", 2)
            await anyio.wait_all_tasks_blocked()
            assert _addresses_on_the_line(bus) == [0]  # the first read alone
            hold.released.set()
        assert results == {"first": [0x1234], "third": [7]}
        assert _addresses_on_the_line(bus) == [0, 2]


@pytest.mark.parametrize("backend", BACKENDS)
def test_a_caller_cancelled_while_queued_does_not_hand_the_line_on(backend: str) -> None:
    _run(backend, _cancelled_while_queued)


@on_virtual_clock
async def test_after_a_retry_succeeds_the_next_request_waits_the_guard() -> None:
    # The first attempt's reply may still be on its way: the guard is kept once more.
    guard = 0.4
    options = {"timeout": 0.05, "retries": 1, "late_reply_guard": guard}
    async with line(script={0: silent}, **options) as (master, slave, _):
        assert await master.read_holding_registers(1, 0, 2) == [1000, 1001]  # on the retry
        assert await master.read_holding_registers(1, 0, 2) == [1000, 1001]
        times = [seen.time for seen in slave.seen]
        assert len(times) == 3
        # The retry: the timeout after the request left the wire, then the guard. The next
        # request: the guard again, though the retry was answered at once.
        wire = 8 * master.settings.char_time
        assert times[1] - times[0] == pytest.approx(0.05 + wire + guard, abs=1e-9)
        assert times[2] - times[1] == pytest.approx(guard, abs=1e-9)


async def test_frames_nobody_examines_keep_the_newest_and_count_the_dropped() -> None:
    # Frames the link delivers while no attempt examines them (other units' traffic on a busy
    # bus) are bounded by the link's queue size: the oldest go, each counted once.
    async with line() as (master, _, _):
        link = master.engine.link
        frames = [FrameReceived(encode_frame(9, bytes((7, n))), 0.0, 0.0) for n in range(70)]
        link._deliver(frames)
        kept = list(master.engine.attempts.events)
        assert len(kept) == link.queue_size == 64
        assert kept == frames[-64:]
        assert link.events_dropped == 6

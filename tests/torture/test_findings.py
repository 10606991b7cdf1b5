"""What the torture suite found, each pinned by a short test of its own.

- A master whose port came back (or any link just opened) sent its first frame at once,
  on top of a frame already on the wire: the link had heard nothing, so it counted the
  line as silent since forever (torture seed 19). A link now keeps ``frame_gap`` of
  silence after it opens, as the spec's INIT state does for the receiver.
- A master on a stream that pushes its bytes (a serial port) left its reply timer armed
  on the event loop after it closed (torture seeds 2, 15, 20, 22, 23).
- A slave that started on a busy line stayed in the receiver's INIT state until the line
  rested for the tolerant frame silence (20 ms), then answered every request it had
  gathered as noise, however old (torture slave seed 1002). INIT now ends on t3.5 of
  silence, as the spec says.
- A slave's serve task cancelled as its line closed could raise ConnectionLost instead
  of ending cancelled (torture slave seed 1175).
"""

from __future__ import annotations

import anyio
import pytest

import aiortu
from aiortu.core.serial import LineSettings
from aiortu.testing import PtyBus, VirtualBus

from .checks import Leftovers

pytestmark = pytest.mark.timeout(30)

SETTINGS = LineSettings(1200, parity="N")
"""Slow enough that t3.5 (32 ms) is far longer than the master takes to start."""


async def test_a_link_keeps_the_frame_gap_after_it_opens() -> None:
    bus = VirtualBus(2, settings=SETTINGS)
    store = aiortu.MemoryStore(holding_registers={0: [7]})
    async with bus, aiortu.Slave(bus.endpoints[1], {1: store}, SETTINGS):
        opened = anyio.current_time()
        async with aiortu.Master(bus.endpoints[0], SETTINGS) as master:
            assert await master.read_holding_registers(1, 0, 1) == [7]
    request = bus.trace[0]
    assert request.sender == 0
    assert request.start - opened >= SETTINGS.t3_5 - 1e-6, request.start - opened


async def test_a_closed_master_leaves_no_timer_on_the_loop() -> None:
    leftovers = Leftovers()
    store = aiortu.MemoryStore(holding_registers={0: [7]})
    async with (
        PtyBus(2) as bus,
        aiortu.serve(bus.paths[1], {1: store}, parity="N"),
        aiortu.open_master(bus.paths[0], parity="N", timeout=5.0) as master,
    ):
        assert await master.read_holding_registers(1, 0, 1) == [7]
    # The reply came long before its 5 s deadline: the timer for it must not outlive
    # the master.
    assert leftovers.new() == []


async def test_a_slave_starting_on_a_busy_line_answers_no_stale_request() -> None:
    """Torture slave seed 1002: a slave restarted while other masters kept the line busy
    (never 20 ms quiet) heard nothing until the line fell quiet, then answered every
    request it had gathered as noise, up to 200 ms late; a master that had timed out
    took one of those replies for its next read of the same shape."""
    settings = LineSettings(115200, parity="N")
    bus = VirtualBus(2, trace_size=100)
    store = aiortu.MemoryStore(holding_registers={0: [7]})
    request = bytes.fromhex("010300000001840a")
    async with bus, aiortu.Slave(bus.endpoints[1], {1: store}, settings, frame_gap=0.0):
        await bus.endpoints[0].send(request)
        sent = anyio.current_time()
        for _ in range(20):  # another master's noise, never 20 ms apart
            await anyio.sleep(0.005)
            await bus.endpoints[0].send(b"\xff\x00")
        await anyio.sleep(0.05)
    replies = [entry for entry in bus.trace if entry.sender == 1]
    # Answering at all is fine (the request came whole); answering it 100 ms on is not.
    assert all(entry.start - sent < 0.03 for entry in replies), [
        round(entry.start - sent, 3) for entry in replies
    ]


async def test_a_cancelled_slave_ends_cancelled_even_as_its_line_closes() -> None:
    """Torture slave seed 1175 (once, timing-dependent): the serve task of a slave,
    cancelled as its line closed, raised ConnectionLost out of the cancel scope instead
    of ending cancelled. Here the cancellation comes in the very step in which the link
    wakes the serve loop to say the line closed, so the loop resumes before anyio can
    deliver it."""
    bus = VirtualBus(2)
    slave = aiortu.Slave(bus.endpoints[1], {1: aiortu.MemoryStore()}, frame_gap=0.0)
    scope = anyio.CancelScope()
    wake = slave._wake_serve_loop

    def wake_then_cancel() -> None:
        wake()
        scope.cancel()

    slave._wake_serve_loop = wake_then_cancel  # type: ignore[method-assign]

    async def pull_the_plug() -> None:
        await anyio.sleep(0.01)
        bus.endpoints[1].close()

    async with bus, anyio.create_task_group() as tasks:
        tasks.start_soon(pull_the_plug)
        with scope:
            await slave.serve()
    assert scope.cancelled_caught

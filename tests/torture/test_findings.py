"""What the torture suite found, each pinned by a short test of its own.

- A master whose port came back (or any link just opened) sent its first frame at once,
  on top of a frame already on the wire: the link had heard nothing, so it counted the
  line as silent since forever (torture seed 19). A link now keeps ``frame_gap`` of
  silence after it opens, as the spec's INIT state does for the receiver.
- A master on a stream that pushes its bytes (a serial port) left its reply timer armed
  on the event loop after it closed (torture seeds 2, 15, 20, 22, 23).
"""

from __future__ import annotations

import anyio
import pytest

import aiortu
from aiortu.core.timing import LineSettings
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

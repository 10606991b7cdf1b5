"""Promises of the serial slave, through a master on a virtual line."""

from __future__ import annotations

import pytest

from aiortu.core.serial import LineSettings
from aiortu.errors import InvalidValue
from aiortu.master import Master
from aiortu.slave import Slave
from aiortu.testing import VirtualBus
from tests.slave.tcp_helpers import device

pytestmark = pytest.mark.timeout(30)


async def test_units_1_and_247_are_served_and_248_is_refused() -> None:
    bus = VirtualBus(2)
    slave = Slave(bus.endpoints[1], {1: device(), 247: device()}, frame_gap=0.0,
                  frame_silence=0.005)  # fmt: skip
    master = Master(bus.endpoints[0], LineSettings(1_000_000), frame_gap=0, timeout=1.0)
    async with slave, master:
        for unit in (1, 247):
            assert await master.read_holding_registers(unit, 0, 1) == [0x1234]
    with pytest.raises(InvalidValue) as raised:
        Slave(VirtualBus(2).endpoints[1], {248: device()})
    assert str(raised.value) == "unit = 248 is outside the allowed range 1..247"

"""Promises of the serial slave: the units it serves (through a master on a virtual line),
and its default line."""

from __future__ import annotations

import anyio
import anyio.abc
import pytest

from aiortu.core.serial import LineSettings
from aiortu.errors import InvalidValue
from aiortu.master import Master
from aiortu.slave import Slave, serve
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


async def test_a_line_is_served_at_the_specs_19200_8e1_by_default() -> None:
    # The serial line spec's default line, whose timing the slave keeps; here the line of a
    # serial device server the slave connects to.
    async with await anyio.create_tcp_listener(local_host="127.0.0.1") as listeners:
        port = listeners.listeners[0].extra(anyio.abc.SocketAttribute.local_port)
        async with serve(f"rtu+tcp://127.0.0.1:{port}", {1: device()}) as slave:
            assert isinstance(slave, Slave)
            assert slave.link.settings == LineSettings(19200, 8, "E", 1)

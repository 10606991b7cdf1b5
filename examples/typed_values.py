"""Typed values in registers: float32 and int32 in every word order, and references.

Runs on its own against a simulated device (an aiortu.Slave with a MemoryStore on an
in-memory line). The device holds the same float and the same integer in the four
layouts (ABCD big-endian, CDAB word-swapped, BADC byte-swapped, DCBA little-endian);
the master reads each back through ``master.slave(unit)`` and by reference::

    python examples/typed_values.py
"""

from __future__ import annotations

import anyio

import aiortu
from aiortu.core.model import Layout, encode_value
from aiortu.testing import VirtualBus

UNIT = 17
FLOAT = 21.5
INT = -123_456


async def main() -> None:
    registers: list[int] = []
    for layout in Layout:  # float32 at 0, 2, 4, 6; int32 at 8, 10, 12, 14
        registers += encode_value(FLOAT, "float32", layout)
    for layout in Layout:
        registers += encode_value(INT, "int32", layout)
    registers += [0] * (120 - len(registers))
    registers[107] = 0x022B  # 40108: holding register 107
    store = aiortu.MemoryStore(holding_registers={0: registers})
    bus = VirtualBus(2)
    async with (
        aiortu.Slave(bus.endpoints[1], {UNIT: store}, frame_gap=0),
        aiortu.Master(bus.endpoints[0], frame_gap=0, timeout=0.5) as master,
    ):
        device = master.slave(UNIT)
        await anyio.sleep(0.01)
        for index, layout in enumerate(Layout):
            raw = await device.read_holding_registers(2 * index, 2)
            value = await device.read_float32(2 * index, layout=layout)
            print(f"float32 {layout} at {2 * index}: {raw[0]:04X} {raw[1]:04X} -> {value}")
        for index, layout in enumerate(Layout):
            address = 8 + 2 * index
            value = await device.read_int32(address, layout=layout)
            print(f"int32 {layout} at {address}: {value}")
        # A reference names the table and the 1-based number: 40108 is holding register 107.
        (value,) = await device.read_reference("40108")
        print(f"40108 = holding register 107 = 0x{value:04X}")
        # Writing goes the other way: the value is encoded in the layout the device uses.
        await device.write_float32(20, -0.125, layout="CDAB")
        print(f"wrote -0.125 as CDAB: {await device.read_holding_registers(20, 2)}")
        print(f"read back: {await device.read_float32(20, layout='CDAB')}")


if __name__ == "__main__":
    anyio.run(main)

"""An async data store that proxies another device through a master.

A gateway: a slave answers unit 1 on one line by asking unit 17 on another line. Here
both lines are in-memory virtual lines, and unit 17 is itself a simulated device, so
the example runs on its own: ``python examples/proxy_store.py``.
"""

from __future__ import annotations

from collections.abc import Sequence

import anyio

import aiortu
from aiortu.slave import MemoryStore, Table
from aiortu.testing import virtual_pair


class ProxyStore:
    """Reads and writes go to *unit* through *master*; their exceptions come back as they are."""

    def __init__(self, master: aiortu.Master, unit: int) -> None:
        self.master = master
        self.unit = unit

    async def read(self, table: Table, address: int, count: int) -> Sequence[int]:
        device = self.master.slave(self.unit)
        if table is Table.COILS:
            return await device.read_coils(address, count)
        if table is Table.DISCRETE_INPUTS:
            return await device.read_discrete_inputs(address, count)
        if table is Table.INPUT_REGISTERS:
            return await device.read_input_registers(address, count)
        return await device.read_holding_registers(address, count)

    async def write(self, table: Table, address: int, values: Sequence[int]) -> None:
        device = self.master.slave(self.unit)
        if table is Table.COILS:
            await device.write_coils(address, [bool(value) for value in values])
        else:
            await device.write_registers(address, list(values))


async def main() -> None:
    far_master_end, far_slave_end = virtual_pair()
    near_master_end, near_slave_end = virtual_pair()
    device = MemoryStore(holding_registers={0: [100, 200, 300, 400]})
    far_device = aiortu.Slave(far_slave_end, {17: device}, frame_gap=0.0)
    upstream = aiortu.Master(far_master_end, timeout=1.0, frame_gap=0.0)
    async with far_device, upstream:
        gateway = aiortu.Slave(near_slave_end, {1: ProxyStore(upstream, 17)}, frame_gap=0.0)
        async with gateway, aiortu.Master(near_master_end, timeout=2.0, frame_gap=0.0) as master:
            await anyio.sleep(0.05)
            print(f"through the proxy: {await master.read_holding_registers(1, 0, 4)}")
            await master.write_register(1, 3, 401)
            print(f"the far device now holds: {device.get(Table.HOLDING_REGISTERS, 0, 4)}")


if __name__ == "__main__":
    anyio.run(main)

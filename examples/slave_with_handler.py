"""A slave with a custom range handler and an observer, read and written by our master.

Runs on its own over an in-memory virtual line: ``python examples/slave_with_handler.py``.
"""

from __future__ import annotations

import anyio

import aiortu
from aiortu.slave import Change, MemoryStore, RangeAccess, Table
from aiortu.testing import virtual_pair


def thermometer(access: RangeAccess) -> list[int] | None:
    """Input registers 100..103: a temperature in 0.1 degC, computed when read."""
    if access.is_write:
        return None
    return [215 + access.address - 100 + index for index in range(access.count)]


async def main() -> None:
    store = MemoryStore(holding_registers={0: 10})
    store.observe(lambda change: print(f"observer: {format_change(change)}"))
    master_end, slave_end = virtual_pair()
    slave = aiortu.Slave(slave_end, {17: store}, frame_gap=0.0)
    slave.route(Table.INPUT_REGISTERS, range(100, 104), thermometer)
    async with slave, aiortu.Master(master_end, timeout=1.0, frame_gap=0.0) as master:
        await anyio.sleep(0.05)  # the slave's receiver starts by waiting for silence
        temperatures = await master.read_input_registers(17, 100, 4)
        print(f"temperatures: {[value / 10 for value in temperatures]}")
        await master.write_registers(17, 2, [7, 8])
        print(f"holding registers: {await master.read_holding_registers(17, 0, 4)}")


def format_change(change: Change) -> str:
    return f"{change.table} {change.address}: {list(change.previous)} -> {list(change.values)}"


if __name__ == "__main__":
    anyio.run(main)

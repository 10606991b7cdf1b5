"""Broadcast a write to every device on a line, then read it back from each.

Runs on its own: three simulated devices (units 1, 2 and 3) share an in-memory RS-485
bus paced at 9600 baud. A broadcast goes to unit 0: every slave executes it and none
answers, so the master waits only the turnaround delay (not a timeout) before the next
request::

    python examples/broadcast.py
"""

from __future__ import annotations

import anyio

import aiortu
from aiortu.testing import VirtualBus

SETTINGS = aiortu.LineSettings(9600, parity="E")
SETPOINT = 0x0010


async def main() -> None:
    devices = {unit: aiortu.MemoryStore(holding_registers={0: 32}) for unit in (1, 2, 3)}
    bus = VirtualBus(2, settings=SETTINGS)
    async with (
        aiortu.Slave(bus.endpoints[1], devices, SETTINGS),
        aiortu.Master(bus.endpoints[0], SETTINGS, timeout=0.5, turnaround_delay=0.1) as master,
    ):
        started = anyio.current_time()
        await master.broadcast.write_register(SETPOINT, 215)
        await master.broadcast.write_registers(0, [1, 2, 3])
        elapsed = anyio.current_time() - started
        print(f"two broadcasts took {elapsed * 1000:.0f} ms (two turnaround delays of 100 ms)")
        for unit in devices:
            value = (await master.read_holding_registers(unit, SETPOINT, 1))[0]
            first = await master.read_holding_registers(unit, 0, 3)
            print(f"unit {unit}: setpoint {value}, registers 0..2 = {first}")


if __name__ == "__main__":
    anyio.run(main)

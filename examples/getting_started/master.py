"""The getting-started master: reads unit 1's registers, writes one, reads them again.

Run it while ``slave.py`` serves the other port of the virtual bus: ``python master.py``
(or ``python master.py PORT``).
"""

import sys

import anyio

import aiortu

PORT = sys.argv[1] if len(sys.argv) > 1 else "/tmp/rtu/port0"


async def main() -> None:
    async with aiortu.open_master(PORT, parity="N", stopbits=2) as master:
        print(await master.read_holding_registers(1, 0, 4))  # unit, address, count
        await master.write_register(1, 1, 42)
        unit = master.slave(1)  # a handle on one unit
        print(await unit.read_holding_registers(0, 4))


anyio.run(main)

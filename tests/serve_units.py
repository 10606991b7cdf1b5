"""A slave for CLI tests: ``python serve_units.py PORT UNIT [UNIT ...]``.

Serves each unit at 19200 8N2 (ptys keep no parity; see aiortu.testing._pty_bus): odd
units have holding register 0 = 0x1234, even units have no holding registers, so that
they answer the scan's probe with exception 02. Prints ``ready`` once the port is open,
and serves until killed.
"""

from __future__ import annotations

import sys

import anyio

import aiortu


async def serve(port: str, units: list[int]) -> None:
    stores = {
        unit: aiortu.MemoryStore(holding_registers={0: [0x1234]} if unit % 2 else None)
        for unit in units
    }
    async with aiortu.serve(port, stores, parity="N", stopbits=2):
        print("ready", flush=True)
        await anyio.sleep_forever()


if __name__ == "__main__":
    anyio.run(serve, sys.argv[1], [int(unit) for unit in sys.argv[2:]])

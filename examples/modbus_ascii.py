"""Modbus ASCII: the same master and slave, with the serial line spec's second framing.

``framing="ascii"`` makes ``aiortu.open_master`` and ``aiortu.serve`` send each byte as two hex
characters between ':' and CR LF, checked by an LRC. Here both ends sit on a virtual serial bus
of two pseudo-terminals; a pty keeps neither parity nor 7 data bits, so the line runs at 8N2
(the spec's ASCII line is 7E1: pass ``bytesize=7`` on a real port). Run it on its own::

    python examples/modbus_ascii.py
"""

from __future__ import annotations

import logging

import anyio

import aiortu
from aiortu.testing import PtyBus

LINE = {"baudrate": 19200, "bytesize": 8, "parity": "N", "stopbits": 2}


async def main() -> None:
    logging.basicConfig(level=logging.ERROR)  # the 8-data-bit warning is expected here
    store = aiortu.MemoryStore(holding_registers={0: [215, 0, 0, 0]})
    async with (
        PtyBus(ports=2) as bus,
        aiortu.serve(bus.paths[1], {17: store}, framing="ascii", **LINE) as slave,
        aiortu.open_master(bus.paths[0], framing="ascii", timeout=1.0, **LINE) as master,
    ):
        await master.write_registers(17, 1, [7, 8])
        print(f"registers 0..2 = {await master.read_holding_registers(17, 0, 3)}")
        stream = slave.link.stream
        print(f"ASCII frames the slave received: {stream.frames_received}")


if __name__ == "__main__":
    anyio.run(main)

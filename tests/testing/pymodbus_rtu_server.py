"""A pymodbus RTU server for interop tests: ``python pymodbus_rtu_server.py PORT``.

Serves unit 1 at 19200 8N2 (pyserial cannot reconfigure a pty with parity; see
aiortu.testing.pty_bus) with holding registers 0, 1, 2 = 0x1234, 0xABCD, 7 and prints
``ready`` on stdout once the port is open. Runs until killed.
"""

from __future__ import annotations

import asyncio
import sys

from pymodbus import FramerType
from pymodbus.datastore import (
    ModbusDeviceContext,
    ModbusSequentialDataBlock,
    ModbusServerContext,
)
from pymodbus.server import ModbusSerialServer

HOLDING_REGISTERS = [0x1234, 0xABCD, 7]


def _connected(up: bool) -> None:
    if up:
        print("ready", flush=True)


async def serve(port: str) -> None:
    # pymodbus's device context shifts addresses by one, so the block starts at 1 for
    # protocol address 0.
    device = ModbusDeviceContext(hr=ModbusSequentialDataBlock(1, HOLDING_REGISTERS + [0] * 16))
    server = ModbusSerialServer(
        ModbusServerContext(devices={1: device}, single=False),
        framer=FramerType.RTU,
        port=port,
        baudrate=19200,
        parity="N",
        stopbits=2,
        bytesize=8,
        trace_connect=_connected,
    )
    await server.serve_forever()


if __name__ == "__main__":
    asyncio.run(serve(sys.argv[1]))

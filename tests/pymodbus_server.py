"""pymodbus's RTU server with all four tables, for the interop tests, and its Modbus TCP server.

``python pymodbus_server.py PORT`` serves unit 1 at 19200 8N2 (ptys keep no parity; see
aiortu.testing._pty_bus) and prints ``ready`` once the port is open. Runs until killed.
``python pymodbus_server.py tcp`` serves the same unit over Modbus TCP on an ephemeral port of
127.0.0.1 and prints ``ready PORT`` once it listens (:func:`running_tcp`).
The initial values are :data:`COILS`, :data:`DISCRETE_INPUTS`, :data:`INPUT_REGISTERS`
and :data:`HOLDING_REGISTERS` from protocol address 0. Tests start it with
:func:`running`.
"""

from __future__ import annotations

import asyncio
import contextlib
import subprocess
import sys
from collections.abc import Iterator

from pymodbus import FramerType
from pymodbus.datastore import (
    ModbusDeviceContext,
    ModbusSequentialDataBlock,
    ModbusServerContext,
)
from pymodbus.server import ModbusSerialServer, ModbusTcpServer

COILS = [bool(i % 3 == 0) for i in range(40)]
DISCRETE_INPUTS = [bool(i % 4 == 1) for i in range(40)]
INPUT_REGISTERS = [0x100 + i for i in range(40)]
HOLDING_REGISTERS = [0x1234, 0xABCD, 7] + [1000 + i for i in range(3, 40)]


def _connected(up: bool) -> None:
    if up:
        print("ready", flush=True)


def _context() -> ModbusServerContext:
    # pymodbus's device context shifts addresses by one: a block starting at 1 serves
    # protocol address 0.
    device = ModbusDeviceContext(
        co=ModbusSequentialDataBlock(1, COILS),
        di=ModbusSequentialDataBlock(1, DISCRETE_INPUTS),
        ir=ModbusSequentialDataBlock(1, INPUT_REGISTERS),
        hr=ModbusSequentialDataBlock(1, HOLDING_REGISTERS),
    )
    return ModbusServerContext(devices={1: device}, single=False)


async def serve_tcp() -> None:
    server = ModbusTcpServer(_context(), address=("127.0.0.1", 0))
    await server.serve_forever(background=True)
    port = server.transport.sockets[0].getsockname()[1]  # type: ignore[union-attr]
    print(f"ready {port}", flush=True)
    await server.serving


async def serve(port: str) -> None:
    server = ModbusSerialServer(
        _context(),
        framer=FramerType.RTU,
        port=port,
        baudrate=19200,
        parity="N",
        stopbits=2,
        bytesize=8,
        trace_connect=_connected,
    )
    await server.serve_forever()


@contextlib.contextmanager
def running_tcp() -> Iterator[int]:
    """Run the Modbus TCP server in a subprocess for the ``with`` block; yield its port."""
    server = subprocess.Popen(
        [sys.executable, "-W", "ignore", __file__, "tcp"],
        stdout=subprocess.PIPE,
        stderr=subprocess.DEVNULL,
        text=True,
    )
    try:
        assert server.stdout is not None
        ready, port = server.stdout.readline().split()
        assert ready == "ready"
        yield int(port)
    finally:
        server.terminate()
        server.wait(timeout=10)


@contextlib.contextmanager
def running(port: str) -> Iterator[None]:
    """Run this server on *port* in a subprocess for the ``with`` block, once it is ready."""
    server = subprocess.Popen(
        [sys.executable, "-W", "ignore", __file__, port],
        stdout=subprocess.PIPE,
        stderr=subprocess.DEVNULL,
        text=True,
    )
    try:
        assert server.stdout is not None
        assert server.stdout.readline().strip() == "ready"
        yield
    finally:
        server.terminate()
        server.wait(timeout=10)


if __name__ == "__main__":
    asyncio.run(serve_tcp() if sys.argv[1] == "tcp" else serve(sys.argv[1]))

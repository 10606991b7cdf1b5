"""The slaves the benchmarks talk to, each run in a process of its own so that its CPU time
and memory can be read from /proc.

    python benchmarks/bench_servers.py pymodbus PORT [--changing]
    python benchmarks/bench_servers.py aiortu PORT [--frame-gap SECONDS] [--units N]
    python benchmarks/bench_servers.py bare PORT
    python benchmarks/bench_servers.py paced-lines --lines 16 [--baudrate 19200] [--units N]
        [--latency SECONDS]

``pymodbus`` runs pymodbus's RTU server, ``aiortu`` runs :func:`aiortu.serve`, both on
PORT at 19200 8N2 (ptys keep no parity) with holding registers 0..99 holding 0..99 on
unit 1 (``--units N``: units 1..N sharing one store); with ``--changing``, pymodbus's
registers change on every read: a read of *count* registers gets ``n, n + 1, ...`` where
*n* counts the reads, so no two replies are the same. ``bare`` is the reference with no
Modbus logic: blocking reads of 8-byte requests, each answered with the fixed reply to a
read of registers 0..9 of unit 1, whatever it asked. ``paced-lines`` starts *lines*
:class:`aiortu.testing.PtyBus` buses paced at *baudrate*, each with an aiortu slave
(frame gap t3.5) on its port 1 (``--latency``: the bus's adapter latency, bytes
handed over in chunks), and prints the port-0 paths, space separated, before
``ready``. Every mode prints ``ready`` on stdout once it serves, then runs until killed.
"""

from __future__ import annotations

import argparse
import asyncio
import os
import signal
import sys

REGISTERS = list(range(100))
BAUDRATE = 19200
PARITY = "N"
STOPBITS = 2


def _ready() -> None:
    print("ready", flush=True)


async def _until_signal() -> None:
    stop = asyncio.Event()
    loop = asyncio.get_running_loop()
    for signum in (signal.SIGTERM, signal.SIGINT):
        loop.add_signal_handler(signum, stop.set)
    await stop.wait()


async def serve_pymodbus(
    port: str, units: int, changing: bool = False, settings: tuple[int, int] = (BAUDRATE, STOPBITS)
) -> None:
    from pymodbus import FramerType
    from pymodbus.datastore import (
        ModbusDeviceContext,
        ModbusSequentialDataBlock,
        ModbusServerContext,
    )
    from pymodbus.server import ModbusSerialServer

    class ChangingBlock(ModbusSequentialDataBlock):  # type: ignore[misc]
        """Registers that change on every read (see the module docstring)."""

        reads = 0

        def getValues(self, address: int, count: int = 1) -> list[int]:
            self.reads += 1
            return [(self.reads + offset) & 0xFFFF for offset in range(count)]

    # pymodbus's device context shifts addresses by one: the block starts at 1 for
    # protocol address 0.
    # pymodbus refuses one device object under several ids: one (same) block each.
    block_class = ChangingBlock if changing else ModbusSequentialDataBlock
    devices = {
        unit: ModbusDeviceContext(hr=block_class(1, REGISTERS)) for unit in range(1, units + 1)
    }
    context = ModbusServerContext(devices=devices, single=False)
    server = ModbusSerialServer(
        context,
        framer=FramerType.RTU,
        port=port,
        baudrate=settings[0],
        parity=PARITY,
        stopbits=settings[1],
        bytesize=8,
        trace_connect=lambda up: _ready() if up else None,
    )
    task = asyncio.create_task(server.serve_forever())
    try:
        await _until_signal()
    finally:
        await server.shutdown()
        task.cancel()


def _store(units: int) -> dict[int, object]:
    import aiortu
    from aiortu.slave._store import Block

    store = aiortu.MemoryStore(holding_registers=[Block(0, len(REGISTERS), REGISTERS)])
    return dict.fromkeys(range(1, units + 1), store)


async def serve_aiortu(port: str, units: int, frame_gap: float | None) -> None:
    import aiortu

    async with aiortu.serve(
        port,
        _store(units),  # type: ignore[arg-type]
        baudrate=BAUDRATE,
        parity=PARITY,
        stopbits=STOPBITS,
        frame_gap=frame_gap,
    ):
        _ready()
        await _until_signal()


def serve_bare(port: str) -> None:
    sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
    import benchlib

    from aiortu.core.pdu import ReadHoldingRegistersResponse
    from aiortu.core.rtu import encode_frame

    reply = encode_frame(1, ReadHoldingRegistersResponse(tuple(range(10))).encode())
    fd = benchlib.open_raw(port)
    _ready()
    while True:
        benchlib.read_exactly(fd, 8)
        os.write(fd, reply)


async def paced_lines(lines: int, baudrate: int, units: int, latency: float) -> None:
    import contextlib

    import aiortu
    from aiortu.testing import PtyBus

    settings = aiortu.LineSettings(baudrate, 8, PARITY, STOPBITS)
    async with contextlib.AsyncExitStack() as stack:
        paths = []
        for _ in range(lines):
            bus = await stack.enter_async_context(PtyBus(2, settings=settings, latency=latency))
            await stack.enter_async_context(
                aiortu.serve(
                    bus.paths[1],
                    _store(units),  # type: ignore[arg-type]
                    baudrate=baudrate,
                    parity=PARITY,
                    stopbits=STOPBITS,
                )
            )
            paths.append(bus.paths[0])
        print(" ".join(paths), flush=True)
        _ready()
        await _until_signal()


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("mode", choices=["pymodbus", "aiortu", "bare", "paced-lines"])
    parser.add_argument("port", nargs="?")
    parser.add_argument("--frame-gap", type=float, default=None)
    parser.add_argument("--units", type=int, default=1)
    parser.add_argument("--lines", type=int, default=16)
    parser.add_argument("--baudrate", type=int, default=BAUDRATE)
    parser.add_argument("--stopbits", type=int, default=STOPBITS)
    parser.add_argument("--latency", type=float, default=0.0)
    parser.add_argument("--changing", action="store_true")
    args = parser.parse_args()
    if args.mode == "pymodbus":
        settings = (args.baudrate, args.stopbits)
        asyncio.run(serve_pymodbus(args.port, args.units, args.changing, settings))
    elif args.mode == "aiortu":
        asyncio.run(serve_aiortu(args.port, args.units, args.frame_gap))
    elif args.mode == "bare":
        serve_bare(args.port)
    else:
        asyncio.run(paced_lines(args.lines, args.baudrate, args.units, args.latency))
    sys.stdout.flush()
    os._exit(0)


if __name__ == "__main__":
    main()

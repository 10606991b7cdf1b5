"""Modbus ASCII with real peers on a pty bus: pymodbus 3.16.1 as client and server, tmodbus
1.1.0 as client and server, and minimalmodbus 2.1.1's ASCII master against an aiortu slave.

The ptys keep neither parity nor 7 data bits, so every end runs at 19200 8N2; the ASCII
characters fit in 7 bits anyway."""

from __future__ import annotations

import subprocess
from collections.abc import AsyncIterator
from contextlib import asynccontextmanager
from pathlib import Path
from typing import Any

import anyio
import pytest

import aiortu
from aiortu.testing import PtyBus
from aiortu.transport import AsciiStream
from tests.peers.venvs import minimalmodbus_python, tmodbus_python
from tests.pymodbus_server import COILS, HOLDING_REGISTERS
from tests.transport import pymodbus_peers
from tests.transport.test_interop_tmodbus import tmodbus_server

pymodbus_client = pytest.importorskip("pymodbus.client")
pymodbus = pytest.importorskip("pymodbus")

pytestmark = [pytest.mark.interop, pytest.mark.timeout(120)]

LINE: dict[str, Any] = {"baudrate": 19200, "bytesize": 8, "parity": "N", "stopbits": 2}
HERE = Path(__file__).parent


def _store() -> aiortu.MemoryStore:
    return aiortu.MemoryStore(
        holding_registers={0: [10, 20, 30, 0, 0, 0]}, coils={0: [1, 0, 1, 1, 0, 0, 0, 0]}
    )


@asynccontextmanager
async def aiortu_ascii_slave(store: aiortu.MemoryStore) -> AsyncIterator[tuple[str, Any]]:
    """An aiortu ASCII slave (unit 17) on port 1 of a pty bus; yields port 0's path and it."""
    async with (
        PtyBus(ports=2) as bus,
        aiortu.serve(bus.paths[1], {17: store}, framing="ascii", **LINE) as slave,
    ):
        yield bus.paths[0], slave


async def _run(argv: list[str]) -> list[str]:
    done = await anyio.run_process(argv, check=False, stdin=subprocess.DEVNULL)
    assert done.returncode == 0, done.stderr.decode()[-2000:]
    return done.stdout.decode().splitlines()


async def test_pymodbus_ascii_client_against_aiortu() -> None:
    store = _store()
    async with aiortu_ascii_slave(store) as (path, slave):
        client = pymodbus_client.AsyncModbusSerialClient(
            path, framer=pymodbus.FramerType.ASCII, timeout=2, retries=0, **LINE
        )
        assert await client.connect()
        try:
            unit = {"device_id": 17}
            reply = await client.read_holding_registers(0, count=3, **unit)
            assert reply.registers == [10, 20, 30]
            assert not (await client.write_registers(3, [7, 8], **unit)).isError()
            assert not (await client.write_coil(5, True, **unit)).isError()
            bits = (await client.read_coils(0, count=8, **unit)).bits
            assert bits[:8] == [True, False, True, True, False, True, False, False]
            missing = await client.read_holding_registers(60, count=1, **unit)
            assert missing.exception_code == 2
        finally:
            client.close()
        stream = slave.link.stream
        assert isinstance(stream, AsciiStream)
        assert stream.frames_received == 5
        assert sum(stream.discarded.values()) == 0
    assert store.get(aiortu.slave.Table.HOLDING_REGISTERS, 3, 2) == [7, 8]


async def test_aiortu_ascii_master_against_pymodbus_server() -> None:
    async with PtyBus(ports=2) as bus:
        with pymodbus_peers.running("ascii", bus.paths[1]):
            async with aiortu.open_master(
                bus.paths[0], framing="ascii", timeout=2.0, **LINE
            ) as master:
                assert await master.read_holding_registers(1, 0, 3) == HOLDING_REGISTERS[:3]
                await master.write_registers(1, 30, [5, 6])
                assert await master.read_holding_registers(1, 30, 2) == [5, 6]
                assert await master.read_coils(1, 0, 6) == COILS[:6]
                with pytest.raises(aiortu.ExceptionResponse):
                    await master.read_holding_registers(1, 500, 1)


async def test_minimalmodbus_ascii_master_against_aiortu() -> None:
    python = minimalmodbus_python()
    store = _store()
    async with aiortu_ascii_slave(store) as (path, _):
        lines = await _run([python, str(HERE / "minimalmodbus_peer.py"), path])
    assert lines == [
        "read [10, 20, 30]",
        "read [77, 1, 2]",
        "coils [1, 0, 1, 1]",
    ]


async def test_tmodbus_ascii_client_against_aiortu() -> None:
    python = tmodbus_python()
    store = aiortu.MemoryStore(holding_registers={0: [10, 20, 30, 0, 0]})
    async with (
        PtyBus(ports=2) as bus,
        aiortu.serve(bus.paths[1], {1: store}, framing="ascii", **LINE),
    ):
        lines = await _run([python, str(HERE / "tmodbus_peer.py"), "client", "ascii", bus.paths[0]])
    assert lines == ["read [10, 20, 30]", "read [30, 7, 8]", "written"]


async def test_aiortu_ascii_master_against_tmodbus_server() -> None:
    python = tmodbus_python()
    async with PtyBus(ports=2) as bus:
        with tmodbus_server(python, "ascii", bus.paths[1]):
            async with aiortu.open_master(
                bus.paths[0], framing="ascii", timeout=2.0, **LINE
            ) as master:
                assert await master.read_holding_registers(1, 0, 3) == [0, 1, 2]
                await master.write_registers(1, 3, [7, 8])
                assert await master.read_holding_registers(1, 2, 3) == [2, 7, 8]

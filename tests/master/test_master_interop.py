"""The master against pymodbus's RTU server over a pty bus (8N2): exact values for every
table and for the writes."""

from __future__ import annotations

import contextlib
from collections.abc import AsyncIterator, Iterator

import pytest

import aiortu
from aiortu.core.serial import LineSettings
from aiortu.testing import PtyBus
from tests import pymodbus_server
from tests.pymodbus_server import COILS, DISCRETE_INPUTS, HOLDING_REGISTERS, INPUT_REGISTERS

pytestmark = [pytest.mark.interop, pytest.mark.timeout(60)]

SETTINGS = LineSettings(19200, parity="N", stopbits=2)


@pytest.fixture(scope="module")
def port() -> Iterator[str]:
    """The master's port on a pty bus whose other port pymodbus's server serves."""
    with (
        PtyBus(2, settings=SETTINGS).running_in_thread() as bus,
        pymodbus_server.running(bus.paths[1]),
    ):
        yield bus.paths[0]


@contextlib.asynccontextmanager
async def connect(port: str) -> AsyncIterator[aiortu.Master]:
    # Not a fixture: pytest-asyncio may set a fixture up and tear it down in different
    # tasks, and the master's task group must be left in the task that entered it.
    async with aiortu.open_master(
        port, baudrate=19200, parity="N", stopbits=2, timeout=1.0
    ) as opened:
        yield opened


async def test_reads_of_every_table(port: str) -> None:
    async with connect(port) as master:
        assert await master.read_holding_registers(1, 0, 3) == [0x1234, 0xABCD, 7]
        assert await master.read_holding_registers(1, 10, 20) == HOLDING_REGISTERS[10:30]
        assert await master.read_input_registers(1, 2, 5) == INPUT_REGISTERS[2:7]
        assert await master.read_coils(1, 3, 19) == COILS[3:22]
        assert await master.read_discrete_inputs(1, 0, 11) == DISCRETE_INPUTS[:11]


async def test_writes_read_back_exactly(port: str) -> None:
    async with connect(port) as master:
        await master.write_register(1, 5, 0xBEEF)
        await master.write_registers(1, 6, [1, 2, 3])
        assert await master.read_holding_registers(1, 5, 4) == [0xBEEF, 1, 2, 3]
        await master.write_coil(1, 0, False)
        await master.write_coils(1, 1, [True, False, True, True])
        assert await master.read_coils(1, 0, 6) == [False, True, False, True, True, COILS[5]]
        await master.write_register(1, 20, 0x0012)
        await master.mask_write_register(1, 20, 0x00F2, 0x0025)
        assert await master.read_holding_registers(1, 20, 1) == [0x0017]
        # Read/write multiple: the write happens before the read.
        assert await master.read_write_registers(1, 30, 4, 31, [0x11, 0x22]) == [
            HOLDING_REGISTERS[30],
            0x11,
            0x22,
            HOLDING_REGISTERS[33],
        ]


async def test_typed_values_and_references(port: str) -> None:
    async with connect(port) as master:
        device = master.slave(1)
        await device.write_float32(10, 21.5, layout="CDAB")
        assert await device.read_float32(10, layout="CDAB") == 21.5
        await device.write_int32(12, -123456)
        assert await device.read_int32(12) == -123456
        assert await device.read_reference("40001", 2) == [0x1234, 0xABCD]


async def test_an_exception_from_pymodbus(port: str) -> None:
    async with connect(port) as master:
        with pytest.raises(aiortu.ExceptionResponse) as caught:
            await master.read_holding_registers(1, 1000, 2)
        assert caught.value.code == aiortu.ExceptionCode.ILLEGAL_DATA_ADDRESS

"""The master over Modbus TCP against pymodbus's Modbus TCP server: every code it serves."""

from __future__ import annotations

from collections.abc import Iterator

import pytest

import aiortu
from aiortu.core.codes import DiagnosticSubFunction
from aiortu.transport import ModbusTcpStream, PushConnectionStream
from tests import pymodbus_server
from tests.pymodbus_server import COILS, DISCRETE_INPUTS, HOLDING_REGISTERS, INPUT_REGISTERS

pytestmark = [pytest.mark.interop, pytest.mark.timeout(60)]


@pytest.fixture(scope="module")
def url() -> Iterator[str]:
    """The URL of pymodbus's Modbus TCP server (unit 1), run in a subprocess."""
    with pymodbus_server.running_tcp() as port:
        yield f"tcp://127.0.0.1:{port}"


async def test_reads_and_writes(url: str) -> None:
    async with aiortu.open_master(url, timeout=2.0) as master:
        assert await master.read_coils(1, 3, 19) == COILS[3:22]
        assert await master.read_discrete_inputs(1, 0, 11) == DISCRETE_INPUTS[:11]
        assert await master.read_holding_registers(1, 10, 20) == HOLDING_REGISTERS[10:30]
        assert await master.read_input_registers(1, 2, 5) == INPUT_REGISTERS[2:7]
        await master.write_register(1, 5, 0xBEEF)
        await master.write_registers(1, 6, [1, 2, 3])
        assert await master.read_holding_registers(1, 5, 4) == [0xBEEF, 1, 2, 3]
        await master.write_coil(1, 0, False)
        await master.write_coils(1, 1, [True, False, True, True])
        assert await master.read_coils(1, 0, 6) == [False, True, False, True, True, COILS[5]]
        await master.write_register(1, 20, 0x0012)
        await master.mask_write_register(1, 20, 0x00F2, 0x0025)
        assert await master.read_holding_registers(1, 20, 1) == [0x0017]
        assert await master.read_write_registers(1, 30, 4, 31, [0x11, 0x22]) == [
            HOLDING_REGISTERS[30],
            0x11,
            0x22,
            HOLDING_REGISTERS[33],
        ]
        with pytest.raises(aiortu.ExceptionResponse) as caught:
            await master.read_holding_registers(1, 1000, 2)
        assert caught.value.code == aiortu.ExceptionCode.ILLEGAL_DATA_ADDRESS
        stream = master.link.stream
        assert isinstance(stream, ModbusTcpStream | PushConnectionStream)
        assert stream.counters.dropped == 0


async def test_the_other_codes_pymodbus_serves(url: str) -> None:
    # pymodbus answers a file record read with records of its own length, which the
    # master refuses as malformed; that code is left out.
    async with aiortu.open_master(url, timeout=2.0) as master:
        assert await master.read_fifo_queue(1, 0) == [0, 1, 2, 3]
        await master.write_file_record(1, [(1, 0, [1, 2])])
        assert await master.read_exception_status(1) == 0
        diagnostics = await master.diagnostics(
            1, DiagnosticSubFunction.RETURN_QUERY_DATA, b"\xa5\x37"
        )
        assert diagnostics is not None
        assert diagnostics.data == b"\xa5\x37"
        assert (await master.get_comm_event_counter(1)).event_count == 0
        assert (await master.get_comm_event_log(1)).events == b""
        assert (await master.report_server_id(1)).server_id == b"Pymodbus"
        assert await master.read_device_identification(1) == {}

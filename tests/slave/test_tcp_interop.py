"""aiortu.serve("tcp://...") against pymodbus's TCP clients (async and sync) and mbpoll -m tcp."""

from __future__ import annotations

import shutil
from typing import Any

import anyio
import pytest

from aiortu.slave import MemoryStore, Table
from tests.slave.tcp_helpers import UNIT, device, tcp_server

pymodbus_client = pytest.importorskip("pymodbus.client")
file_message = pytest.importorskip("pymodbus.pdu.file_message")

pytestmark = [pytest.mark.interop, pytest.mark.timeout(60)]

UNIT_ID = {"device_id": UNIT}


async def _ok(call: Any) -> Any:
    reply = await call
    assert not reply.isError(), reply
    return reply


async def _data_codes(client: Any, store: MemoryStore) -> None:
    """01-06, 0F, 10, 14-18 and 2B, as any Modbus TCP device serves them."""
    assert (await _ok(client.read_coils(0, count=4, **UNIT_ID))).bits[:4] == [1, 0, 1, 1]
    assert (await _ok(client.read_discrete_inputs(0, count=3, **UNIT_ID))).bits[:3] == [0, 1, 1]
    regs = await _ok(client.read_holding_registers(0, count=3, **UNIT_ID))
    assert regs.registers == [0x1234, 0xABCD, 7]
    assert (await _ok(client.read_input_registers(1, count=2, **UNIT_ID))).registers == [22, 33]
    await _ok(client.write_coil(1, True, **UNIT_ID))
    await _ok(client.write_register(3, 99, **UNIT_ID))
    await _ok(client.write_coils(4, [True, False, True], **UNIT_ID))
    await _ok(client.write_registers(4, [1, 2, 3], **UNIT_ID))
    assert store.get(Table.COILS, 0, 7) == [1, 1, 1, 1, 1, 0, 1]
    assert store.get(Table.HOLDING_REGISTERS, 3, 4) == [99, 1, 2, 3]
    record = file_message.FileRecord(file_number=4, record_number=1, record_length=4)
    records = await _ok(client.read_file_record([record], **UNIT_ID))
    assert records.records[0].record_data == bytes.fromhex("04 BE 10 0D")
    written = file_message.FileRecord(
        file_number=4, record_number=3, record_data=b"\x00\x07\x00\x08"
    )
    await _ok(client.write_file_record([written], **UNIT_ID))
    assert store.read_file_record(4, 3, 2) == [7, 8]
    await _ok(client.mask_write_register(address=0, and_mask=0x00FF, or_mask=0, **UNIT_ID))
    assert store.get(Table.HOLDING_REGISTERS, 0) == [0x34]
    both = await _ok(
        client.readwrite_registers(
            read_address=0, read_count=2, write_address=1, values=[5], **UNIT_ID
        )
    )
    assert both.registers == [0x34, 5]
    # Over TCP the MBAP length frames the FIFO reply, which pymodbus's RTU framer mispredicts.
    assert (await _ok(client.read_fifo_queue(address=0x04DE, **UNIT_ID))).values == [440, 25]
    ident = await _ok(client.read_device_information(read_code=1, object_id=0, **UNIT_ID))
    assert ident.information[0] == b"aiortu"
    refused = await client.read_holding_registers(14, count=5, **UNIT_ID)
    assert refused.isError()
    assert refused.exception_code == 0x02


async def test_async_client_every_function_code() -> None:
    store = device()
    async with tcp_server({UNIT: store}, serial_line_codes=True) as server:
        client = pymodbus_client.AsyncModbusTcpClient(
            "127.0.0.1", port=server.port, timeout=3, retries=0
        )
        try:
            assert await client.connect()
            await _data_codes(client, store)
            # The serial line codes, served because serial_line_codes=True.
            assert (await _ok(client.read_exception_status(**UNIT_ID))).status == 0x6D
            echo = await _ok(client.diag_query_data(b"\xa5\x37", **UNIT_ID))
            assert echo.message == b"\xa5\x37"
            await _ok(client.diag_read_bus_message_count(**UNIT_ID))
            await _ok(client.diag_read_diagnostic_register(**UNIT_ID))
            await _ok(client.diag_clear_counters(**UNIT_ID))
            await _ok(client.diag_get_comm_event_counter(**UNIT_ID))
            await _ok(client.diag_get_comm_event_log(**UNIT_ID))
            assert (await _ok(client.report_device_id(**UNIT_ID))).identifier[:1] == b"\x11"
        finally:
            client.close()


async def test_async_client_gets_01_for_serial_line_codes_and_0B_for_other_units() -> None:
    async with tcp_server() as server:
        client = pymodbus_client.AsyncModbusTcpClient(
            "127.0.0.1", port=server.port, timeout=3, retries=0
        )
        try:
            assert await client.connect()
            for call in (
                client.read_exception_status(**UNIT_ID),
                client.diag_query_data(b"\x00\x01", **UNIT_ID),
                client.diag_get_comm_event_counter(**UNIT_ID),
                client.diag_get_comm_event_log(**UNIT_ID),
                client.report_device_id(**UNIT_ID),
            ):
                reply = await call
                assert reply.isError()
                assert reply.exception_code == 0x01
            other = await client.read_holding_registers(0, count=1, device_id=5)
            assert other.isError()
            assert other.exception_code == 0x0B
            assert not (await client.read_holding_registers(0, count=1, device_id=255)).isError()
        finally:
            client.close()


def _sync_session(port: int, session: int) -> list[int]:
    # Each session writes registers and a coil of its own, so that what it reads back
    # depends on its own requests alone, however the sessions interleave.
    client = pymodbus_client.ModbusTcpClient("127.0.0.1", port=port, timeout=3, retries=0)
    address, coil = 4 + 4 * session, 12 + session
    try:
        assert client.connect()
        assert not client.write_registers(address, [4, 5, 6], **UNIT_ID).isError()
        assert not client.write_coil(coil, True, **UNIT_ID).isError()
        assert client.read_coils(coil, count=1, **UNIT_ID).bits[0]
        assert not client.mask_write_register(
            address=address, and_mask=0, or_mask=0x10, **UNIT_ID
        ).isError()
        registers: list[int] = client.read_holding_registers(address, count=3, **UNIT_ID).registers
        return registers
    finally:
        client.close()


async def test_sync_clients_at_once() -> None:
    store = device()
    async with tcp_server({UNIT: store}) as server:
        results: list[list[int]] = []

        async def one(session: int) -> None:
            results.append(await anyio.to_thread.run_sync(_sync_session, server.port, session))

        async with anyio.create_task_group() as group:
            for session in range(3):
                group.start_soon(one, session)
    assert results == [[0x10, 5, 6]] * 3
    assert server.counters.connections_accepted == 3


MBPOLL = shutil.which("mbpoll")


@pytest.mark.skipif(MBPOLL is None, reason="mbpoll is not installed")
async def test_mbpoll_tcp_reads_and_writes() -> None:
    store = device()
    async with tcp_server({UNIT: store}) as server:

        async def run(*args: str, values: tuple[str, ...] = ()) -> str:
            assert MBPOLL is not None
            command = [MBPOLL, "-m", "tcp", "-a", str(UNIT), "-p", str(server.port), "-1"]
            command += ["-o", "2", *args, "127.0.0.1", *values]
            result = await anyio.run_process(command, check=False)
            output = result.stdout.decode()
            assert result.returncode == 0, output + result.stderr.decode()
            return output

        out = await run("-r", "1", "-c", "5")  # 03, 1-based references
        assert "[1]: \t4660" in out
        assert "[3]: \t7" in out
        assert "[2]: \t22" in await run("-t", "3", "-r", "2", "-c", "2")  # 04
        assert "[1]: \t1" in await run("-t", "0", "-r", "1", "-c", "4")  # 01
        await run("-t", "4", "-r", "11", values=("4660",))  # 06
        await run("-t", "4", "-r", "12", values=("1", "2"))  # 10
        await run("-t", "0", "-r", "12", values=("1", "0", "1"))  # 0F
        assert store.get(Table.HOLDING_REGISTERS, 10, 3) == [4660, 1, 2]
        assert store.get(Table.COILS, 11, 3) == [1, 0, 1]


@pytest.mark.skipif(MBPOLL is None, reason="mbpoll is not installed")
async def test_mbpoll_against_the_serve_command() -> None:
    import re
    import signal
    import subprocess
    import sys

    assert MBPOLL is not None
    command = [sys.executable, "-m", "aiortu", "serve", "tcp://127.0.0.1:0"]
    command += ["--config", "examples/devices.toml", "--trace"]
    async with await anyio.open_process(command, stderr=subprocess.PIPE) as process:
        assert process.stderr is not None
        banner = b""
        with anyio.fail_after(20):
            while b"\n" not in banner:
                banner += await process.stderr.receive()
        found = re.search(rb"\(port (\d+)\)", banner)
        assert found is not None, banner
        port = found[1].decode()
        poll = [MBPOLL, "-m", "tcp", "-a", "17", "-r", "108", "-c", "3", "-1", "-p", port]
        result = await anyio.run_process([*poll, "127.0.0.1"], check=False)
        assert result.returncode == 0, result.stdout + result.stderr
        assert b"[108]: \t-20927" in result.stdout or b"[108]: \t44609" in result.stdout
        with anyio.fail_after(20):
            while b"->" not in banner:
                banner += await process.stderr.receive()
        # The trace shows each ADU's request with its meaning, as over RTU.
        assert b"00 00 00 06 11 03 00 6b 00 03  unit 17 read holding registers 107..109" in banner
        process.send_signal(signal.SIGTERM)
        assert await process.wait() == 0

"""Every function code of the slave against pymodbus's client and mbpoll, over ptys (8N2)."""

from __future__ import annotations

import contextlib
import os
import shutil
import tty
from collections.abc import AsyncIterator

import anyio
import pytest

from aiortu.core.serial import LineSettings
from aiortu.slave import MemoryStore, ServerId, Slave, Table
from aiortu.transport import FileDescriptorStream

pymodbus_client = pytest.importorskip("pymodbus.client")
file_message = pytest.importorskip("pymodbus.pdu.file_message")

pytestmark = pytest.mark.interop

# Ptys here keep no parity: 8N2, still 11 bits a character.
LINE = LineSettings(19200, 8, "N", 2)
UNIT = 17


def device() -> MemoryStore:
    return MemoryStore(
        coils={0: [1, 0, 1, 1] + [0] * 12},
        discrete_inputs={0: [0, 1, 1] + [0] * 5},
        holding_registers={0: [0x1234, 0xABCD, 7] + [0] * 13},
        input_registers={0: [11, 22, 33]},
        fifo_queues={0x04DE: [440, 25]},
        files={4: [0x06AF, 0x04BE, 0x100D, 0, 0]},
        device_identification={0: "aiortu", 1: "SIM", 2: "1.0", 4: "meter"},
        server_id=ServerId(b"\x11", True, b"sim"),
        exception_status=0x6D,
    )


@contextlib.asynccontextmanager
async def pty_slave(store: MemoryStore) -> AsyncIterator[tuple[str, Slave]]:
    master_fd, slave_fd = os.openpty()
    tty.setraw(slave_fd)
    path = os.ttyname(slave_fd)
    slave = Slave(FileDescriptorStream(master_fd), {UNIT: store}, LINE, frame_gap=0.0)
    try:
        async with slave:
            await anyio.sleep(0.05)
            yield path, slave
    finally:
        with contextlib.suppress(OSError):
            os.close(slave_fd)


async def test_pymodbus_client_every_function_code() -> None:
    store = device()
    async with pty_slave(store) as (path, slave):
        client = pymodbus_client.AsyncModbusSerialClient(
            path, baudrate=19200, parity="N", stopbits=2, timeout=2, retries=0
        )
        try:
            assert await client.connect()
            unit = {"device_id": UNIT}

            async def ok(call: object) -> object:
                reply = await call  # type: ignore[misc]
                assert not reply.isError(), reply
                return reply

            assert (await ok(client.read_coils(0, count=4, **unit))).bits[:4] == [1, 0, 1, 1]
            inputs = await ok(client.read_discrete_inputs(0, count=3, **unit))
            assert inputs.bits[:3] == [0, 1, 1]
            regs = await ok(client.read_holding_registers(0, count=3, **unit))
            assert regs.registers == [0x1234, 0xABCD, 7]
            assert (await ok(client.read_input_registers(1, count=2, **unit))).registers == [22, 33]
            await ok(client.write_coil(1, True, **unit))
            await ok(client.write_register(3, 99, **unit))
            await ok(client.write_coils(4, [True, False, True], **unit))
            await ok(client.write_registers(4, [1, 2, 3], **unit))
            assert store.get(Table.COILS, 0, 7) == [1, 1, 1, 1, 1, 0, 1]
            assert store.get(Table.HOLDING_REGISTERS, 3, 4) == [99, 1, 2, 3]
            assert (await ok(client.read_exception_status(**unit))).status == 0x6D
            echo = await ok(client.diag_query_data(b"\xa5\x37", **unit))
            assert echo.message == b"\xa5\x37"
            messages = await ok(client.diag_read_bus_message_count(**unit))
            assert messages.message == 11  # the eleven requests so far
            await ok(client.diag_read_bus_comm_error_count(**unit))
            await ok(client.diag_read_bus_exception_error_count(**unit))
            await ok(client.diag_read_device_message_count(**unit))
            await ok(client.diag_read_device_no_response_count(**unit))
            await ok(client.diag_read_device_nak_count(**unit))
            await ok(client.diag_read_device_busy_count(**unit))
            await ok(client.diag_read_bus_char_overrun_count(**unit))
            await ok(client.diag_read_diagnostic_register(**unit))
            # pymodbus sends the value as given; the spec wants the character in the high byte.
            await ok(client.diag_change_ascii_input_delimeter(delimiter=0x3A00, **unit))
            assert slave.machine.ascii_delimiter == 0x3A
            await ok(client.diag_clear_overrun_counter(**unit))
            await ok(client.diag_clear_counters(**unit))
            await ok(client.diag_restart_communication(False, **unit))
            counter = await ok(client.diag_get_comm_event_counter(**unit))
            assert counter.count == 0  # the restart cleared it
            log = await ok(client.diag_get_comm_event_log(**unit))
            assert log.message_count == 2
            assert log.events[:1] == [0x80]
            server = await ok(client.report_device_id(**unit))
            assert server.identifier[:1] == b"\x11"
            # pymodbus counts record_length in bytes.
            records = await ok(
                client.read_file_record(
                    [file_message.FileRecord(file_number=4, record_number=1, record_length=4)],
                    **unit,
                )
            )
            assert records.records[0].record_data == bytes.fromhex("04 BE 10 0D")
            await ok(
                client.write_file_record(
                    [
                        file_message.FileRecord(
                            file_number=4, record_number=3, record_data=b"\x00\x07\x00\x08"
                        )
                    ],
                    **unit,
                )
            )
            assert store.read_file_record(4, 3, 2) == [7, 8]
            await ok(client.mask_write_register(address=0, and_mask=0x00FF, or_mask=0, **unit))
            assert store.get(Table.HOLDING_REGISTERS, 0) == [0x34]
            both = await ok(
                client.readwrite_registers(
                    read_address=0, read_count=2, write_address=1, values=[5], **unit
                )
            )
            assert both.registers == [0x34, 5]
            # Not 18: pymodbus's RTU framer mispredicts the length of a FIFO reply (a
            # two-byte byte count); our master covers it in test_our_master_... below.
            ident = await ok(client.read_device_information(read_code=2, object_id=0, **unit))
            assert ident.information[0] == b"aiortu"
            assert ident.information[4] == b"meter"
            refused = await client.read_holding_registers(14, count=5, device_id=UNIT)
            assert refused.isError()
            assert refused.exception_code == 0x02
            await client.diag_force_listen_only(**unit)
            await anyio.sleep(0.05)
            assert slave.listen_only
        finally:
            client.close()


MBPOLL = shutil.which("mbpoll")


@pytest.mark.skipif(MBPOLL is None, reason="mbpoll is not installed")
async def test_mbpoll_reads_and_writes() -> None:
    store = device()
    async with pty_slave(store) as (path, _):

        async def run(*args: str, values: tuple[str, ...] = ()) -> str:
            assert MBPOLL is not None
            command = [MBPOLL, "-m", "rtu", "-a", str(UNIT), "-b", "19200", "-P", "none"]
            command += ["-s", "2", "-0", "-1", "-o", "2", *args, path, *values]
            result = await anyio.run_process(command, check=False)
            output = result.stdout.decode()
            assert result.returncode == 0, output + result.stderr.decode()
            return output

        assert "[0]: \t1" in await run("-t", "0", "-r", "0", "-c", "4")  # 01
        assert "[2]: \t1" in await run("-t", "1", "-r", "0", "-c", "3")  # 02
        assert "[2]: \t33" in await run("-t", "3", "-r", "0", "-c", "3")  # 04
        out = await run("-t", "4:hex", "-r", "0", "-c", "3")  # 03
        assert "0XABCD" in out.upper()
        await run("-t", "0", "-r", "5", values=("1",))  # 05
        await run("-t", "0", "-r", "8", values=("1", "0", "1"))  # 0F
        await run("-t", "4", "-r", "6", values=("4660",))  # 06
        await run("-t", "4", "-r", "8", values=("1", "2", "3"))  # 10
        assert store.get(Table.COILS, 5) == [1]
        assert store.get(Table.COILS, 8, 3) == [1, 0, 1]
        assert store.get(Table.HOLDING_REGISTERS, 6) == [4660]
        assert store.get(Table.HOLDING_REGISTERS, 8, 3) == [1, 2, 3]
        assert MBPOLL is not None
        refused = await anyio.run_process(
            [
                *(MBPOLL, "-m", "rtu", "-a", str(UNIT), "-b", "19200", "-P", "none", "-s", "2"),
                *("-0", "-1", "-o", "1", "-t", "4", "-r", "100", "-c", "2", path),
            ],
            check=False,
        )
        assert refused.returncode != 0 or b"Illegal data address" in refused.stdout + refused.stderr


async def test_our_master_reads_what_pymodbus_cannot() -> None:
    import aiortu

    store = device()
    async with (
        pty_slave(store) as (path, _),
        aiortu.open_master(path, parity="N", stopbits=2, timeout=1, retries=0) as master,
    ):
        assert await master.read_fifo_queue(UNIT, 0x04DE) == [440, 25]
        objects = await master.read_device_identification(UNIT, 3)
        assert objects[4] == b"meter"
        log = await master.get_comm_event_log(UNIT)
        assert log.message_count == 3

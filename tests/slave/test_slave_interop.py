"""Interop: pymodbus's async serial client reads and writes our slave over a pty pair."""

from __future__ import annotations

import contextlib
import os
import tty

import anyio
import pytest

import aiortu
from aiortu.core.rtu import encode_frame
from aiortu.core.serial import LineSettings
from aiortu.slave import MemoryStore, Slave, Table
from aiortu.transport import FileDescriptorStream

pymodbus_client = pytest.importorskip("pymodbus.client")

pytestmark = pytest.mark.interop

# pyserial cannot set parity on a pty everywhere; the format does not matter on one.
LINE = LineSettings(19200, 8, "N", 2)


async def test_pymodbus_client_reads_and_writes_holding_registers() -> None:
    master_fd, slave_fd = os.openpty()
    tty.setraw(slave_fd)
    path = os.ttyname(slave_fd)
    store = MemoryStore(holding_registers={0: [0x1234, 0xABCD, 7] + [0] * 7})
    slave = Slave(FileDescriptorStream(master_fd), {1: store}, LINE, frame_gap=0.0)
    client = pymodbus_client.AsyncModbusSerialClient(
        path, baudrate=19200, parity="N", stopbits=2, timeout=2, retries=0
    )
    try:
        async with slave:
            assert await client.connect()
            read = await client.read_holding_registers(0, count=3, device_id=1)
            assert not read.isError()
            assert read.registers == [0x1234, 0xABCD, 7]
            written = await client.write_registers(4, [1, 2, 3], device_id=1)
            assert not written.isError()
            assert store.get(Table.HOLDING_REGISTERS, 4, 3) == [1, 2, 3]
            refused = await client.read_holding_registers(8, count=5, device_id=1)
            assert refused.isError()
            assert refused.exception_code == 0x02
    finally:
        client.close()
        with contextlib.suppress(OSError):
            os.close(slave_fd)


async def test_serve_opens_a_port_path_and_answers() -> None:
    master_fd, slave_fd = os.openpty()
    tty.setraw(slave_fd)
    os.set_blocking(master_fd, False)
    path = os.ttyname(slave_fd)
    store = aiortu.MemoryStore(holding_registers={0x6B: [0xAE41, 0x5652, 0x4340]})
    try:
        async with aiortu.serve(path, {17: store}, parity="N", stopbits=2, frame_gap=0) as slave:
            assert isinstance(slave, aiortu.Slave)
            await anyio.sleep(0.05)  # the receiver first waits for silence
            os.write(master_fd, encode_frame(17, bytes.fromhex("03 00 6B 00 03")))
            reply = bytearray()
            with anyio.fail_after(2):
                while len(reply) < 11:
                    await anyio.wait_readable(master_fd)
                    with contextlib.suppress(BlockingIOError):
                        reply += os.read(master_fd, 64)
        assert bytes(reply) == bytes.fromhex("11 03 06 AE 41 56 52 43 40 49 AD")
    finally:
        for fd in (master_fd, slave_fd):
            with contextlib.suppress(OSError):
                os.close(fd)

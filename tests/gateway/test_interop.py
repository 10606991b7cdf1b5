"""Real peers through the gateway: pymodbus's async TCP client and aiortu's Modbus TCP master
to an aiortu slave on a virtual line, and mbpoll -m tcp through the `aiortu gateway` command
to `aiortu serve` on a pty bus."""

from __future__ import annotations

import re
import shutil
import signal
import subprocess
from collections.abc import AsyncIterator
from contextlib import asynccontextmanager

import anyio
import anyio.abc
import pytest

from aiortu.testing import PtyBus
from tests.cli.cli_helpers import aiortu_command
from tests.gateway.helpers import UNIT, device, line
from tests.slave.test_tcp_interop import UNIT_ID, _data_codes, _ok

pymodbus_client = pytest.importorskip("pymodbus.client")

pytestmark = [pytest.mark.interop, pytest.mark.timeout(60)]

MBPOLL = shutil.which("mbpoll")


async def test_pymodbus_async_client_every_function_code_through_the_gateway() -> None:
    store = device()
    async with line({UNIT: store}, master_options={"timeout": 1.0}) as bench:
        client = pymodbus_client.AsyncModbusTcpClient(
            "127.0.0.1", port=bench.gateway.port, timeout=3, retries=0
        )
        try:
            assert await client.connect()
            await _data_codes(client, store)
            # The serial line codes: the device on the line answers them.
            assert (await _ok(client.read_exception_status(**UNIT_ID))).status == 0x6D
            echo = await _ok(client.diag_query_data(b"\xa5\x37", **UNIT_ID))
            assert echo.message == b"\xa5\x37"
            await _ok(client.diag_get_comm_event_counter(**UNIT_ID))
            await _ok(client.diag_get_comm_event_log(**UNIT_ID))
            assert (await _ok(client.report_device_id(**UNIT_ID))).identifier[:1] == b"\x11"
            # A unit that is not on the line: 0B once the master gave up on it.
            missing = await client.read_holding_registers(0, count=1, device_id=5)
            assert missing.isError()
            assert missing.exception_code == 0x0B
        finally:
            client.close()


async def _line_from(stream: anyio.abc.ByteReceiveStream, pattern: bytes) -> re.Match[bytes]:
    text = b""
    with anyio.fail_after(20):
        while (found := re.search(pattern, text)) is None:
            text += await stream.receive()
    return found


@asynccontextmanager
async def _command(*args: str) -> AsyncIterator[anyio.abc.Process]:
    command = aiortu_command(*args)
    async with await anyio.open_process(command, stderr=subprocess.PIPE) as process:
        try:
            yield process
        finally:
            if process.returncode is None:
                process.send_signal(signal.SIGTERM)
                with anyio.fail_after(20):
                    assert await process.wait() == 0


@pytest.mark.skipif(MBPOLL is None, reason="mbpoll is not installed")
async def test_mbpoll_through_the_gateway_command() -> None:
    assert MBPOLL is not None
    with PtyBus(2).running_in_thread() as bus:
        config = "examples/devices.toml"
        async with (
            _command("serve", bus.paths[1], "--config", config) as slave,
            _command("gateway", bus.paths[0], "--listen", "tcp://127.0.0.1:0") as gateway,
        ):
            assert slave.stderr is not None
            assert gateway.stderr is not None
            await _line_from(slave.stderr, rb"Ctrl-C")
            port = (await _line_from(gateway.stderr, rb"127\.0\.0\.1:(\d+);"))[1].decode()
            poll = [MBPOLL, "-m", "tcp", "-a", "17", "-p", port, "-1", "-o", "2"]
            result = await anyio.run_process([*poll, "-r", "108", "-c", "3", "127.0.0.1"])
            assert b"[108]: \t-20927" in result.stdout or b"[108]: \t44609" in result.stdout
            # A write, then the same registers read back through the line.
            await anyio.run_process([*poll, "-r", "109", "127.0.0.1", "1234", "5678"])
            result = await anyio.run_process([*poll, "-r", "109", "-c", "2", "127.0.0.1"])
            assert b"[109]: \t1234" in result.stdout
            assert b"[110]: \t5678" in result.stdout


@pytest.mark.skipif(MBPOLL is None, reason="mbpoll is not installed")
async def test_mbpoll_gets_0b_for_a_missing_unit_within_its_default_timeout() -> None:
    # The gateway's defaults answer a unit that does not answer within mbpoll's 1 s: mbpoll
    # prints the exception, not "Connection timed out".
    assert MBPOLL is not None
    with PtyBus(2).running_in_thread() as bus:
        async with (
            _command("serve", bus.paths[1], "--config", "examples/devices.toml") as slave,
            _command("gateway", bus.paths[0], "--listen", "tcp://127.0.0.1:0") as gateway,
        ):
            assert slave.stderr is not None
            assert gateway.stderr is not None
            await _line_from(slave.stderr, rb"Ctrl-C")
            port = (await _line_from(gateway.stderr, rb"127\.0\.0\.1:(\d+);"))[1].decode()
            poll = [MBPOLL, "-m", "tcp", "-a", "50", "-p", port, "-1", "-r", "1", "127.0.0.1"]
            result = await anyio.run_process(poll, check=False)
            output = result.stdout + result.stderr
            assert b"Target device failed to respond" in output, output  # libmodbus: 0B
            assert b"timed out" not in output


async def test_aiortu_modbus_tcp_master_through_the_gateway() -> None:
    # aiortu's own master over Modbus TCP, as a network client of the line server: the
    # same Master API end to end, transaction ids matched by the master, 0B for a unit the
    # line does not answer.
    import aiortu

    store = device()
    async with line({UNIT: store}, master_options={"timeout": 1.0}) as bench:
        url = f"tcp://127.0.0.1:{bench.gateway.port}"
        async with aiortu.open_master(url, timeout=3.0, retries=0) as master:
            await master.write_registers(UNIT, 0, [215, 7, 8])
            assert await master.read_holding_registers(UNIT, 0, 3) == [215, 7, 8]
            await master.write_coil(UNIT, 1, True)
            assert (await master.read_coils(UNIT, 0, 2))[1] is True
            assert await master.read_input_registers(UNIT, 0, 2) == list(
                store.read(aiortu.slave.Table.INPUT_REGISTERS, 0, 2)
            )
            with pytest.raises(aiortu.ExceptionResponse) as refused:
                await master.read_holding_registers(5, 0, 1)
            assert (
                refused.value.code == aiortu.ExceptionCode.GATEWAY_TARGET_DEVICE_FAILED_TO_RESPOND
            )

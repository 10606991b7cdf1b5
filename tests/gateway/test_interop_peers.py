"""The gateway with real peers on both sides: pymodbus's TCP clients (sync and async) through
it to pymodbus's RTU server on a pty bus, and the gateway against mbusd (a C Modbus TCP to
RTU gateway) answering the same client script byte for byte."""

from __future__ import annotations

import contextlib
import os
import shutil
import socket
import struct
import subprocess
import sys
import time
from collections.abc import AsyncIterator, Iterator
from pathlib import Path
from typing import Any

import anyio
import pytest

import aiortu
from aiortu.core.serial import LineSettings
from aiortu.testing import PtyBus
from tests import pymodbus_server
from tests.pymodbus_server import COILS, DISCRETE_INPUTS, HOLDING_REGISTERS, INPUT_REGISTERS

pymodbus_client = pytest.importorskip("pymodbus.client")

pytestmark = [pytest.mark.interop, pytest.mark.timeout(90)]

SETTINGS = LineSettings(19200, parity="N", stopbits=2)
LINE: dict[str, Any] = {
    "baudrate": 19200,
    "parity": "N",
    "stopbits": 2,
    "timeout": 0.5,
    "retries": 0,
}
UNIT = {"device_id": 1}

MBUSD = os.environ.get("AIORTU_MBUSD", "/tmp/mbusd-build/mbusd")
# The peers' sources sit in shared/, beside the repository.
BUILD_MBUSD = str(Path(__file__).resolve().parents[3] / "shared" / "peers" / "build-mbusd.sh")

# Every request pymodbus's clients can send, with the reply expected from pymodbus's RTU
# server (a value to compare, or None for "no exception"). Writes come before the reads of
# what they wrote. Left out: force listen only (the server would stop answering), restart
# communication (it resets the server's state), and change ASCII input delimiter (see
# test_change_ascii_input_delimiter_as_pymodbus_sends_it).
CALLS: list[tuple[str, tuple[Any, ...], dict[str, Any], str | None, Any]] = [
    ("read_coils", (0,), {"count": 10}, "bits", COILS[:10] + [False] * 6),
    ("read_discrete_inputs", (0,), {"count": 8}, "bits", DISCRETE_INPUTS[:8]),
    ("read_holding_registers", (0,), {"count": 3}, "registers", HOLDING_REGISTERS[:3]),
    ("read_input_registers", (2,), {"count": 5}, "registers", INPUT_REGISTERS[2:7]),
    ("write_coil", (20, True), {}, None, None),
    ("write_register", (20, 0xBEEF), {}, None, None),
    ("write_coils", (21, [True, False, True]), {}, None, None),
    ("write_registers", (21, [1, 2, 3]), {}, None, None),
    ("read_coils", (20,), {"count": 4}, "bits", [True, True, False, True] + [False] * 4),
    ("read_holding_registers", (20,), {"count": 4}, "registers", [0xBEEF, 1, 2, 3]),
    ("mask_write_register", (), {"address": 21, "and_mask": 0xF2, "or_mask": 0x25}, None, None),
    (
        "readwrite_registers",
        (),
        {"read_address": 21, "read_count": 2, "write_address": 22, "values": [9]},
        "registers",
        [0x05, 9],  # (1 AND 0xF2) OR (0x25 AND NOT 0xF2)
    ),
    ("read_exception_status", (), {}, None, None),
    ("diag_query_data", (b"\xa5\x37",), {}, "message", b"\xa5\x37"),
    ("diag_read_diagnostic_register", (), {}, None, None),
    ("diag_clear_counters", (), {}, None, None),
    ("diag_read_bus_message_count", (), {}, None, None),
    ("diag_read_bus_comm_error_count", (), {}, None, None),
    ("diag_read_bus_exception_error_count", (), {}, None, None),
    ("diag_read_device_message_count", (), {}, None, None),
    ("diag_read_device_no_response_count", (), {}, None, None),
    ("diag_read_device_nak_count", (), {}, None, None),
    ("diag_read_device_busy_count", (), {}, None, None),
    ("diag_read_bus_char_overrun_count", (), {}, None, None),
    ("diag_read_iop_overrun_count", (), {}, None, None),
    ("diag_clear_overrun_counter", (), {}, None, None),
    ("diag_getclear_modbus_response", (), {}, None, None),
    ("diag_get_comm_event_counter", (), {}, None, None),
    ("diag_get_comm_event_log", (), {}, None, None),
    ("report_device_id", (), {}, None, None),
    ("read_device_information", (), {"read_code": 1, "object_id": 0}, None, None),
]


def _check(name: str, reply: Any, attribute: str | None, expected: Any) -> None:
    assert not reply.isError(), f"{name}: {reply}"
    if attribute is not None:
        assert getattr(reply, attribute) == expected, name


@pytest.fixture(scope="module")
def line() -> Iterator[str]:
    """A paced pty bus with pymodbus's RTU server on port 1; yield port 0."""
    with (
        PtyBus(2, settings=SETTINGS).running_in_thread() as bus,
        pymodbus_server.running(bus.paths[1]),
    ):
        yield bus.paths[0]


@contextlib.asynccontextmanager
async def _gateway(port: str) -> AsyncIterator[int]:
    # Not a fixture: the gateway's task group must be left in the task that entered it.
    async with aiortu.gateway(port, ["tcp://127.0.0.1:0"], **LINE) as server:
        yield server.port


async def test_async_client_every_function_code(line: str) -> None:
    async with _gateway(line) as port:
        client = pymodbus_client.AsyncModbusTcpClient("127.0.0.1", port=port, timeout=3, retries=0)
        try:
            assert await client.connect()
            for name, args, kwargs, attribute, expected in CALLS:
                reply = await getattr(client, name)(*args, **kwargs, **UNIT)
                _check(name, reply, attribute, expected)
            # pymodbus's server answers a unit it does not serve with exception 04 (it is not
            # silent, as a missing device is): the gateway passes the exception on.
            other = await client.read_holding_registers(0, count=1, device_id=9)
            assert other.isError()
            assert other.exception_code == 0x04
        finally:
            client.close()


async def test_change_ascii_input_delimiter_as_pymodbus_sends_it(line: str) -> None:
    async with _gateway(line) as port:
        client = pymodbus_client.AsyncModbusTcpClient("127.0.0.1", port=port, timeout=3, retries=0)
        try:
            assert await client.connect()
            assert not (await client.diag_change_ascii_input_delimeter(**UNIT)).isError()
        finally:
            client.close()


def _sync_script(port: int) -> None:
    client = pymodbus_client.ModbusTcpClient("127.0.0.1", port=port, timeout=3, retries=0)
    try:
        assert client.connect()
        for name, args, kwargs, attribute, expected in CALLS:
            _check(name, getattr(client, name)(*args, **kwargs, **UNIT), attribute, expected)
        refused = client.read_holding_registers(60, count=5, **UNIT)
        assert refused.isError()
        assert refused.exception_code == 0x02
    finally:
        client.close()


async def test_sync_clients_every_function_code_two_at_once(line: str) -> None:
    async with _gateway(line) as port, anyio.create_task_group() as tasks:
        for _ in range(2):
            tasks.start_soon(anyio.to_thread.run_sync, _sync_script, port)


# -- the same script through mbusd and through the gateway ----------------------------------


def _mbap(transaction: int, unit: int, pdu: str) -> bytes:
    body = bytes.fromhex(pdu)
    return struct.pack(">HHHB", transaction, 0, len(body) + 1, unit) + body


# Requests of the codes mbusd forwards (01-07, 0F, 10): writes before the reads of what they
# wrote, so that running the script twice against the same slave gives the same replies.
SCRIPT = [
    _mbap(1, 1, "0F 0020 0005 01 15"),  # write coils 32..36: 1 0 1 0 1
    _mbap(2, 1, "10 0020 0003 06 0001 0002 FFFF"),  # write registers 32..34
    _mbap(3, 1, "05 0025 FF00"),  # write coil 37 on
    _mbap(4, 1, "06 0023 1234"),  # write register 35
    _mbap(5, 1, "01 0020 0008"),  # read coils 32..39
    _mbap(6, 1, "02 0000 000B"),  # read discrete inputs 0..10
    _mbap(7, 1, "03 0020 0004"),  # read holding registers 32..35
    _mbap(8, 1, "04 0002 0005"),  # read input registers 2..6
    _mbap(9, 1, "07"),  # read exception status
    _mbap(10, 1, "03 0040 0005"),  # out of the server's range: exception 02
    _mbap(11, 1, "05 0001 1234"),  # not a coil value: both forward it as it is
    _mbap(0x7F01, 1, "03 0000 0001"),  # a high transaction id comes back as it was
]


def _free_port() -> int:
    with socket.socket() as probe:
        probe.bind(("127.0.0.1", 0))
        return int(probe.getsockname()[1])


def _receive(sock: socket.socket) -> bytes:
    data = b""
    while len(data) < 6 or len(data) < 6 + struct.unpack(">H", data[4:6])[0]:
        chunk = sock.recv(260)
        assert chunk, "the gateway closed the connection"
        data += chunk
    return data


def _run_script(port: int) -> list[bytes]:
    with socket.create_connection(("127.0.0.1", port), timeout=5) as sock:
        replies = []
        for request in SCRIPT:
            sock.sendall(request)
            replies.append(_receive(sock))
        return replies


@contextlib.contextmanager
def _process(argv: list[str], port: int) -> Iterator[None]:
    process = subprocess.Popen(argv, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    try:
        for _ in range(200):
            assert process.poll() is None, f"{argv[0]} exited with {process.returncode}"
            with contextlib.suppress(OSError), socket.create_connection(("127.0.0.1", port), 0.2):
                break
            time.sleep(0.05)
        yield
    finally:
        process.terminate()
        process.wait(timeout=10)


def _mbusd() -> str:
    """The mbusd binary, built with the peers' build script when missing."""
    if not os.access(MBUSD, os.X_OK) and os.path.exists(BUILD_MBUSD):
        if shutil.which("cmake") is None or shutil.which("cc") is None:
            pytest.skip("mbusd cannot be built here: cmake and a C compiler are missing")
        build = subprocess.run(
            ["bash", BUILD_MBUSD, os.path.dirname(MBUSD)], capture_output=True, check=False
        )
        assert build.returncode == 0, build.stderr.decode(errors="replace")
    if not os.access(MBUSD, os.X_OK):
        pytest.skip(f"no mbusd at {MBUSD} and no {BUILD_MBUSD} to build it")
    return MBUSD


def test_mbusd_and_the_gateway_answer_the_same_script_the_same_way(line: str) -> None:
    mbusd = _mbusd()
    replies = {}
    port = _free_port()
    argv = [mbusd, "-d", "-L", "/dev/null", "-p", line, "-s", "19200", "-m", "8N2"]
    argv += ["-A", "127.0.0.1", "-P", str(port), "-R", "1", "-N", "0", "-W", "500"]
    with _process(argv, port):
        replies["mbusd"] = _run_script(port)
    port = _free_port()
    argv = [sys.executable, "-m", "aiortu", "gateway", line, "--listen", f"tcp://127.0.0.1:{port}"]
    argv += ["--parity", "N", "--stopbits", "2", "--retries", "0", "--timeout", "0.5"]
    with _process(argv, port):
        replies["aiortu"] = _run_script(port)
    assert replies["aiortu"] == replies["mbusd"]
    # And they are the answers, not two gateways wrong the same way.
    assert replies["aiortu"][4] == _mbap(5, 1, "01 01 B5")  # coil 39 was on
    assert replies["aiortu"][6] == _mbap(7, 1, "03 08 0001 0002 FFFF 1234")
    assert replies["aiortu"][9] == _mbap(10, 1, "83 02")
    # pymodbus's server takes any value but 0 for on (not exception 03) and echoes FF00.
    assert replies["aiortu"][10] == _mbap(11, 1, "05 0001 FF00")
    assert replies["aiortu"][11] == _mbap(0x7F01, 1, "03 02 1234")

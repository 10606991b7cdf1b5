"""``aiortu read``, ``write`` and ``poll`` as subprocesses against pymodbus's RTU server
on a pty bus (8N2): exact output, text and JSON; failures exit non-zero with one line."""

from __future__ import annotations

import json
from collections.abc import Iterator
from pathlib import Path

import pytest

from aiortu.core.serial import LineSettings
from aiortu.testing import PtyBus
from tests import pymodbus_server
from tests.cli.cli_helpers import run_aiortu
from tests.pymodbus_server import COILS, HOLDING_REGISTERS, INPUT_REGISTERS

pytestmark = [pytest.mark.interop, pytest.mark.timeout(90)]

LINE = ["--parity", "N", "--stopbits", "2"]


@pytest.fixture(scope="module")
def port() -> Iterator[str]:
    """A pty bus port whose other port pymodbus's server (unit 1) serves."""
    settings = LineSettings(19200, parity="N", stopbits=2)
    with (
        PtyBus(2, settings=settings).running_in_thread() as bus,
        pymodbus_server.running(bus.paths[1]),
    ):
        yield bus.paths[0]


@pytest.fixture(scope="module")
def silent_port() -> Iterator[str]:
    """A pty bus port with nobody else on the bus."""
    with PtyBus(2, settings=LineSettings(19200, parity="N", stopbits=2)).running_in_thread() as bus:
        yield bus.paths[0]


def test_read_holding_registers_as_text_and_json(port: str) -> None:
    text = run_aiortu("read", port, "--unit", "1", "--table", "holding", "--address", "0",
                  "--count", "3", *LINE)  # fmt: skip
    assert (text.returncode, text.stdout, text.stderr) == (0, "0 4660\n1 43981\n2 7\n", "")
    as_json = run_aiortu("read", port, "--unit", "1", "--ref", "40001", "--count", "3", "--json",
                     *LINE)  # fmt: skip
    assert as_json.returncode == 0, as_json.stderr
    assert (
        as_json.stdout
        == '{"unit": 1, "table": "holding", "address": 0, "values": [4660, 43981, 7]}\n'
    )


def test_read_the_other_tables(port: str) -> None:
    coils = run_aiortu("read", port, "--unit", "1", "--table", "coils", "--address", "0x3",
                   "--count", "5", "--json", *LINE)  # fmt: skip
    assert json.loads(coils.stdout) == {
        "unit": 1, "table": "coils", "address": 3, "values": COILS[3:8],
    }  # fmt: skip
    inputs = run_aiortu("read", port, "--unit", "1", "--ref", "30003", "--count", "2", *LINE)
    assert inputs.stdout == f"30003 {INPUT_REGISTERS[2]}\n30004 {INPUT_REGISTERS[3]}\n"
    discrete = run_aiortu("read", port, "--unit", "1", "--table", "discrete", "--address", "0",
                      "--count", "3", *LINE)  # fmt: skip
    assert discrete.stdout == "0 0\n1 1\n2 0\n"


def test_write_then_read_back(port: str) -> None:
    written = run_aiortu("write", port, "--unit", "1", "--table", "holding", "--address", "35",
                     "--values", "1,0x10,65535", "--json", *LINE)  # fmt: skip
    assert (written.returncode, written.stderr) == (0, "")
    assert (
        written.stdout
        == '{"unit": 1, "table": "holding", "address": 35, "values": [1, 16, 65535]}\n'
    )
    back = run_aiortu("read", port, "--unit", "1", "--ref", "40036", "--count", "3", *LINE)
    assert back.stdout == "40036 1\n40037 16\n40038 65535\n"
    coils = run_aiortu("write", port, "--unit", "1", "--table", "coils", "--address", "30",
                   "--values", "on,off,true,0", *LINE)  # fmt: skip
    assert (coils.returncode, coils.stdout) == (0, "30 1\n31 0\n32 1\n33 0\n")
    single = run_aiortu("write", port, "--unit", "1", "--ref", "00040", "--values", "1", *LINE)
    assert (single.returncode, single.stdout) == (0, "00040 1\n")
    bits = run_aiortu("read", port, "--unit", "1", "--table", "coils", "--address", "30",
                  "--count", "4", "--json", *LINE)  # fmt: skip
    assert json.loads(bits.stdout)["values"] == [True, False, True, False]


def test_poll_prints_plain_cycles_when_piped(port: str) -> None:
    result = run_aiortu("poll", port, "--unit", "1", "--ref", "40001", "--count", "3",
                    "--cycles", "2", "--interval", "0.1", *LINE)  # fmt: skip
    assert result.returncode == 0, result.stderr
    assert "\x1b[" not in result.stdout
    blocks = result.stdout.strip("\n").split("\n\n")
    assert len(blocks) == 2
    for index, block in enumerate(blocks):
        lines = block.splitlines()
        assert lines[0].startswith(f"cycle {index + 1}  time ")
        assert lines[1:5] == [
            "POINT            UNIT  VALUE",
            "40001               1  4660",
            "40002               1  43981",
            "40003               1  7",
        ]
        assert lines[5].startswith("unit 1: online, latency ")


def test_poll_json_with_named_typed_points(port: str) -> None:
    result = run_aiortu("poll", port, "--point", "a=1:40001", "--point", "b=1:40002:int16",
                    "--point", "w=1:40001:uint32:CDAB", "--cycles", "1", "--json",
                    *LINE)  # fmt: skip
    assert result.returncode == 0, result.stderr
    samples = [json.loads(line) for line in result.stdout.splitlines()]
    assert samples == [
        {"cycle": 1, "name": "a", "unit": 1, "value": 0x1234, "error": None},
        {"cycle": 1, "name": "w", "unit": 1, "value": 0xABCD1234, "error": None},
        {"cycle": 1, "name": "b", "unit": 1, "value": 0xABCD - 0x10000, "error": None},
    ]
    assert HOLDING_REGISTERS[:2] == [0x1234, 0xABCD]


@pytest.mark.parametrize(
    ("args", "code", "message"),
    [
        (["read", "--unit", "1", "--table", "holding", "--address", "1000"], 4,
         "aiortu read: exception response ILLEGAL_DATA_ADDRESS (0x02) from unit 1, function 0x03"),
        (["read", "--unit", "1", "--table", "holding"], 2,
         "aiortu read: error: read needs --table and --address, or --ref"),
        (["read", "--unit", "1", "--table", "holding", "--address", "0", "--count", "126"], 2,
         "aiortu read: error: at most 125 registers can be read at once, not 126"),
        (["write", "--unit", "1", "--table", "coils", "--address", "0", "--values", "maybe"], 2,
         "aiortu write: error: --values must be 1, 0, true, false, on or off, not maybe"),
        (["write", "--unit", "1", "--ref", "30001", "--values", "1"], 2,
         "aiortu write: error: cannot write input registers: only coils and holding registers "
         "are writable"),
    ],
)  # fmt: skip
def test_failures_exit_non_zero_with_one_line(
    port: str, args: list[str], code: int, message: str
) -> None:
    command, *rest = args
    result = run_aiortu(command, port, *rest, *LINE)
    assert (result.returncode, result.stdout, result.stderr) == (code, "", message + "\n")


def test_no_reply_and_no_port(silent_port: str, tmp_path: Path) -> None:
    timeout = run_aiortu("read", silent_port, "--unit", "1", "--ref", "40001", "--timeout", "0.2",
                     *LINE)  # fmt: skip
    assert timeout.returncode == 3
    assert timeout.stdout == ""
    assert timeout.stderr == "aiortu read: no reply from unit 1 to function 0x03 within 0.2 s\n"
    assert timeout.stderr.count("\n") == 1
    missing = run_aiortu("write", str(tmp_path / "ttyNONE"), "--unit", "1", "--ref", "40001",
                     "--values", "1", *LINE)  # fmt: skip
    assert missing.returncode == 1
    assert missing.stderr.startswith(f"aiortu write: {tmp_path / 'ttyNONE'}: ")
    assert missing.stderr.count("\n") == 1


def test_poll_shows_an_offline_unit(silent_port: str) -> None:
    result = run_aiortu("poll", silent_port, "--unit", "5", "--ref", "40001", "--cycles", "4",
                    "--interval", "0.05", "--timeout", "0.1", *LINE)  # fmt: skip
    assert result.returncode == 0, result.stderr
    blocks = [block.splitlines() for block in result.stdout.strip("\n").split("\n\n")]
    assert blocks[0][2] == "40001               5  -- no reply"
    # Suspect after one failed read, and still read; offline after three in a row (the
    # master's offline_after), then skipped until a probe is due.
    assert blocks[0][3] == "unit 5: suspect, 1 failure in a row"
    assert blocks[1][2] == "40001               5  -- no reply"
    assert blocks[1][3] == "unit 5: suspect, 2 failures in a row"
    assert blocks[2][3].startswith("unit 5: OFFLINE, 3 failures in a row, next probe in ")
    assert blocks[3][2] == "40001               5  -- skipped, unit offline"


@pytest.fixture(scope="module")
def tcp_url() -> Iterator[str]:
    """The URL of pymodbus's Modbus TCP server (unit 1)."""
    with pymodbus_server.running_tcp() as tcp_port:
        yield f"tcp://127.0.0.1:{tcp_port}"


def test_read_write_and_poll_over_modbus_tcp(tcp_url: str) -> None:
    text = run_aiortu("read", tcp_url, "--unit", "1", "--table", "holding", "--address", "0",
                  "--count", "3")  # fmt: skip
    assert (text.returncode, text.stdout, text.stderr) == (0, "0 4660\n1 43981\n2 7\n", "")
    written = run_aiortu("write", tcp_url, "--unit", "1", "--ref", "40021", "--values", "5,6")
    assert (written.returncode, written.stdout, written.stderr) == (0, "40021 5\n40022 6\n", "")
    polled = run_aiortu("poll", tcp_url, "--unit", "1", "--ref", "40021", "--count", "2",
                    "--cycles", "1")  # fmt: skip
    assert polled.returncode == 0, polled.stderr
    assert polled.stdout.splitlines()[1:4] == [
        "POINT            UNIT  VALUE",
        "40021               1  5",
        "40022               1  6",
    ]
    refused = run_aiortu("read", tcp_url, "--unit", "1", "--ref", "41001", "--count", "2")
    assert refused.returncode == 4

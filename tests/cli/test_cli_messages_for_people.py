"""Messages reworded for people, each where it is produced: request limits in words, a
number that is not one, a directory given as a device or a file, a Modbus TCP address
without its scheme, a URL without its port number, and a pty that keeps no parity and 8 data
bits (from the library too)."""

from __future__ import annotations

from pathlib import Path

import pytest

import aiortu
from aiortu.errors import UnsupportedSettings
from aiortu.testing import PtyBus
from tests.cli.cli_helpers import run_aiortu

pytestmark = pytest.mark.timeout(60)

NOWHERE = "/nonexistent/ttyX"
"""A port that cannot be opened: the checks must come before opening it."""


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (["write", NOWHERE, "--unit", "1", "--ref", "40001", "--values", ",".join(["1"] * 124)],
         "aiortu write: error: at most 123 registers can be written at once, not 124"),
        (["write", NOWHERE, "--unit", "1", "--ref", "00001", "--values", ",".join(["1"] * 1969)],
         "aiortu write: error: at most 1968 coils can be written at once, not 1969"),
        (["write", NOWHERE, "--unit", "1", "--ref", "465536", "--values", "1,2"],
         "aiortu write: error: the registers written must end at address 65535 or before, "
         "not 65536 (65535 + 2 registers)"),
        (["read", NOWHERE, "--unit", "1", "--ref", "30001", "--count", "126"],
         "aiortu read: error: at most 125 input registers can be read at once, not 126"),
        (["read", NOWHERE, "--unit", "1", "--table", "discrete", "--address", "65535",
          "--count", "2"],
         "aiortu read: error: the discrete inputs read must end at address 65535 or before, "
         "not 65536 (65535 + 2 discrete inputs)"),
        (["poll", NOWHERE, "--unit", "1", "--ref", "40001", "--scale", "abc"],
         "aiortu poll: error: argument --scale: 'abc' is not a number"),
        (["read", "tcp://127.0.0.1", "--unit", "1", "--ref", "40001"],
         "aiortu read: error: PORT must be a serial device path, rtu+tcp://host:port, "
         "ascii+tcp://host:port, tcp://host:port, udp://host:port or tls://host:port, not "
         "tcp://127.0.0.1 (the port number is missing: tcp://host:port)"),
        (["read", "/tmp", "--unit", "1", "--ref", "40001"],
         "aiortu read: /tmp: a directory, not a device file"),
        (["serve", "/dev/null", "--config", "/tmp"],
         "aiortu serve: error: --config /tmp is a directory, not a TOML file"),
        (["serve", "/dev/null", "--config", "/nonexistent/devices.toml"],
         "aiortu serve: error: --config /nonexistent/devices.toml does not exist"),
        (["read", "127.0.0.1:1502", "--unit", "1", "--ref", "40001"],
         "aiortu read: 127.0.0.1:1502: no such serial device (No such file or directory); for "
         "Modbus TCP write tcp://127.0.0.1:1502 (RTU over TCP: rtu+tcp://)"),
    ],
)  # fmt: skip
def test_each_message_in_words(args: list[str], message: str) -> None:
    result = run_aiortu(*args)
    assert result.returncode in (1, 2)
    assert (result.stdout, result.stderr) == ("", message + "\n")


def test_a_device_path_is_not_taken_for_a_tcp_address(tmp_path: Path) -> None:
    result = run_aiortu("read", str(tmp_path / "ttyUSB0"), "--unit", "1", "--ref", "40001")
    assert result.returncode == 1
    assert "tcp://" not in result.stderr


async def test_the_library_says_what_to_open_a_pty_with() -> None:
    async with PtyBus() as bus:
        path = bus.paths[0]
        with pytest.raises(UnsupportedSettings) as refused:
            async with aiortu.open_master(path, parity="E"):
                pass
    assert str(refused.value) == (
        f"{path}: the driver kept 8N1 instead of 8E1; a pseudo-terminal keeps no "
        "parity bit: open it with parity N and 2 stop bits (8N2, the same character time as 8E1)"
    )


def test_the_command_adds_its_flags_to_the_librarys_pty_hint() -> None:
    with PtyBus().running_in_thread() as bus:
        result = run_aiortu("read", bus.paths[0], "--unit", "1", "--ref", "40001", "--parity", "E")
    assert result.returncode == 1
    assert result.stderr.endswith(
        "(8N2, the same character time as 8E1); on the command line: --bytesize 8 --parity N "
        "--stopbits 2, or leave them out\n"
    )
    assert result.stderr.count("\n") == 1


async def test_the_library_says_a_pty_keeps_8_data_bits() -> None:
    async with PtyBus() as bus:
        path = bus.paths[0]
        with pytest.raises(UnsupportedSettings) as refused:
            async with aiortu.open_master(
                path, framing="ascii", bytesize=7, parity="N", stopbits=2
            ):
                pass
    assert str(refused.value) == (
        f"{path}: the driver kept 8N2 instead of 7N2; a pseudo-terminal keeps 8 data bits and "
        "no parity bit: open it with 8 data bits, parity N and 2 stop bits (8N2, the same "
        "character time as 8E1; for Modbus ASCII too, as long as both ends use it)"
    )


def test_the_command_names_bytesize_when_a_pty_refuses_7_data_bits() -> None:
    with PtyBus().running_in_thread() as bus:
        result = run_aiortu(
            "read", bus.paths[0], "--unit", "1", "--ref", "40001", "--framing", "ascii",
            "--bytesize", "7",
        )  # fmt: skip
    assert result.returncode == 1
    assert result.stderr.endswith(
        "as long as both ends use it); on the command line: --bytesize 8 --parity N "
        "--stopbits 2, or leave them out\n"
    )
    assert result.stderr.count("\n") == 1

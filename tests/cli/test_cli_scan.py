"""``aiortu scan``: against ``aiortu virtual-bus`` with a slave subprocess, and in process."""

from __future__ import annotations

import argparse
import contextlib
import io
import random
import subprocess
import sys
from pathlib import Path

import anyio
import pytest

from aiortu import MemoryStore, Slave
from aiortu.cli import main
from aiortu.cli._scan import (
    Answer,
    SettingResult,
    _Progress,
    parse_units,
    probe_units,
    report,
    settings_to_try,
)
from aiortu.core.serial import LineSettings, Parity
from aiortu.slave import BUILTIN_HANDLERS
from aiortu.testing import VirtualBus
from tests.cli.cli_helpers import run_aiortu, start_aiortu

pytestmark = pytest.mark.timeout(60)

SLAVE_SCRIPT = Path(__file__).parents[1] / "serve_units.py"
SETTINGS = LineSettings(19200, parity="N", stopbits=2)


@pytest.fixture(scope="module")
def bus_with_slaves(tmp_path_factory):
    """A two-port pty bus at 8N2 with units 3 and 6 served on port 1; yields port 0."""
    links = tmp_path_factory.mktemp("bus")
    bus = start_aiortu(
        "virtual-bus", "--ports", "2", "--parity", "N", "--stopbits", "2", "--link-dir", str(links)
    )
    slave = None
    try:
        assert bus.stdout is not None
        ports = [bus.stdout.readline().strip() for _ in range(2)]
        slave = subprocess.Popen(
            [sys.executable, str(SLAVE_SCRIPT), ports[1], "3", "6"],
            stdout=subprocess.PIPE,
            text=True,
        )
        assert slave.stdout is not None
        assert slave.stdout.readline().strip() == "ready"
        yield ports[0]
    finally:
        if slave is not None:
            slave.kill()
            slave.wait(timeout=10)
        bus.terminate()
        bus.wait(timeout=10)


def run_scan(*args: str) -> subprocess.CompletedProcess[str]:
    return run_aiortu("scan", *args)


def test_finds_exactly_the_units_served(bus_with_slaves):
    result = run_scan(
        bus_with_slaves, "--baudrates", "19200", "--parities", "N", "--units", "1-8",
        "--timeout", "0.1",
    )  # fmt: skip
    assert result.returncode == 0, result.stderr
    lines = result.stdout.splitlines()
    found = {int(line.split()[0]) for line in lines if line.split()[0].isdigit()}
    assert found == {3, 6}
    unit3 = next(line for line in lines if line.split()[0] == "3")
    assert "19200 8N2" in unit3
    assert "0x1234" in unit3
    unit6 = next(line for line in lines if line.split()[0] == "6")
    assert "exception 02 (ILLEGAL_DATA_ADDRESS)" in unit6
    assert lines[-1] == "found 2 units (3, 6) at 19200 8N2"
    # Progress without a terminal: plain lines on stderr, one per setting and result.
    assert "19200 8N2: units answering: 3, 6" in result.stderr


def test_nothing_found_exits_1(bus_with_slaves):
    result = run_scan(
        bus_with_slaves, "--baudrates", "19200", "--parities", "N", "--units", "10-12",
        "--timeout", "0.05", "--quiet",
    )  # fmt: skip
    assert result.returncode == 1
    assert result.stdout == "no unit answered at 1 line setting\n"
    assert result.stderr == ""


def test_refused_settings_are_skipped_and_first_stops(bus_with_slaves):
    # A pty keeps no parity: E is refused and skipped, N then finds the units.
    result = run_scan(
        bus_with_slaves, "--baudrates", "19200,9600", "--parities", "E,N", "--units", "2-3",
        "--timeout", "0.1", "--first",
    )  # fmt: skip
    assert result.returncode == 0, result.stderr
    assert "19200 8E1: skipped" in result.stderr
    assert "9600" not in result.stderr + result.stdout
    assert result.stdout.splitlines()[-1] == "found 1 unit (3) at 19200 8N2"


def test_every_setting_refused_is_one_line_and_exit_1(bus_with_slaves):
    result = run_scan(bus_with_slaves, "--parities", "E", "--baudrates", "19200", "-q")
    assert result.returncode == 1
    assert result.stdout == ""
    assert result.stderr.count("\n") == 2  # the skipped setting, then the error
    assert "refused every line setting" in result.stderr


def test_missing_port_exits_1_with_one_line():
    result = run_scan("/dev/no-such-port", "--quiet")
    assert result.returncode == 1
    assert result.stdout == ""
    assert result.stderr.count("\n") == 1
    assert "cannot open the port" in result.stderr


# -- in process --------------------------------------------------------------------


async def test_probe_units_on_a_virtual_bus():
    async with VirtualBus(2, settings=SETTINGS) as bus:
        stores = {2: MemoryStore(holding_registers={0: [7]}), 5: MemoryStore()}
        async with Slave(bus[1], stores, SETTINGS):
            seen: list[int] = []
            result = await probe_units(
                bus[0], SETTINGS, range(1, 7), timeout=0.05,
                on_probe=lambda unit, _: seen.append(unit),
            )  # fmt: skip
    assert seen == [1, 2, 3, 4, 5, 6]
    assert result.units == [2, 5]
    assert result.probed == 6
    assert result.garbled == 0
    by_unit = {answer.unit: answer for answer in result.answers}
    assert by_unit[2].answer == "holding register 0 (40001) = 7 (0x0007)"
    assert by_unit[5].answer.startswith("exception 02")
    assert all(a.latency is not None and 0 < a.latency < 0.05 for a in result.answers)


async def test_a_late_reply_still_counts():
    read_holding_registers = BUILTIN_HANDLERS[3]

    async def slow(request, context):
        await anyio.sleep(0.08)
        return read_holding_registers(request, context)

    async with VirtualBus(2, settings=SETTINGS) as bus:
        store = MemoryStore(holding_registers={0: 1})
        async with Slave(bus[1], {1: store}, SETTINGS, handlers={3: slow}):
            result = await probe_units(bus[0], SETTINGS, [1, 2, 3], timeout=0.03)
    assert result.units == [1]
    assert result.answers[0].latency is None


async def test_garbage_is_reported_as_garbled_traffic():
    async with VirtualBus(2, settings=SETTINGS) as bus:
        noise = random.Random(3)

        async def device_at_other_settings():
            # Hears noise where requests are, and answers noise, until the scan closes
            # its end of the line.
            with contextlib.suppress(anyio.EndOfStream):
                while True:
                    await bus[1].receive()
                    await bus[1].send(bytes(noise.randrange(256) for _ in range(7)))

        async with anyio.create_task_group() as group:
            group.start_soon(device_at_other_settings)
            result = await probe_units(bus[0], SETTINGS, [1, 2, 3], timeout=0.05)
            group.cancel_scope.cancel()
    assert result.answers == []
    assert result.garbled >= 3
    out = io.StringIO()
    assert report([result], out) is False
    assert "traffic but garbled at 19200 8N2" in out.getvalue()
    assert "wrong line settings likely" in out.getvalue()


# -- arguments and output ------------------------------------------------------------


def test_parse_units():
    assert parse_units("1-3,7,2") == [1, 2, 3, 7]
    assert parse_units("247") == [247]
    for bad in ("0", "248", "5-3", "x", "1-"):
        with pytest.raises(argparse.ArgumentTypeError):
            parse_units(bad)


def test_settings_follow_the_stop_bit_rule():
    assert [str(s) for s in settings_to_try([9600, 19200], [Parity.EVEN, Parity.NONE])] == [
        "9600 8E1", "9600 8N2", "19200 8E1", "19200 8N2",
    ]  # fmt: skip
    assert [str(s) for s in settings_to_try([9600], [Parity.NONE], 1)] == ["9600 8N1"]


class FakeTerminal(io.StringIO):
    def isatty(self) -> bool:
        return True


def test_progress_bar_on_a_terminal():
    err = FakeTerminal()
    progress = _Progress(err, 4, quiet=False)
    progress.setting(SETTINGS)
    result = SettingResult(SETTINGS)
    progress.probe(1, result)
    progress.probe(2, result)
    assert "\r[" in err.getvalue()
    assert " 50%" in err.getvalue()
    progress.result(result, 2)
    assert err.getvalue().endswith("aiortu scan: 19200 8N2: units answering: none\n")


@pytest.mark.parametrize(
    "argv",
    [
        ["scan"],
        ["scan", "/dev/x", "--units", "0-3"],
        ["scan", "/dev/x", "--baudrates", "fast"],
        ["scan", "/dev/x", "--parities", "Q"],
        ["scan", "/dev/x", "--timeout", "0"],
        ["scan", "/dev/x", "--stopbits", "3"],
    ],
)
def test_bad_arguments_exit_2(argv, capsys):
    with pytest.raises(SystemExit) as raised:
        main(argv)
    assert raised.value.code == 2
    assert len(capsys.readouterr().err.strip().splitlines()) == 1


def test_help_has_examples_and_mbpoll_flags(capsys):
    with pytest.raises(SystemExit):
        main(["scan", "--help"])
    out = capsys.readouterr().out
    assert "examples:" in out
    assert "mbpoll -b 9600" in out
    assert "exit codes:" in out


def test_a_pty_ignores_baud_rates_so_it_is_probed_once(bus_with_slaves):
    result = run_scan(bus_with_slaves, "--units", "1-8", "--timeout", "0.05")
    assert result.returncode == 0, result.stderr
    assert result.stderr.splitlines()[:2] == [
        f"aiortu scan: {bus_with_slaves} is a pseudo-terminal, which ignores the baud rate: "
        "probing once, at 19200",
        f"aiortu scan: 8 units at 1 line setting on {bus_with_slaves}; at most 1 s",
    ]
    assert result.stdout.splitlines()[-1] == "found 2 units (3, 6) at 19200 8N2"
    assert [line.split()[0] for line in result.stdout.splitlines()[1:-1]] == ["3", "6"]


def test_a_missing_port_says_so_first_and_only():
    result = run_scan("/dev/no-such-port")
    assert (result.returncode, result.stdout) == (1, "")
    assert result.stderr == (
        "aiortu scan: cannot open the port: /dev/no-such-port: no such serial device\n"
    )


def test_line_settings_are_listed_by_baud_rate_as_a_number():
    results = []
    for rate in (115200, 19200, 38400, 9600):
        setting = LineSettings(rate, parity="N", stopbits=2)
        result = SettingResult(setting)
        result.answers.append(Answer(1, setting, "holding register 0 (40001) = 1", 0.01))
        results.append(result)
    out = io.StringIO()
    report(results, out)
    lines = out.getvalue().splitlines()
    assert lines[-1] == "found 1 unit (1) at 9600 8N2, 19200 8N2, 38400 8N2, 115200 8N2"
    assert [line.split()[1] for line in lines[1:-1]] == ["9600", "19200", "38400", "115200"]

"""The examples run on their own and print what they promise; the example suite passes."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

EXAMPLES = Path(__file__).parents[2] / "examples"

# Each script, and lines (or line beginnings) its output must contain.
EXPECTED = {
    "profile_device.py": [
        "flow_temperature  35.5 °C",
        "mode              heat",
        "setpoint now 48.5",
        "refused: heat-pump.toml: point setpoint: value 70 is outside the limits 20..55",
    ],
    "poll_several_devices.py": ["cycle 2 unit 3 voltage3   231.250", "unit 4: offline"],
    "typed_values.py": [
        "float32 CDAB at 2: 0000 41AC -> 21.5",
        "40108 = holding register 107 = 0x022B",
    ],
    "slave_with_handler.py": [
        "temperatures: [21.5, 21.6, 21.7, 21.8]",
        "observer: holding_registers 2: [0, 0] -> [7, 8]",
    ],
    "proxy_store.py": ["the far device now holds: [100, 200, 300, 401]"],
    "blocking_read.py": [
        "registers 0x6B..0x6D = [215, 7, 8]",
        "float32 at 0x10 = 21.5",
        "from two threads: {16: [16812, 0], 107: [215, 7]}",
        "unit 17: 6 requests, online True",
    ],
    "broadcast.py": ["unit 1: setpoint 215, registers 0..2 = [1, 2, 3]", "unit 3: setpoint 215"],
    "rtu_over_tcp.py": ["after the write: [1234]"],
    "modbus_tcp_master.py": [
        "registers 0..2 = [215, 7, 8]",
        "coils 0..3 = [True, False, True, False]",
        "register 100: exception 02",
        "requests 5, replies 5, dropped 0",
    ],
    "gateway_two_programs.py": [
        "tool: setpoint written, reply 06 00 00 00 d7",
        "logger: registers 0..2 = [215, 7, 8]",
        "the device: setpoint 215",
    ],
    "modbus_ascii.py": [
        "registers 0..2 = [215, 7, 8]",
        "ASCII frames the slave received: 2",
    ],
    "modbus_udp.py": [
        "registers 0..2 = [215, 7, 8]",
        "requests 2, replies 2, from strangers 0, refused 0",
    ],
    "modbus_tls.py": [
        "operator: setpoint written",
        "viewer: write refused with exception 01",
        "viewer: setpoint = 230",
        "requests denied by the rules: 1",
    ],
    "modbus_tcp_server.py": [
        "Modbus TCP transaction 2: reply 03 06 00 d7 00 07 00 08",
        "RTU over TCP: registers 0..2 = [215, 7, 8]",
    ],
}


def _run(*arguments: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        [sys.executable, *arguments],
        capture_output=True,
        text=True,
        timeout=60,
        check=False,
        cwd=EXAMPLES.parent,
    )


def test_every_example_script_is_checked() -> None:
    assert {path.name for path in EXAMPLES.glob("*.py")} == set(EXPECTED)


@pytest.mark.parametrize("script", sorted(EXPECTED))
def test_an_example_runs_and_prints(script: str) -> None:
    result = _run(str(EXAMPLES / script))
    assert result.returncode == 0, result.stderr
    lines = result.stdout.splitlines()
    for expected in EXPECTED[script]:
        assert any(line.startswith(expected) for line in lines), (expected, result.stdout)


def test_the_example_test_suite_passes() -> None:
    result = _run("-m", "pytest", "-q", "-p", "no:cacheprovider", "examples/tests")
    assert result.returncode == 0, result.stdout + result.stderr
    assert "3 passed" in result.stdout

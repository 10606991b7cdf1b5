"""mbpoll reads pymodbus's RTU server through ``aiortu virtual-bus``."""

from __future__ import annotations

import os
import shutil
import subprocess
import sys

import pytest

from tests import pymodbus_server

MBPOLL = shutil.which("mbpoll")

pytestmark = [
    pytest.mark.interop,
    pytest.mark.timeout(40),
    pytest.mark.skipif(
        MBPOLL is None and not os.environ.get("CI"), reason="mbpoll is not installed"
    ),
]


@pytest.fixture
def bus_paths():
    process = subprocess.Popen(
        [sys.executable, "-m", "aiortu", "virtual-bus", "--ports", "2", "--parity", "N",
         "--stopbits", "2"],
        stdout=subprocess.PIPE,
        text=True,
    )  # fmt: skip
    assert process.stdout is not None
    paths = [process.stdout.readline().strip() for _ in range(2)]
    yield paths
    process.terminate()
    assert process.wait(timeout=10) == 0


@pytest.fixture
def pymodbus(bus_paths):
    with pymodbus_server.running(bus_paths[1]):
        yield


def test_mbpoll_reads_pymodbus_holding_registers(bus_paths, pymodbus):
    assert MBPOLL is not None, "mbpoll must be installed in CI"
    result = subprocess.run(
        [MBPOLL, "-m", "rtu", "-a", "1", "-b", "19200", "-P", "none", "-s", "2",
         "-t", "4:hex", "-r", "1", "-c", "3", "-o", "2", "-1", bus_paths[0]],
        capture_output=True,
        text=True,
        timeout=20,
        check=False,
    )  # fmt: skip
    assert result.returncode == 0, result.stdout + result.stderr
    values = [line.split(":", 1)[1].strip() for line in result.stdout.splitlines()
              if line.startswith("[")]  # fmt: skip
    assert values == ["0x1234", "0xABCD", "0x0007"]

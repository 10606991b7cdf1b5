"""The getting-started pair in ``examples/getting_started``: the master reads and writes
through the slave on a pty bus, and the slave, which says Ctrl-C stops it, stops cleanly."""

from __future__ import annotations

import signal
import subprocess
import sys
from pathlib import Path

import pytest

from aiortu.core.serial import LineSettings
from aiortu.testing import PtyBus

pytestmark = pytest.mark.timeout(60)

HERE = Path(__file__).parents[2] / "examples" / "getting_started"


def test_the_slave_serves_the_master_and_stops_on_ctrl_c() -> None:
    with PtyBus(2, settings=LineSettings(19200, parity="N", stopbits=2)).running_in_thread() as bus:
        slave = subprocess.Popen(
            [sys.executable, str(HERE / "slave.py"), bus.paths[1]],
            stdout=subprocess.PIPE,
            stderr=subprocess.PIPE,
            text=True,
        )
        assert slave.stdout is not None
        assert slave.stdout.readline() == f"serving unit 1 on {bus.paths[1]}; Ctrl-C to stop\n"
        master = subprocess.run(
            [sys.executable, str(HERE / "master.py"), bus.paths[0]],
            capture_output=True,
            text=True,
            timeout=30,
            check=False,
        )
        assert master.returncode == 0, master.stderr
        assert master.stdout == "[215, 0, 0, 0]\n[215, 42, 0, 0]\n"
        assert slave.stdout.readline() == "written: 1 (42,)\n"
        slave.send_signal(signal.SIGINT)
        out, err = slave.communicate(timeout=10)
    assert slave.returncode == 0
    assert out == "stopped\n"
    assert err == ""

"""Starting and stopping the ``aiortu`` command: ``--help`` imports no subcommand, a command
imports only its own module, Ctrl-C while starting exits 130 without a traceback, and an
interrupted ``scan`` still reports the units it found."""

from __future__ import annotations

import importlib
import signal
import subprocess
import sys
import time
from collections.abc import Iterator
from pathlib import Path

import pytest

import aiortu.cli
from aiortu.cli import SUMMARIES, build_parser, main
from aiortu.core.serial import LineSettings
from aiortu.testing import PtyBus
from tests.cli.cli_helpers import aiortu_command

pytestmark = pytest.mark.timeout(60)

DEVICES = str(Path(__file__).parents[2] / "examples" / "devices.toml")


def modules_after(*code: str) -> set[str]:
    """The aiortu modules a fresh interpreter holds after running *code*."""
    script = "\n".join([*code, "import sys", "print(' '.join(sys.modules))"])
    result = subprocess.run(
        [sys.executable, "-c", script], capture_output=True, text=True, timeout=30, check=True
    )
    return {name for name in result.stdout.split() if name.startswith("aiortu")}


def test_help_imports_no_subcommand_and_no_library() -> None:
    loaded = modules_after(
        "import contextlib, io",
        "from aiortu.cli import main",
        "out = io.StringIO()",
        "with contextlib.redirect_stdout(out), contextlib.suppress(SystemExit): main(['--help'])",
    )
    assert loaded == {"aiortu", "aiortu.cli"}, loaded


def test_a_command_imports_only_its_own_module() -> None:
    loaded = modules_after(
        "import contextlib, io",
        "from aiortu.cli import main",
        "out = io.StringIO()",
        "with contextlib.redirect_stdout(out), contextlib.suppress(SystemExit): "
        "main(['virtual-bus', '--help'])",
    )
    commands = {name for name in loaded if name.startswith("aiortu.cli._")}
    assert commands == {"aiortu.cli._arguments", "aiortu.cli._virtual_bus"}, commands


def test_the_summaries_are_the_modules_help() -> None:
    parser = build_parser()
    actions = [a for a in parser._actions if a.dest == "command"]
    shown = {choice.dest: choice.help for choice in actions[0]._choices_actions}  # type: ignore[attr-defined]
    assert shown == SUMMARIES


def test_ctrl_c_while_importing_a_command_exits_130_quietly(
    monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    def interrupted(name: str) -> object:
        raise KeyboardInterrupt

    monkeypatch.setattr(importlib, "import_module", interrupted)
    assert main(["read", "/dev/null", "--unit", "1", "--ref", "40001"]) == 130
    assert capsys.readouterr() == ("", "")
    assert aiortu.cli  # the package itself imports nothing heavy (see above)


@pytest.fixture
def served_bus() -> Iterator[str]:
    """A pty bus whose second port ``aiortu serve`` serves (units 5, 6 and 17)."""
    with PtyBus(2, settings=LineSettings(19200, parity="N", stopbits=2)).running_in_thread() as bus:
        slave = subprocess.Popen(
            aiortu_command("serve", bus.paths[1], "--config", DEVICES),
            stderr=subprocess.PIPE,
            text=True,
        )
        assert slave.stderr is not None
        assert "Ctrl-C to stop" in slave.stderr.readline()
        try:
            yield bus.paths[0]
        finally:
            slave.terminate()
            slave.wait(timeout=10)


def test_an_interrupted_scan_reports_the_units_found_and_exits_130(served_bus: str) -> None:
    # The units served answer within milliseconds; the 148 after them take 0.1 s each.
    scan = subprocess.Popen(
        aiortu_command("scan", served_bus, "--units", "5,6,17,100-247", "--timeout", "0.1"),
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )  # fmt: skip
    assert scan.stderr is not None
    deadline = time.monotonic() + 30
    line = ""
    while "probing at" not in line and time.monotonic() < deadline:
        line = scan.stderr.readline()
    assert line == "aiortu scan: probing at 19200 8N2\n", line
    # The setting is under way, its answering units probed: interrupt it.
    time.sleep(1.0)
    scan.send_signal(signal.SIGINT)
    out, err = scan.communicate(timeout=10)
    assert scan.returncode == 130
    assert "Traceback" not in err
    assert "interrupted" in err
    assert "   5  19200 8N2" in out
    assert out.splitlines()[-1].startswith("found 3 units (5, 6, 17) at 19200 8N2")


def test_ctrl_c_during_a_read_exits_130_quietly() -> None:
    with PtyBus(2, settings=LineSettings(19200, parity="N", stopbits=2)).running_in_thread() as bus:
        read = subprocess.Popen(
            aiortu_command("read", bus.paths[0], "--unit", "1",
                           "--ref", "40001", "--timeout", "20"),
            stdout=subprocess.PIPE,
            stderr=subprocess.PIPE,
            text=True,
        )  # fmt: skip
        # Wait until the request is on the wire, so that the read is waiting for its reply.
        deadline = time.monotonic() + 20
        while not bus.trace and time.monotonic() < deadline:
            time.sleep(0.02)
        assert bus.trace
        read.send_signal(signal.SIGINT)
        out, err = read.communicate(timeout=10)
    assert (read.returncode, out, err) == (130, "", "")


def test_the_master_and_the_transports_load_pyserial_and_the_poller_on_first_use() -> None:
    script = "\n".join([
        "import sys",
        "import aiortu.master, aiortu.transport",
        "print(sorted(n for n in sys.modules if n == 'serial' or n.endswith('_poller')))",
        "aiortu.master.Poller, aiortu.transport.RS485Options",
        "print(sorted(n for n in sys.modules if n == 'serial' or n.endswith('_poller')))",
    ])  # fmt: skip
    result = subprocess.run(
        [sys.executable, "-c", script], capture_output=True, text=True, timeout=30, check=True
    )
    assert result.stdout.splitlines() == ["[]", "['aiortu.master._poller', 'serial']"]

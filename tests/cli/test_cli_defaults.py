"""The commands with their defaults against ``aiortu virtual-bus`` with its defaults, as a
new user runs them: no line flags anywhere. Ptys keep no parity, so both sides use 8N2 on
a pty unless told otherwise; a parity asked for on a pty is refused with the flags to use."""

from __future__ import annotations

import json
from collections.abc import Iterator
from pathlib import Path

import pytest

from tests.cli.cli_helpers import run_aiortu, start_aiortu, stop

pytestmark = pytest.mark.timeout(60)

DEVICES = str(Path(__file__).parents[2] / "examples" / "devices.toml")


@pytest.fixture(scope="module")
def bus() -> Iterator[list[str]]:
    """A default ``aiortu virtual-bus`` (three ports) with a default ``aiortu serve`` on its
    second port; the third is free for a monitor."""
    relay = start_aiortu("virtual-bus", "--ports", "3")
    assert relay.stdout is not None
    paths = [relay.stdout.readline().strip() for _ in range(3)]
    slave = start_aiortu("serve", paths[1], "--config", DEVICES)
    assert slave.stderr is not None
    banner = slave.stderr.readline()
    try:
        assert (
            banner == f"aiortu serve: units 5, 6, 17 on {paths[1]} at 19200 8N2; Ctrl-C to stop\n"
        )
        yield paths
    finally:
        stop(slave)
        stop(relay)


def test_read_with_its_defaults(bus: list[str]) -> None:
    result = run_aiortu("read", bus[0], "--unit", "17", "--ref", "40108", "--count", "3", "--json")
    assert result.returncode == 0, result.stderr
    assert json.loads(result.stdout)["values"] == [0xAE41, 0x5652, 0x4340]


def test_poll_with_its_defaults(bus: list[str]) -> None:
    result = run_aiortu("poll", bus[0], "--unit", "17", "--ref", "40108", "--cycles", "1")
    assert result.returncode == 0, result.stderr
    lines = result.stdout.splitlines()
    assert lines[0].startswith("cycle 1  time ")
    assert lines[2] == f"40108              17  {0xAE41}"
    assert lines[3].startswith("unit 17: online, latency ")


def test_a_parity_on_a_pty_is_refused_with_the_flags_to_use(bus: list[str]) -> None:
    result = run_aiortu("read", bus[0], "--unit", "17", "--ref", "40108", "--parity", "even")
    assert result.returncode == 1
    assert result.stderr == (
        f"aiortu read: {bus[0]}: the driver kept 8N1 instead of 8E1; a pseudo-terminal keeps "
        "no parity bit: open it with parity N and 2 stop bits (8N2, the same character time "
        "as 8E1); on the command line: --bytesize 8 --parity N --stopbits 2, or leave them out\n"
    )


def test_scan_with_its_defaults(bus: list[str]) -> None:
    result = run_aiortu("scan", bus[0], "--baudrates", "19200", "--units", "16-18", "-q")
    assert result.returncode == 0, result.stderr
    assert result.stdout.splitlines()[-1] == "found 1 unit (17) at 19200 8N2"


def test_monitor_with_its_defaults(bus: list[str]) -> None:
    monitor = start_aiortu("monitor", bus[2])
    assert monitor.stderr is not None
    assert monitor.stderr.readline().startswith(
        f"aiortu monitor: listening on {bus[2]} at 19200 8N2"
    )
    assert run_aiortu("read", bus[0], "--unit", "17", "--ref", "40108").returncode == 0
    out, _ = stop(monitor)
    assert "request   ok        unit 17 read holding registers 107 (1)\n" in out
    assert "reply     ok        unit 17 reply holding 107 = [44609]\n" in out

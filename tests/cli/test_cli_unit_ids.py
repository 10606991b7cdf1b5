"""Unit ids as the framing takes them: ``--unit 255`` and ``--unit 0`` over Modbus TCP reach a
device by its IP address (its reply awaited); a serial line keeps 1..247."""

from __future__ import annotations

import re
from collections.abc import Iterator
from pathlib import Path

import pytest

from tests.cli.cli_helpers import run_aiortu, serving_tcp, start_aiortu, stop

pytestmark = pytest.mark.timeout(60)

ONE_UNIT = """\
[[slave]]
unit = 17
[[slave.holding_registers]]
start = 0
values = [1, 2, 3]
"""


@pytest.fixture(scope="module")
def tcp_url(tmp_path_factory: pytest.TempPathFactory) -> Iterator[str]:
    config = tmp_path_factory.mktemp("tcp") / "one.toml"
    config.write_text(ONE_UNIT)
    with serving_tcp(config) as url:
        yield url


@pytest.mark.parametrize("unit", ["255", "0", "0xFF"])
def test_read_and_write_over_modbus_tcp_take_any_unit_id(tcp_url: str, unit: str) -> None:
    read = run_aiortu("read", tcp_url, "--unit", unit, "--ref", "40001", "--count", "3")
    assert (read.returncode, read.stdout, read.stderr) == (0, "40001 1\n40002 2\n40003 3\n", "")
    written = run_aiortu("write", tcp_url, "--unit", unit, "--ref", "40003", "--values", "3")
    assert (written.returncode, written.stderr) == (0, "")


@pytest.mark.parametrize(
    ("unit", "message"),
    [
        ("255", "argument --unit: must be a unit address 1..247, not 255"),
        ("0", "argument --unit: must be a unit address 1..247, not 0 (0 is the broadcast address, "
              "which gets no reply)"),
    ],
)  # fmt: skip
def test_a_serial_line_keeps_units_1_to_247(tmp_path: Path, unit: str, message: str) -> None:
    result = run_aiortu("read", str(tmp_path / "ttyX"), "--unit", unit, "--ref", "40001")
    assert (result.returncode, result.stderr) == (2, f"aiortu read: error: {message}\n")


def test_no_framing_takes_256(tcp_url: str) -> None:
    result = run_aiortu("read", tcp_url, "--unit", "256", "--ref", "40001")
    assert result.returncode == 2
    assert result.stderr.endswith(
        "--unit: must be a unit address 1..247 (0..255 over tcp://, udp://, tls://), not 256\n"
    )


def test_modbus_udp_takes_unit_255_too(tmp_path: Path) -> None:
    config = tmp_path / "one.toml"
    config.write_text(ONE_UNIT)
    process = start_aiortu("serve", "udp://127.0.0.1:0", "--config", str(config))
    try:
        assert process.stderr is not None
        found = re.search(r"\(port (\d+)\)", process.stderr.readline())
        assert found is not None
        url = f"udp://127.0.0.1:{found.group(1)}"
        read = run_aiortu("read", url, "--unit", "255", "--ref", "40001", "--count", "3")
    finally:
        stop(process)
    assert (read.returncode, read.stdout, read.stderr) == (0, "40001 1\n40002 2\n40003 3\n", "")

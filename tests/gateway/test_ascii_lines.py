"""The gateway's lines in Modbus ASCII: mbpoll and pymodbus (over TCP and UDP) through the
`aiortu gateway --framing ascii` command to `aiortu serve --framing ascii` on a pty bus, and
`--line PORT:1-20,framing=ascii` beside an RTU line."""

from __future__ import annotations

import argparse
import re
import shutil

import anyio
import pytest

from aiortu.cli._gateway import _parse_line, _with_options
from aiortu.errors import InvalidValue
from aiortu.gateway import GatewayLine
from aiortu.testing import PtyBus
from tests.gateway.test_interop import _command, _line_from

pymodbus_client = pytest.importorskip("pymodbus.client")

pytestmark = [pytest.mark.interop, pytest.mark.timeout(90)]

MBPOLL = shutil.which("mbpoll")
CONFIG = "examples/devices.toml"


def _args(framing: str = "rtu", bytesize: int | None = None) -> argparse.Namespace:
    return argparse.Namespace(framing=framing, bytesize=bytesize)


def test_a_line_takes_its_own_framing() -> None:
    line = _parse_line("rtu+tcp://10.0.0.5:4001:21-40,framing=ascii")
    assert line.port == "rtu+tcp://10.0.0.5:4001"
    assert line.units == range(21, 41)
    assert line.options == {"framing": "ascii"}
    assert _parse_line("/dev/ttyUSB0:1-20").options == {}
    for bad in ("/dev/ttyUSB0:1-20,framing=7e1", "/dev/ttyUSB0:1-20,speed=9600"):
        with pytest.raises(InvalidValue, match=re.escape("[,framing=rtu|ascii]")):
            _parse_line(bad)


def test_each_line_gets_its_framings_data_bits() -> None:
    lines = [_parse_line("/dev/ttyS0:1-20"), _parse_line("/dev/ttyS1:21-40,framing=ascii")]
    opened, shared = _with_options(_args(), lines)
    assert shared == {}
    assert isinstance(opened, list)
    assert [line.options for line in opened] == [
        {"bytesize": 8},
        {"framing": "ascii", "bytesize": 7},
    ]
    # --framing ascii for every line; --bytesize given wins over the framing's default.
    _, shared = _with_options(_args("ascii"), "/dev/ttyS0")
    assert shared == {"framing": "ascii", "bytesize": 7}
    _, shared = _with_options(_args("ascii", 8), "/dev/ttyS0")
    assert shared == {"framing": "ascii", "bytesize": 8}
    opened, _ = _with_options(_args("ascii"), [GatewayLine("/dev/ttyS0", range(1, 5))])
    assert isinstance(opened, list)
    assert opened[0].options == {"framing": "ascii", "bytesize": 7}


@pytest.mark.skipif(MBPOLL is None, reason="mbpoll is not installed")
async def test_mbpoll_and_pymodbus_through_the_gateway_to_an_ascii_line() -> None:
    assert MBPOLL is not None
    with PtyBus(2).running_in_thread() as bus:
        async with (
            _command("serve", bus.paths[1], "--config", CONFIG, "--framing", "ascii") as slave,
            _command(
                "gateway", bus.paths[0], "--framing", "ascii",
                "--listen", "tcp://127.0.0.1:0", "--listen", "udp://127.0.0.1:0",
            ) as gateway,
        ):  # fmt: skip
            assert slave.stderr is not None
            assert gateway.stderr is not None
            await _line_from(slave.stderr, rb"Ctrl-C")
            found = await _line_from(gateway.stderr, rb"127\.0\.0\.1:(\d+), 127\.0\.0\.1:(\d+);")
            tcp, udp = int(found[1]), int(found[2])
            poll = [MBPOLL, "-m", "tcp", "-a", "17", "-p", str(tcp), "-1", "-o", "2"]
            await anyio.run_process([*poll, "-r", "109", "127.0.0.1", "1234", "5678"])
            result = await anyio.run_process([*poll, "-r", "109", "-c", "2", "127.0.0.1"])
            assert b"[109]: \t1234" in result.stdout
            assert b"[110]: \t5678" in result.stdout
            await _pymodbus_reads(pymodbus_client.AsyncModbusTcpClient("127.0.0.1", port=tcp))
            await _pymodbus_reads(pymodbus_client.AsyncModbusUdpClient("127.0.0.1", port=udp))


async def _pymodbus_reads(client: object) -> None:
    """The registers mbpoll wrote above (its references 109..110 are addresses 108..109),
    read by a pymodbus client."""
    try:
        assert await client.connect()  # type: ignore[attr-defined]
        reply = await client.read_holding_registers(108, count=2, device_id=17)  # type: ignore[attr-defined]
        assert not reply.isError(), reply
        assert reply.registers == [1234, 5678]
        refused = await client.read_holding_registers(0, count=1, device_id=9)  # type: ignore[attr-defined]
        assert refused.isError()
        assert refused.exception_code == 0x0B
    finally:
        client.close()  # type: ignore[attr-defined]

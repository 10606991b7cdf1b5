"""Several lines in one gateway, routed by unit ranges: each line its own master, a unit no
line serves gets exception 0A, overlapping ranges refused; `--line` on the command line."""

from __future__ import annotations

from collections.abc import AsyncIterator
from contextlib import AsyncExitStack, asynccontextmanager
from typing import Any

import anyio
import pytest

from aiortu.cli import main
from aiortu.core.serial import LineSettings
from aiortu.errors import InvalidValue
from aiortu.gateway import Gateway, GatewayLine, gateway
from aiortu.master import Master
from aiortu.slave import MemoryStore, Slave
from aiortu.testing import VirtualBus
from tests.gateway.helpers import client, memory_client
from tests.virtual_clock import on_virtual_clock

pytestmark = pytest.mark.timeout(30)

_MASTER: dict[str, Any] = {
    "frame_gap": 0, "timeout": 0.2, "retries": 0, "turnaround_delay": 0.005,
    "late_reply_guard": 0.005, "fail_fast_offline": True, "reconnect_fail_fast": True,
}  # fmt: skip


async def _bus(stack: AsyncExitStack, unit: int, value: int) -> tuple[Master, Slave]:
    bus = VirtualBus(2)
    store = MemoryStore(holding_registers={0: [value, 0]})
    slave = Slave(bus.endpoints[1], {unit: store}, frame_gap=0.0, frame_silence=0.005)
    master = Master(bus.endpoints[0], LineSettings(1_000_000), **_MASTER)
    await stack.enter_async_context(slave)
    await stack.enter_async_context(master)
    return master, slave


@asynccontextmanager
async def two_lines(
    listen: tuple[str, ...] = ("tcp://127.0.0.1:0",),
) -> AsyncIterator[tuple[Gateway, Slave, Slave]]:
    """Unit 5 on line A (units 1-20), unit 30 on line B (units 21-40), one gateway."""
    async with AsyncExitStack() as stack:
        master_a, slave_a = await _bus(stack, 5, 0xA)
        master_b, slave_b = await _bus(stack, 30, 0xB)
        await anyio.sleep(0.02)  # the receivers past their first silence
        lines = [
            GatewayLine(master_a, range(1, 21), "A"),
            GatewayLine(master_b, range(21, 41), "B"),
        ]
        server = await stack.enter_async_context(gateway(lines, listen))
        yield server, slave_a, slave_b


async def test_each_unit_goes_to_its_line_and_only_there() -> None:
    async with two_lines() as (server, slave_a, slave_b), client(server) as tcp:
        assert await tcp.request("03 0000 0001", unit=5) == "03 02 00 0A"
        assert await tcp.request("03 0000 0001", unit=30) == "03 02 00 0B"
        assert await tcp.request("03 0000 0001", unit=6) == "83 0B"  # line A, nobody there
        assert slave_a.counters.bus_message_count == 2
        assert slave_b.counters.bus_message_count == 1
        assert server.statistics.lines["A"].transactions == 2
        assert server.statistics.units[("B", 30)].replies == 1


async def test_a_unit_no_line_serves_gets_0A_without_a_transaction() -> None:
    async with two_lines() as (server, slave_a, slave_b), client(server) as tcp:
        assert await tcp.request("03 0000 0001", unit=41) == "83 0A"
        assert await tcp.request("06 0000 0001", unit=247) == "86 0A"
        assert await tcp.request("03 0000 0001", unit=250) == "83 0B"  # no unit id at all
        assert slave_a.counters.bus_message_count == 0
        assert slave_b.counters.bus_message_count == 0
        assert server.counters.transactions == 0


@on_virtual_clock
async def test_a_broadcast_goes_on_every_line() -> None:
    async with two_lines(listen=()) as (server, slave_a, slave_b), memory_client(server) as tcp:
        await tcp.send("06 0001 0063", unit=0)
        assert await tcp.receive(wait=10) is None  # never answered
        assert await tcp.request("03 0001 0001", unit=5) == "03 02 00 63"
        assert await tcp.request("03 0001 0001", unit=30) == "03 02 00 63"
        assert server.counters.broadcasts == 2
        assert [server.statistics.lines[name].broadcasts for name in ("A", "B")] == [1, 1]
        assert slave_a.counters.bus_message_count == 2  # the broadcast, the read
        assert slave_b.counters.bus_message_count == 2


async def test_overlapping_ranges_are_refused_in_one_sentence() -> None:
    async with AsyncExitStack() as stack:
        master, _ = await _bus(stack, 5, 0)
        lines = [GatewayLine(master, range(1, 21), "A"), GatewayLine(master, range(20, 31), "B")]
        with pytest.raises(InvalidValue) as raised:
            Gateway(lines)
    assert str(raised.value) == (
        "units 20-30 of line B overlap units 1-20 of line A; give each unit to one line"
    )


@pytest.mark.parametrize(
    ("units", "allowed"),
    [(range(5), "1..247"), (range(240, 249), "1..247"), (range(5, 5), "1..247")],
)
async def test_a_range_outside_the_unit_ids_is_refused(units: range, allowed: str) -> None:
    async with AsyncExitStack() as stack:
        master, _ = await _bus(stack, 5, 0)
        with pytest.raises(InvalidValue, match=allowed):
            Gateway([GatewayLine(master, units)])


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (["--line", "/dev/null:1-20", "--line", "/dev/zero:15-30"],
         "units 15-30 of line /dev/zero overlap units 1-20 of line /dev/null"),
        (["--line", "/dev/null:1-x"], "--line /dev/null:1-x: expected PORT:FIRST-LAST"),
        (["--line", "/dev/null:30-20"], "FIRST-LAST with 1 <= FIRST <= LAST <= 247"),
        (["/dev/null", "--line", "/dev/null:1-2"], "give either SERIAL or --line, not both"),
        ([], "give a SERIAL port or --line"),
    ],
)  # fmt: skip
def test_bad_lines_on_the_command_line_are_one_line_and_exit_2(
    args: list[str], message: str, capsys: pytest.CaptureFixture[str]
) -> None:
    assert main(["gateway", *args, "--listen", "tcp://127.0.0.1:0"]) == 2
    err = capsys.readouterr().err
    assert message in err
    assert err.count("\n") == 1


async def test_lines_given_as_masters_without_names_are_numbered() -> None:
    async with AsyncExitStack() as stack:
        master_a, _ = await _bus(stack, 5, 0)
        master_b, _ = await _bus(stack, 30, 0)
        lines = [GatewayLine(master_a, range(1, 21)), GatewayLine(master_b, range(21, 41))]
        assert sorted(Gateway(lines).statistics.lines) == ["line 1", "line 2"]

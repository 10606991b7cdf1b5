"""MockLine: a master, its handles and its poller against a function, without bytes or timing."""

from __future__ import annotations

import anyio
import anyio.lowlevel
import pytest

import aiortu
from aiortu.core.pdu import (
    ExceptionPDU,
    ReadHoldingRegistersRequest,
    ReadHoldingRegistersResponse,
    Request,
    Response,
    WriteSingleRegisterRequest,
    WriteSingleRegisterResponse,
)
from aiortu.errors import ExceptionResponse, InvalidValue, ResponseTimeout
from aiortu.testing import MockLine

REGISTERS = {0: 215, 1: 7}


def device(unit: int, request: Request) -> Response | ExceptionPDU | None:
    """Unit 1 holds REGISTERS; unit 2 never answers; anything else is refused (02)."""
    if unit == 2:
        raise ResponseTimeout("no reply from unit 2")
    match request:
        case ReadHoldingRegistersRequest(address=address, count=count) if unit == 1:
            if address + count > len(REGISTERS):
                return ExceptionPDU(request.function_code, 2)
            values = tuple(REGISTERS[address + i] for i in range(count))
            return ReadHoldingRegistersResponse(values)
        case WriteSingleRegisterRequest(address=address, value=value):
            if unit != 0:
                REGISTERS[address] = value
            return WriteSingleRegisterResponse(address, value)
    return ExceptionPDU(request.function_code, 1)


async def test_a_master_reads_and_writes_through_the_handler() -> None:
    line = MockLine(device)
    async with aiortu.Master(line) as master:
        assert await master.read_holding_registers(1, 0, 2) == [215, 7]
        await master.slave(1).write_register(1, 8)
        assert await master.slave(1).read_holding_registers(1, 1) == [8]
        with pytest.raises(ExceptionResponse) as refused:
            await master.read_holding_registers(1, 5, 1)
        assert refused.value.code == 2
        with pytest.raises(ResponseTimeout):
            await master.read_holding_registers(2, 0, 1)
        await master.broadcast.write_register(0, 9)  # the handler sees it; no reply awaited
    assert [(t.unit, type(t.request).__name__) for t in line.transactions] == [
        (1, "ReadHoldingRegistersRequest"),
        (1, "WriteSingleRegisterRequest"),
        (1, "ReadHoldingRegistersRequest"),
        (1, "ReadHoldingRegistersRequest"),
        (2, "ReadHoldingRegistersRequest"),
        (0, "WriteSingleRegisterRequest"),
    ]
    assert line.transactions[-1].expects_reply is False
    one, two = master.unit_stats(1), master.unit_stats(2)
    assert (one.requests, one.successes, one.exceptions) == (4, 4, 1)
    assert (two.requests, two.failures, two.timeouts, two.online) == (1, 1, 1, True)


async def test_a_unit_that_keeps_timing_out_goes_offline_by_the_health_policy() -> None:
    line = MockLine(device, health=aiortu.HealthPolicy(offline_after=2))
    async with aiortu.Master(line) as master:
        for _ in range(2):
            with pytest.raises(ResponseTimeout):
                await master.read_holding_registers(2, 0, 1)
        assert not master.is_online(2)


async def test_an_async_handler_is_awaited_and_priorities_reach_it() -> None:
    seen: list[int] = []

    async def slow(unit: int, request: Request) -> Response:
        await anyio.lowlevel.checkpoint()
        return ReadHoldingRegistersResponse((unit,))

    line = MockLine(slow)
    async with aiortu.Master(line) as master:
        seen = [await master.read_holding_registers(unit, 0, 1, priority=3) for unit in (4, 5)]
    assert seen == [[4], [5]]
    assert [t.priority for t in line.transactions] == [3, 3]


async def test_a_poller_polls_a_mock_line() -> None:
    line = MockLine(device)
    samples: list[aiortu.Sample] = []
    points = [
        aiortu.Point("level", 1, "holding_registers", 0),
        aiortu.Point("x", 2, "holding_registers", 0),
    ]
    async with aiortu.Master(line) as master:
        poller = aiortu.Poller(master, points, interval=0.01, on_sample=samples.append)
        await poller.run(cycles=1)
    by_name = {sample.point.name: sample for sample in samples}
    assert by_name["level"].value == 215
    assert isinstance(by_name["x"].error, ResponseTimeout)


async def test_a_handler_that_returns_something_else_is_told_plainly() -> None:
    line = MockLine(lambda unit, request: "oops")  # type: ignore[arg-type,return-value]
    async with aiortu.Master(line) as master:
        with pytest.raises(InvalidValue, match="MockLine"):
            await master.read_holding_registers(1, 0, 1)


def test_a_master_on_a_mock_line_has_no_engine() -> None:
    master = aiortu.Master(MockLine(device))
    with pytest.raises(InvalidValue, match="no line"):
        master.engine  # noqa: B018
    assert master.connected

"""A gateway in front of a master on a MockLine: what the line server does with replies,
refusals and silence, without a line."""

from __future__ import annotations

import anyio

import aiortu
from aiortu.core.pdu import (
    ExceptionPDU,
    ReadHoldingRegistersRequest,
    ReadHoldingRegistersResponse,
    Request,
    Response,
)
from aiortu.errors import ResponseTimeout
from aiortu.gateway import gateway
from aiortu.testing import MockLine
from tests.gateway.helpers import client, line


def device(unit: int, request: Request) -> Response | ExceptionPDU | None:
    if unit == 9:
        raise ResponseTimeout("no reply from unit 9")
    if isinstance(request, ReadHoldingRegistersRequest) and unit == 17:
        return ReadHoldingRegistersResponse(
            tuple(range(request.address, request.address + request.count))
        )
    return ExceptionPDU(request.function_code, 1)


async def test_a_gateway_forwards_to_a_mock_line() -> None:
    line = MockLine(device)
    async with (
        aiortu.Master(line, fail_fast_offline=True) as master,
        gateway(master, ["tcp://127.0.0.1:0"]) as server,
        client(server) as peer,
    ):
        with anyio.fail_after(5):
            assert await peer.request("0300050002", unit=17) == "03 04 00 05 00 06"
            assert await peer.request("0600010007", unit=17) == "86 01"  # refused
            assert await peer.request("0300000001", unit=9) == "83 0B"  # no reply: 0B
    assert [(t.unit, t.request.function_code) for t in line.transactions] == [
        (17, 3),
        (17, 6),
        (9, 3),
    ]


async def test_a_gateways_reads_take_the_fast_path_as_any_read() -> None:
    # Through the one seam, a forwarded register read on an idle line runs without the
    # machine, as the master's own reads do (failing fast on offline units, as the line
    # server's master does): the machine begins no transaction.
    async with line() as gateway_line, client(gateway_line.gateway) as peer:
        with anyio.fail_after(5):
            for _ in range(3):
                assert (await peer.request("0300000002")).startswith("03 04")
        assert gateway_line.master.engine.machine.transaction is None
        assert gateway_line.master.unit_stats(17).successes == 3

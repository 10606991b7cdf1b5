"""Promises of the Modbus TCP server that hold for requests pipelined on one connection.

Through public behaviour only: `aiortu.serve` on 127.0.0.1, a raw client sending several
ADUs in one chunk, and what comes back.
"""

from __future__ import annotations

from contextlib import AsyncExitStack

import anyio
import pytest

from aiortu.core.mbap import encode_adu
from aiortu.core.pdu import ReadHoldingRegistersResponse
from aiortu.slave import ModbusTcpServer, Reply, RequestContext, serve
from tests.slave.tcp_helpers import TcpClient, device

pytestmark = pytest.mark.timeout(30)


async def test_a_failing_broadcast_is_not_answered_and_the_request_behind_it_is() -> None:
    # With several units, unit 0 is a broadcast. 05 0001 1234 is an invalid coil value: the
    # units answer it with an exception, which a broadcast must never send.
    stores = {1: device(), 2: device()}
    async with serve("tcp://127.0.0.1:0", stores) as server:
        assert isinstance(server, ModbusTcpServer)
        async with await anyio.connect_tcp("127.0.0.1", server.port) as stream:
            tcp = TcpClient(stream)
            broadcast = encode_adu(1, 0, bytes.fromhex("05 0001 1234"))
            read = encode_adu(2, 1, bytes.fromhex("01 0000 0004"))
            await stream.send(broadcast + read)
            reply = await tcp.receive()
            assert reply is not None
            assert (reply.transaction_id, reply.unit, reply.pdu.hex(" ")) == (2, 1, "01 01 0d")
            assert await tcp.receive(wait=0.3) is None  # nothing for the broadcast
            # The connection goes on.
            assert await tcp.request("03 0000 0001", unit=2, transaction_id=3) == "03 02 12 34"
        assert server.counters.connections_accepted == 1
        assert server.counters.requests == 3  # the broadcast counts too


@pytest.mark.parametrize(("unit", "expected"), [(255, "03 02 00 2a"), (256, "83 04")])
async def test_a_reply_as_another_unit_must_name_a_unit_id(unit: int, expected: str) -> None:
    # A handler may answer as another unit (a confused device), 0..255: beyond, it is a
    # handler's mistake, answered with 04 and logged, and serving goes on.
    def confused(request: object, context: RequestContext) -> Reply:
        return Reply(ReadHoldingRegistersResponse((42,)), unit=unit)

    async with serve("tcp://127.0.0.1:0", {1: device()}, handlers={3: confused}) as server:
        assert isinstance(server, ModbusTcpServer)
        async with await anyio.connect_tcp("127.0.0.1", server.port) as stream:
            tcp = TcpClient(stream)
            await tcp.send("03 0000 0001", unit=1, transaction_id=5)
            reply = await tcp.receive()
            assert reply is not None
            assert (reply.transaction_id, reply.pdu.hex(" ")) == (5, expected)
            assert await tcp.request("01 0000 0004", unit=1, transaction_id=6) == "01 01 0D"


async def test_32_connections_are_served_by_default_and_a_33rd_is_closed_at_once() -> None:
    async with serve("tcp://127.0.0.1:0", {1: device()}) as server:
        assert isinstance(server, ModbusTcpServer)
        async with AsyncExitStack() as stack:
            clients = []
            for index in range(32):
                stream = await stack.enter_async_context(
                    await anyio.connect_tcp("127.0.0.1", server.port)
                )
                clients.append(TcpClient(stream))
                assert await clients[-1].request("03 0000 0001", 1, index) == "03 02 12 34"
            async with await anyio.connect_tcp("127.0.0.1", server.port) as stream:
                assert await TcpClient(stream).closed_by_server()
            assert server.counters.connections_refused == 1

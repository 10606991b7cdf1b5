"""Promises of the Modbus TCP server that hold for requests pipelined on one connection.

Through public behaviour only: `aiortu.serve` on 127.0.0.1, a raw client sending several
ADUs in one chunk, and what comes back.
"""

from __future__ import annotations

import anyio
import pytest

from aiortu.core.mbap import encode_adu
from aiortu.slave import ModbusTcpServer, serve
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

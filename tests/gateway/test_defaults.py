"""The gateway's defaults on a line where nothing answers: 0B within a client's 1 s, one retry
of a read, a write sent once."""

from __future__ import annotations

import anyio
import anyio.abc
import pytest

from aiortu.core.rtu import encode_frame
from aiortu.gateway import gateway
from tests.gateway.helpers import TcpClient

pytestmark = pytest.mark.anyio


async def test_a_silent_unit_gets_0b_within_1_s_and_a_write_goes_out_once() -> None:
    heard = bytearray()
    listener = await anyio.create_tcp_listener(local_host="127.0.0.1")
    port = listener.extra(anyio.abc.SocketAttribute.local_port)

    async def silent_line(stream: anyio.abc.SocketStream) -> None:
        async for data in stream:
            heard.extend(data)

    async with listener, anyio.create_task_group() as tasks:
        tasks.start_soon(listener.serve, silent_line)
        url = f"rtu+tcp://127.0.0.1:{port}"
        async with gateway(url, ["tcp://127.0.0.1:0"], frame_gap=0) as server:
            stream = await anyio.connect_tcp("127.0.0.1", server.port)
            async with stream:
                tcp = TcpClient(stream)
                read, write = "03 0000 0001", "06 0000 0001"  # unit 5 does not answer
                for pdu, sent, answer in ((read, 2, "83 0B"), (write, 1, "86 0B")):
                    heard.clear()
                    started = anyio.current_time()
                    assert (await tcp.request(pdu, unit=5)) == answer
                    assert anyio.current_time() - started < 1.0
                    frame = encode_frame(5, bytes.fromhex(pdu))
                    assert bytes(heard) == frame * sent
        tasks.cancel_scope.cancel()

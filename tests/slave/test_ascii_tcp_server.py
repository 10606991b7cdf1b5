"""A listening ASCII-over-TCP server (`serve("ascii+tcp://0.0.0.0:...")`): aiortu's own
`ascii+tcp://` master and pymodbus's ASCII framer over TCP read from it; bad options refused."""

from __future__ import annotations

import anyio
import pytest

import aiortu
from aiortu.core.ascii import encode_ascii_frame
from aiortu.errors import InvalidValue
from aiortu.slave import RtuOverTcpServer

pytestmark = pytest.mark.timeout(30)


def _store() -> aiortu.MemoryStore:
    return aiortu.MemoryStore(holding_registers={0: [10, 20, 30]})


async def test_an_ascii_master_reads_and_writes_through_a_listening_ascii_server() -> None:
    store = _store()
    async with aiortu.serve("ascii+tcp://127.0.0.1:0", {17: store}) as server:
        assert isinstance(server, RtuOverTcpServer)
        assert server.framing == "ascii"
        url = f"ascii+tcp://127.0.0.1:{server.port}"
        async with aiortu.open_master(url, timeout=2, retries=0) as master:
            assert await master.read_holding_registers(17, 0, 3) == [10, 20, 30]
            await master.write_register(17, 1, 99)
        assert store.read(aiortu.slave.Table.HOLDING_REGISTERS, 1, 1) == [99]


async def test_the_wire_carries_ascii_frames() -> None:
    async with aiortu.serve("ascii+tcp://127.0.0.1:0", {17: _store()}) as server:
        assert isinstance(server, RtuOverTcpServer)
        async with await anyio.connect_tcp("127.0.0.1", server.port) as stream:
            await stream.send(encode_ascii_frame(17, bytes.fromhex("03 0000 0001")))
            reply = b""
            with anyio.fail_after(5):
                while not reply.endswith(b"\r\n"):
                    reply += await stream.receive()
    assert reply == encode_ascii_frame(17, bytes.fromhex("03 02 000A"))


async def test_an_rtu_listener_still_speaks_rtu() -> None:
    async with aiortu.serve("rtu+tcp://127.0.0.1:0", {17: _store()}) as server:
        assert isinstance(server, RtuOverTcpServer)
        assert server.framing == "rtu"
        url = f"rtu+tcp://127.0.0.1:{server.port}"
        async with aiortu.open_master(url, timeout=2, retries=0) as master:
            assert await master.read_holding_registers(17, 0, 1) == [10]


def test_bad_framing_options_are_refused() -> None:
    with pytest.raises(InvalidValue, match="framing"):
        RtuOverTcpServer({17: _store()}, framing="binary")
    with pytest.raises(InvalidValue, match="ascii_timeout"):
        RtuOverTcpServer({17: _store()}, ascii_timeout=0.5)


async def test_pymodbus_ascii_over_tcp_client_reads_from_it() -> None:
    pymodbus_client = pytest.importorskip("pymodbus.client")
    framer = pytest.importorskip("pymodbus").FramerType.ASCII
    async with aiortu.serve("ascii+tcp://127.0.0.1:0", {17: _store()}) as server:
        assert isinstance(server, RtuOverTcpServer)
        client = pymodbus_client.AsyncModbusTcpClient(
            "127.0.0.1", port=server.port, framer=framer, timeout=3, retries=0
        )
        try:
            assert await client.connect()
            reply = await client.read_holding_registers(0, count=3, device_id=17)
            assert not reply.isError(), reply
            assert reply.registers == [10, 20, 30]
        finally:
            client.close()

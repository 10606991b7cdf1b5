"""The Modbus TCP server's `idle_timeout` on one connection, on a virtual clock: a client that
says nothing, one that sends requests and never reads the replies, and one that reads them
slowly; in each of its framings (`tcp://`, and `rtu+tcp://` and `ascii+tcp://`, whose
`RtuOverTcpServer` serves connections the same way).

`ModbusTcpServer.serve_connection` serves a client given as a byte stream: one in memory (the
general path, under asyncio and trio), and a `PushServerStream` (what `serve("tcp://...")`
accepts on asyncio, whose read callback may answer a request at once) on a stand-in for
asyncio's transport, whose write buffer the test fills and drains as a client that stops and
resumes reading would. No socket carries a byte, so the virtual clock's times are exact: each
close comes `idle_timeout` after the last thing the client did, to the nanosecond.
"""

from __future__ import annotations

import asyncio
import socket
from collections.abc import Awaitable, Callable
from dataclasses import dataclass
from typing import Any

import anyio
import anyio.abc
import anyio.lowlevel
import pytest
import trio.testing

from aiortu.core.ascii import encode_ascii_frame
from aiortu.core.mbap import encode_adu
from aiortu.core.rtu import encode_frame
from aiortu.slave import MemoryStore, ModbusTcpServer, RtuOverTcpServer
from aiortu.transport import PushServerStream
from tests.virtual_clock import VirtualTimeLoop

UNIT = 17
IDLE = 0.3
READ = bytes.fromhex("03 0000 0001")
ANSWER = bytes.fromhex("03 02 1234")


@dataclass(frozen=True)
class _Framing:
    """A server of one framing, and its requests and replies by number (the transaction id
    over Modbus TCP)."""

    server: Callable[[], ModbusTcpServer]
    frame: Callable[[int, bytes], bytes]

    def request(self, number: int) -> bytes:
        return self.frame(number, READ)

    def replies(self, count: int) -> bytes:
        """The replies to requests 0 .. count - 1, as written."""
        return b"".join(self.frame(number, ANSWER) for number in range(count))


def _store() -> dict[int, MemoryStore]:
    return {UNIT: MemoryStore(holding_registers={0: [0x1234]})}


FRAMINGS = {
    "tcp": _Framing(
        lambda: ModbusTcpServer(_store(), idle_timeout=IDLE),
        lambda number, pdu: encode_adu(number, UNIT, pdu),
    ),
    "rtu+tcp": _Framing(
        lambda: RtuOverTcpServer(_store(), idle_timeout=IDLE),
        lambda number, pdu: encode_frame(UNIT, pdu),
    ),
    "ascii+tcp": _Framing(
        lambda: RtuOverTcpServer(_store(), idle_timeout=IDLE, framing="ascii"),
        lambda number, pdu: encode_ascii_frame(UNIT, pdu),
    ),
}


class _MemoryClient(anyio.abc.ByteStream):
    """The server's end of a client, in memory: requests the test sends, replies taken only
    while the client reads."""

    def __init__(self) -> None:
        self._incoming = bytearray()
        self._arrived = anyio.Event()
        self.replies = bytearray()
        self._reading = True
        self._reads = anyio.Event()
        self.closed = False
        self.ended = anyio.Event()
        """Set once the server is done with the connection."""

    async def receive(self, max_bytes: int = 65536) -> bytes:
        while not self._incoming:
            self._arrived = anyio.Event()
            await self._arrived.wait()
        data = bytes(self._incoming[:max_bytes])
        del self._incoming[:max_bytes]
        return data

    async def send(self, item: bytes) -> None:
        await anyio.lowlevel.checkpoint()
        while not self._reading:
            self._reads = anyio.Event()
            await self._reads.wait()
        self.replies += item

    async def send_eof(self) -> None:
        pass

    async def aclose(self) -> None:
        self.closed = True

    def request(self, data: bytes) -> None:
        self._incoming += data
        self._arrived.set()

    def stop_reading(self) -> None:
        self._reading = False

    def read(self) -> None:
        self._reading = True
        self._reads.set()


class _Transport(asyncio.Transport):
    """What a `PushServerStream` uses of asyncio's transport: the bytes written, in memory."""

    def __init__(self) -> None:
        super().__init__()
        self.written = bytearray()
        self.closed = False

    def write(self, data: bytes | bytearray | memoryview) -> None:
        assert not self.closed
        self.written += data

    def pause_reading(self) -> None:
        pass

    def resume_reading(self) -> None:
        pass

    def is_closing(self) -> bool:
        return self.closed

    def close(self) -> None:
        self.closed = True

    def can_write_eof(self) -> bool:
        return False


class _PushedClient:
    """A client on a `PushServerStream` (the stream `serve("tcp://...")` accepts on asyncio):
    its bytes come through the stream's read callback, and it stops reading by filling the
    transport's write buffer (asyncio's `pause_writing`), as a client that reads nothing does."""

    def __init__(self) -> None:
        self._socket = socket.socket()  # never connected: the stream only keeps it
        self.stream = PushServerStream(self._socket)
        self.transport = _Transport()
        self.stream.transport = self.transport
        self.ended = anyio.Event()
        """Set once the server is done with the connection."""

    @property
    def replies(self) -> bytearray:
        return self.transport.written

    @property
    def closed(self) -> bool:
        return self.transport.closed

    def request(self, data: bytes) -> None:
        self.stream.data(data)

    def stop_reading(self) -> None:
        self.stream.gate.pause()

    def read(self) -> None:
        self.stream.resume_writing()


Client = _MemoryClient | _PushedClient
Scenario = Callable[[ModbusTcpServer, Client, _Framing], Awaitable[None]]


def _run(kind: str, backend: str, framing: str, scenario: Scenario) -> float:
    """Serve one client of `kind` in `framing` while `scenario` plays it, on a virtual clock;
    return when the server closed the connection (its clock, 0 when it came)."""
    closed_at: list[float] = []
    speaks = FRAMINGS[framing]

    async def main() -> None:
        server = speaks.server()
        client: Client = _MemoryClient() if kind == "memory" else _PushedClient()
        stream = client if isinstance(client, _MemoryClient) else client.stream
        try:
            came = anyio.current_time()
            async with anyio.create_task_group() as group:
                group.start_soon(scenario, server, client, speaks)
                with anyio.fail_after(100 * IDLE):  # a guard gone would hang: fail instead
                    await server.serve_connection(stream)
                closed_at.append(anyio.current_time() - came)
                assert client.closed
                client.ended.set()
        finally:
            if isinstance(client, _PushedClient):
                client._socket.close()

    if backend == "trio":
        options: dict[str, Any] = {"clock": trio.testing.MockClock(autojump_threshold=0)}
    else:
        options = {"loop_factory": VirtualTimeLoop}
    anyio.run(main, backend=backend, backend_options=options)
    return closed_at[0]


def _clients(test: Callable[..., None]) -> Callable[..., None]:
    """Run `test` for each client and framing."""
    clients = pytest.mark.parametrize(
        ("kind", "backend"), [("memory", "asyncio"), ("memory", "trio"), ("pushed", "asyncio")]
    )
    return pytest.mark.parametrize("framing", list(FRAMINGS))(clients(test))


@_clients
def test_a_client_that_sends_nothing_is_closed_idle_timeout_after_it_came(
    kind: str, backend: str, framing: str
) -> None:
    async def scenario(server: ModbusTcpServer, client: Client, speaks: _Framing) -> None:
        await _until_closed(client)
        assert server.counters.connections_idle == 1
        assert server.counters.requests == 0

    assert _run(kind, backend, framing, scenario) == pytest.approx(IDLE, abs=1e-9)


@_clients
def test_a_client_silent_after_its_reply_is_closed_idle_timeout_after_its_request(
    kind: str, backend: str, framing: str
) -> None:
    """Requests reset the count (answered at once from the read callback, on the pushed
    stream): a client that asks every 0.75 idle_timeout stays, then is closed idle_timeout
    after its last request."""

    async def scenario(server: ModbusTcpServer, client: Client, speaks: _Framing) -> None:
        for number in range(4):
            await anyio.sleep(0.75 * IDLE)
            client.request(speaks.request(number))
        await _until_closed(client)
        assert client.replies == speaks.replies(4)
        assert server.counters.connections_idle == 1
        # On the pushed Modbus TCP stream the read callback answered them, the task waiting.
        at_once = isinstance(client, _PushedClient) and framing == "tcp"
        assert server._at_once.answered == (4 if at_once else 0)

    assert _run(kind, backend, framing, scenario) == pytest.approx(4 * 0.75 * IDLE + IDLE, abs=1e-9)


@_clients
def test_a_client_that_never_reads_its_replies_is_closed_idle_timeout_after_the_first(
    kind: str, backend: str, framing: str
) -> None:
    """Its first reply cannot be written; the requests it goes on sending do not keep it:
    closed idle_timeout after that reply was due, with nothing written, counted idle."""

    async def scenario(server: ModbusTcpServer, client: Client, speaks: _Framing) -> None:
        client.stop_reading()
        await anyio.sleep(0.5 * IDLE)
        client.request(speaks.request(1))
        for number in range(2, 20):  # pipelined, every quarter of idle_timeout
            await anyio.sleep(IDLE / 4)
            if client.closed:
                break
            client.request(speaks.request(number))
        await _until_closed(client)
        assert client.replies == b""
        assert server.counters.requests == 1
        assert server.counters.connections_idle == 1

    assert _run(kind, backend, framing, scenario) == pytest.approx(0.5 * IDLE + IDLE, abs=1e-9)


@_clients
def test_a_client_that_reads_its_replies_slowly_is_not_closed(
    kind: str, backend: str, framing: str
) -> None:
    """Each reply waits 0.9 idle_timeout for the client to read: six of them, over five
    idle_timeouts, all written in order; the connection stays until the client falls silent,
    then closes idle_timeout after its last reply was taken."""

    async def scenario(server: ModbusTcpServer, client: Client, speaks: _Framing) -> None:
        for number in range(6):
            client.stop_reading()
            client.request(speaks.request(number))
            await anyio.sleep(0.9 * IDLE)
            assert not client.closed, f"closed while reading, at reply {number}"
            client.read()
            for _ in range(3):
                await anyio.lowlevel.checkpoint()
            assert client.replies == speaks.replies(number + 1)
        await _until_closed(client)
        assert server.counters.connections_idle == 1
        assert server.counters.requests == 6
        assert server._at_once.answered == 0  # a client that does not read is the task's

    assert _run(kind, backend, framing, scenario) == pytest.approx(6 * 0.9 * IDLE + IDLE, abs=1e-9)


async def _until_closed(client: Client) -> None:
    """Wait until the server is done with `client` (at most ten idle_timeouts)."""
    with anyio.fail_after(10 * IDLE):
        await client.ended.wait()


@pytest.mark.parametrize("framing", list(FRAMINGS))
def test_a_reply_from_the_connections_task_is_written_at_once_on_a_pushed_stream(
    framing: str,
) -> None:
    # A write is answered by the connection's task, not the read callback. While the client
    # reads, its reply goes straight to the transport: no `send()` (and no timer around it).
    write = bytes.fromhex("06 0000 0001")
    speaks = FRAMINGS[framing]

    async def main() -> None:
        server = speaks.server()
        client = _PushedClient()

        async def no_send(item: bytes) -> None:
            raise AssertionError("the reply waited in send()")

        client.stream.send = no_send  # type: ignore[method-assign]
        try:
            async with anyio.create_task_group() as group:
                group.start_soon(server.serve_connection, client.stream)
                client.request(speaks.frame(7, write))
                await anyio.sleep(IDLE / 2)  # virtual time: the task has long answered
                assert bytes(client.replies) == speaks.frame(7, write)
                group.cancel_scope.cancel()
        finally:
            client._socket.close()

    anyio.run(main, backend="asyncio", backend_options={"loop_factory": VirtualTimeLoop})

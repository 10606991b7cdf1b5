"""The line server under attack, on loopback: clients that leave with requests queued, that
never read, that half-close, that reset before they are accepted, and many client hosts.
These need sockets (resets, half-closes, the kernel's buffers), and run in real time; a slow
line's client runs on a virtual clock over an in-memory stream.

Each bound is one the gateway guarantees (requests on the wire, connections, counters), not a
time a quiet machine happens to show."""

from __future__ import annotations

import functools
import socket
import struct
from collections.abc import Callable

import anyio
import pytest

from aiortu.core.mbap import encode_adu
from aiortu.gateway import GatewayStatistics
from aiortu.slave import MemoryStore, RequestContext, Table
from aiortu.transport import listen_tcp
from tests.gateway.helpers import UNIT, TcpClient, client, device, line, memory_client
from tests.tcp_flood import kernel_buffers, send_until_blocked
from tests.virtual_clock import on_virtual_clock

pytestmark = pytest.mark.timeout(60)


class Gate:
    """Holds the slave's requests until opened; counts those it held."""

    def __init__(self) -> None:
        self.opened = anyio.Event()
        self.held = 0

    async def __call__(self, request: object, context: RequestContext) -> None:
        self.held += 1
        await self.opened.wait()


async def _until(condition: Callable[[], bool], seconds: float = 10.0) -> None:
    with anyio.fail_after(seconds):
        while not condition():  # noqa: ASYNC110 - counters of several objects, none signals
            await anyio.sleep(0.005)


def _reset(sock: socket.socket) -> None:
    """Close `sock` with a reset, as a client that crashes or gives up does."""
    sock.setsockopt(socket.SOL_SOCKET, socket.SO_LINGER, struct.pack("ii", 1, 0))
    sock.close()


async def test_a_departed_clients_queued_requests_never_reach_the_line() -> None:
    gate = Gate()
    store = device()
    async with line({UNIT: store}, max_in_flight=8, master_options={"timeout": 10.0}) as bench:
        bench.slave.before_request(gate)
        sock = socket.create_connection(("127.0.0.1", bench.gateway.port))
        writes = b"".join(
            encode_adu(index, UNIT, bytes.fromhex(f"06 {index:04X} 0001")) for index in range(8)
        )
        sock.sendall(writes)
        await _until(lambda: gate.held == 1 and bench.gateway.counters.requests == 8)
        _reset(sock)  # one write on the wire, seven queued behind it
        await _until(lambda: bench.gateway.connections == 0)
        gate.opened.set()
        await _until(lambda: bench.master.engine.queued == 0 and not bench.master.engine.busy)
        await anyio.sleep(0.1)  # time for a queued write to go out, were one left
        # The write on the wire completed; none of the queued ones was sent.
        assert bench.messages == 1
        assert store.get(Table.HOLDING_REGISTERS, 0, 8) == [1, 0xABCD, 7, 0, 0, 0, 0, 0]


async def test_a_departed_clients_requests_behind_another_clients_never_reach_the_line() -> None:
    gate = Gate()
    store = device()
    async with line({UNIT: store}, max_in_flight=8, master_options={"timeout": 10.0}) as bench:
        bench.slave.before_request(gate)
        async with client(bench.gateway) as other:
            await other.send("03 0000 0001", UNIT, 1)
            await _until(lambda: gate.held == 1)  # the other client's read holds the line
            sock = socket.create_connection(("127.0.0.1", bench.gateway.port))
            sock.sendall(
                b"".join(
                    encode_adu(index, UNIT, bytes.fromhex(f"06 {index:04X} 0001"))
                    for index in range(1, 5)
                )
            )
            await _until(lambda: bench.gateway.counters.requests == 5)
            _reset(sock)  # four writes queued, none on the wire
            await _until(lambda: bench.gateway.connections == 1)
            gate.opened.set()
            reply = await other.receive()
            assert reply is not None
            await anyio.sleep(0.2)  # time for a queued write to go out, were one left
        assert bench.messages == 1
        assert store.get(Table.HOLDING_REGISTERS, 1, 4) == [0xABCD, 7, 0, 0]


async def test_a_half_closed_client_still_gets_its_reply() -> None:
    gate = Gate()  # the reply comes after the gateway has seen the end of stream
    async with line() as bench:
        bench.slave.before_request(gate)
        async with await anyio.connect_tcp("127.0.0.1", bench.gateway.port) as stream:
            tcp = TcpClient(stream)
            await tcp.send("06 0005 0042", UNIT, 7)
            await stream.send_eof()
            await _until(lambda: gate.held == 1)
            await anyio.sleep(0.05)
            gate.opened.set()
            reply = await tcp.receive()
            assert reply is not None
            assert (reply.transaction_id, reply.pdu.hex(" ")) == (7, "06 00 05 00 42")
        await _until(lambda: bench.gateway.connections == 0)


_flood = functools.partial(send_until_blocked, quiet=2.0, most=96 << 20)
"""Send until the server has taken nothing for 2 s, closed, or 96 MiB went: a gateway that
reads without a window takes its bytes in bursts a slow line's replies apart."""


async def test_a_client_that_never_reads_is_closed_as_idle() -> None:
    """Replies it never reads fill its buffers; the one that waits `idle_timeout` to be
    written closes the connection, and with it the requests it still has."""
    store = MemoryStore(holding_registers={0: list(range(125))})
    async with line({UNIT: store}, idle_timeout=0.5, cache_ms=60_000) as bench:
        sock = socket.socket()
        sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 4096)
        sock.connect(("127.0.0.1", bench.gateway.port))
        read = encode_adu(1, UNIT, bytes.fromhex("03 0000 007D"))  # a 250-byte reply each
        # Until the server takes nothing for 0.3 s: the idle close is waited for below.
        flood = functools.partial(send_until_blocked, quiet=0.3)
        sent = await anyio.to_thread.run_sync(flood, sock, read * 64)
        await _until(lambda: bench.gateway.counters.connections_idle == 1)
        await _until(lambda: bench.gateway.connections == 0)
        assert sent > 0
        sock.close()


@on_virtual_clock
async def test_a_request_that_waits_for_a_slow_line_is_not_idle() -> None:
    async def slow(request: object, context: RequestContext) -> None:
        await anyio.sleep(0.8)

    async with line(idle_timeout=0.3, master_options={"timeout": 5.0}, listen=()) as bench:
        bench.slave.before_request(slow)
        async with memory_client(bench.gateway) as tcp:
            for address, reply in ((0, "03 02 12 34"), (1, "03 02 AB CD")):
                asked = anyio.current_time()
                assert await tcp.request(f"03 {address:04X} 0001") == reply
                assert anyio.current_time() - asked >= 0.8  # over twice the idle timeout
        assert bench.gateway.counters.connections_idle == 0


async def test_a_client_reset_before_accept_is_not_counted() -> None:
    async with line(listen=()) as bench:
        listener = await listen_tcp("127.0.0.1", 0)
        port = listener.extra(anyio.abc.SocketAttribute.local_port)
        early = socket.create_connection(("127.0.0.1", port))
        _reset(early)  # gone while still in the backlog
        async with anyio.create_task_group() as tasks:
            await tasks.start(bench.gateway.serve, listener)
            async with await anyio.connect_tcp("127.0.0.1", port) as stream:
                assert await TcpClient(stream).request("03 0000 0001") == "03 02 12 34"
            tasks.cancel_scope.cancel()
        assert bench.gateway.counters.connections_accepted == 1
        assert list(bench.gateway.statistics.clients) == ["127.0.0.1"]


async def test_statistics_keep_the_most_recent_clients_and_add_up_the_others() -> None:
    async with line(client_statistics=4) as bench:
        for host in range(2, 12):
            async with await anyio.connect_tcp(
                "127.0.0.1", bench.gateway.port, local_host=f"127.0.0.{host}"
            ) as stream:
                assert await TcpClient(stream).request("03 0000 0001") == "03 02 12 34"
        statistics = bench.gateway.statistics
        assert set(statistics.clients) == {f"127.0.0.{host}" for host in range(8, 12)} | {"other"}
        assert sum(each.requests for each in statistics.clients.values()) == 10
        assert statistics.clients["other"].connections == 6
        assert statistics.prometheus().count("aiortu_gateway_client_requests_total{") == 5


def test_the_statistics_bound_holds_for_any_number_of_hosts() -> None:
    statistics = GatewayStatistics(max_clients=16)
    for host in range(20_000):
        statistics.client(f"10.0.{host >> 8}.{host & 0xFF}").requests += 1
        assert len(statistics.clients) <= 17
    assert sum(each.requests for each in statistics.clients.values()) == 20_000
    assert len(list(statistics.summary())) <= 17 + 1


@pytest.mark.parametrize("server", ["gateway", "serve tcp://"])
async def test_a_pipelining_client_that_never_reads_is_held_back_by_tcp(server: str) -> None:
    """Requests streamed faster than a slow unit answers, replies never read: the client can
    send no more than the kernel's buffers hold and what the server reads for its window."""
    from aiortu.slave import serve

    async def slow(request: object, context: RequestContext) -> None:
        await anyio.sleep(0.05)

    bound = kernel_buffers() + (1 << 20)
    read = encode_adu(1, UNIT, bytes.fromhex("03 0000 0001")) * 4096
    async with line(master_options={"timeout": 5.0}) as bench:
        bench.slave.before_request(slow)
        async with serve("tcp://127.0.0.1:0", {UNIT: device()}) as tcp_server:
            tcp_server.before_request(slow)
            port = bench.gateway.port if server == "gateway" else tcp_server.port
            with socket.create_connection(("127.0.0.1", port)) as sock:
                # Bytes waiting before the server's first read: where anyio's accept left
                # the connection reading for good.
                sock.sendall(read[:65536])
                sent = await anyio.to_thread.run_sync(_flood, sock, read)
    assert 0 < sent <= bound, f"{sent} bytes taken, more than the {bound} TCP can hold"


async def test_a_read_in_the_same_segment_as_a_write_sees_the_write() -> None:
    # The write goes to a worker, which hands it to the engine only when it runs; the read
    # behind it, on an idle line, must not go out first.
    async with line() as bench, await anyio.connect_tcp("127.0.0.1", bench.gateway.port) as stream:
        tcp = TcpClient(stream)
        for value in (0x42, 0x43, 0x44):
            write = encode_adu(1, UNIT, bytes.fromhex(f"06 0005 {value:04X}"))
            await stream.send(write + encode_adu(2, UNIT, bytes.fromhex("03 0005 0001")))
            replies = {}
            for _ in range(2):
                reply = await tcp.receive()
                assert reply is not None
                replies[reply.transaction_id] = reply.pdu.hex()
            assert replies == {
                1: f"06 0005 {value:04x}".replace(" ", ""),
                2: f"0302{value:04x}",
            }

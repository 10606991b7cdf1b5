"""The Modbus TCP server's answer-at-once against the general route: random request
sequences (every kind of request, to served, aliased and unknown units, sent one per write,
pipelined or split) give the same replies, stores, counters and event log with the shortcut on
and off (test_tcp_server_general.py runs the server's tests with its connections on anyio's
streams); an idle timeout counts requests answered at once as traffic; and a client that does
not read its replies holds the server back without losing one."""

from __future__ import annotations

import asyncio
import dataclasses
import random
import socket
from typing import Any

import anyio
import anyio.abc
import pytest

from aiortu.core.mbap import AduDecoder, encode_adu
from aiortu.core.pdu import RawPDU
from aiortu.core.rtu import decode_frame, encode_frame
from aiortu.slave import MemoryStore, RequestContext, RtuOverTcpServer, Table, serve
from aiortu.slave._tcp_server import READ_SIZE
from tests.slave.tcp_helpers import UNIT, connect, device, tcp_server

pytestmark = pytest.mark.timeout(60)


# -- the differential test ----------------------------------------------------------------

PDUS = [
    "01 0000 0004", "01 000C 0008", "01 0000 07D1", "02 0000 0003", "02 0007 0002",
    "03 0000 0003", "03 0000 0010", "03 0000 007E", "03 00FF 0002", "03 000F 0002",
    "04 0001 0002", "04 0000 0004", "05 0001 FF00", "05 0002 1234", "06 0003 0063",
    "06 0100 0001", "0F 0004 0003 01 05", "10 0004 0003 06 0001 0002 0003",
    "10 0004 0002 06 0001 0002 0003", "10 00FF 0001 02 0007", "17 0000 0001 0001 0001 02 0007",
    "2B 0E 01 00", "41 0102", "03 0000", "08 0000 A537",
]  # fmt: skip
"""Reads and writes the fast paths serve, bad counts and addresses, other codes, a truncated
one, a serial-line-only one."""


def _stores() -> dict[int, MemoryStore]:
    return {UNIT: device(), 3: MemoryStore(holding_registers={0: list(range(16))})}


def _items(rng: random.Random) -> list[list[bytes]]:
    """Writes of ADUs: one per write mostly, sometimes two at once, sometimes split."""
    items: list[list[bytes]] = []
    for transaction_id in range(60):
        unit = rng.choice([UNIT, UNIT, 3, 0, 255, 9])
        adu = encode_adu(transaction_id, unit, bytes.fromhex(rng.choice(PDUS)))
        turn = rng.randrange(8)
        if turn == 0 and items:
            items[-1] = [b"".join(items[-1]) + adu]  # pipelined behind the one before
        elif turn == 1:
            cut = rng.randrange(1, len(adu))
            items.append([adu[:cut], adu[cut:]])
        else:
            items.append([adu])
    return items


async def _run(items: list[list[bytes]], at_once: bool) -> dict[str, Any]:
    stores = _stores()
    replies: list[str] = []
    async with (
        tcp_server(stores, unit_aliases={0: UNIT, 255: 3}) as server,
        connect(server) as client,
    ):
        assert server._at_once is not None
        server._at_once.enabled = at_once
        for writes in items:
            expected = len(AduDecoder().feed(b"".join(writes)))
            for index, data in enumerate(writes):
                if index:
                    await anyio.sleep(0.005)
                await client.stream.send(data)
            for _ in range(expected):
                reply = await client.receive(wait=2.0)
                replies.append("none" if reply is None else f"{reply}")
        machine = server.machine
        return {
            "replies": replies,
            "answered at once": server._at_once.answered,
            "server counters": dataclasses.asdict(server.counters),
            "line counters": dataclasses.asdict(machine.counters),
            "events": machine.event_log.events(),
            "event count": machine.event_log.event_count,
            "stores": {
                unit: [list(block.values) for table in Table for block in store.blocks(table)]
                for unit, store in stores.items()
            },
        }


@pytest.mark.parametrize("seed", range(4))
async def test_the_shortcut_and_the_general_route_agree(seed: int) -> None:
    items = _items(random.Random(seed))
    general = await _run(items, at_once=False)
    shortcut = await _run(items, at_once=True)
    assert general.pop("answered at once") == 0
    answered = shortcut.pop("answered at once")
    assert answered >= 10, f"seed {seed}: the shortcut answered only {answered}"
    for key, value in general.items():
        assert shortcut[key] == value, f"seed {seed}: {key} differ"


# -- the idle timeout and a client that does not read ----------------------------------------


async def test_requests_answered_at_once_keep_a_connection_from_idling() -> None:
    async with tcp_server(idle_timeout=0.3) as server, connect(server) as client:
        assert server._at_once is not None
        with anyio.fail_after(5):
            for _ in range(16):  # 0.8 s of requests, each answered at once
                await anyio.sleep(0.05)
                assert await client.request("03 0000 0001") == "03 02 12 34"
        last = anyio.current_time()
        assert server._at_once.answered == 16
        assert server.counters.connections_idle == 0
        assert await client.closed_by_server(wait=5.0)
        assert anyio.current_time() - last >= 0.29  # idle counted from the last request
        assert server.counters.connections_idle == 1


def _largest_send_buffer() -> int:
    with open("/proc/sys/net/ipv4/tcp_wmem") as file:
        return int(file.read().split()[2])


async def test_a_client_that_does_not_read_is_held_back_and_loses_no_reply() -> None:
    """Pipelined reads of 125 registers (12 bytes in, 259 out) from a client with a small
    receive buffer that reads nothing: the server answers until the buffers are full, then
    stops reading; once the client reads, every reply comes, in order."""
    send_buffer = _largest_send_buffer()
    # The kernel's buffers, the transport's high-water mark and one read's replies.
    bound = (send_buffer + 2 * 8192 + (64 << 10) + (READ_SIZE // 12 + 1) * 259) // 259
    count = bound + 8000
    request = bytes.fromhex("03 0000 007D")
    async with tcp_server({UNIT: MemoryStore(holding_registers={0: [7] * 125})}) as server:
        sock = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
        sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 4096)
        sock.setblocking(False)
        loop = asyncio.get_running_loop()
        await loop.sock_connect(sock, ("127.0.0.1", server.port))
        with sock:
            data = b"".join(encode_adu(n & 0xFFFF, UNIT, request) for n in range(count))
            sending = loop.create_task(loop.sock_sendall(sock, data))
            answered = -1
            with anyio.fail_after(20):
                while answered != server.counters.requests:  # until it stops answering
                    answered = server.counters.requests
                    await anyio.sleep(0.3)
            assert answered <= bound, f"{answered} replies queued for a client that reads nothing"
            decoder = AduDecoder()
            ids: list[int] = []
            with anyio.fail_after(30):
                while len(ids) < count:
                    chunk = await loop.sock_recv(sock, 65536)
                    assert chunk, "the server closed the connection"
                    ids += [adu.transaction_id for adu in decoder.feed(chunk)]
                await sending
        assert ids == [n & 0xFFFF for n in range(count)]
        assert server.counters.requests == count


async def test_a_request_whose_tail_looks_like_a_whole_one_is_framed_as_one() -> None:
    """The first 7 bytes of a request, then its 12 other bytes, which by themselves make a
    well-formed read: the framing holds the 7, so the 12 are not a request of their own."""
    tail = encode_adu(0x0300, UNIT, bytes.fromhex("03 0000 0001"))  # starts with 03
    request = encode_adu(5, UNIT, tail)  # a read of function 03 with 11 bytes too many
    async with tcp_server() as server, connect(server) as client:
        await client.stream.send(request[:7])
        await anyio.sleep(0.05)
        await client.stream.send(request[7:])
        reply = await client.receive()
        assert reply is not None
        assert (reply.transaction_id, reply.pdu.hex()) == (5, "8303")
        assert await client.receive(wait=0.2) is None
        assert server._at_once is not None
        assert server._at_once.answered == 0


async def test_a_request_under_way_on_another_connection_finishes_first() -> None:
    release = anyio.Event()

    async def slow(request: RawPDU, context: RequestContext) -> RawPDU:
        await release.wait()
        return RawPDU(0x41, b"")

    async with (
        tcp_server(handlers={0x41: slow}) as server,
        connect(server) as first,
        connect(server) as second,
    ):
        await first.send("41")
        await anyio.sleep(0.05)  # the handler awaits, the machine is not IDLE
        await second.send("03 0000 0001", transaction_id=2)
        assert await second.receive(wait=0.2) is None, "answered while a request was under way"
        release.set()
        reply = await second.receive()
        assert reply is not None
        assert reply.pdu.hex() == "03021234"
        assert await first.receive() is not None
        assert server._at_once is not None
        assert server._at_once.answered == 0
        assert await second.request("03 0000 0001") == "03 02 12 34"
        assert server._at_once.answered == 1


async def test_listen_only_mode_answers_nothing() -> None:
    async with tcp_server(serial_line_codes=True) as server, connect(server) as client:
        assert await client.request("03 0000 0001") == "03 02 12 34"
        assert server._at_once is not None
        assert server._at_once.answered == 1
        await client.send("08 0004 0000")  # force listen-only mode: no reply
        with anyio.fail_after(5):
            while not server.machine.listen_only:  # noqa: ASYNC110 - the machine's own flag
                await anyio.sleep(0.01)
        await anyio.sleep(0.02)  # the connection's task waits for bytes again
        await client.send("03 0000 0001")
        assert await client.receive(wait=0.2) is None
        assert server.machine.listen_only
        await client.send("08 0001 0000")  # restart communications: no reply, listening again
        assert await client.request("03 0000 0001") == "03 02 12 34"
        assert not server.machine.listen_only


async def test_hooks_see_every_request() -> None:
    seen: list[tuple[str, int]] = []
    async with tcp_server() as server, connect(server) as client:
        assert server._at_once is not None
        remove_before = server.before_request(
            lambda request, ctx: seen.append(("before", ctx.unit))
        )
        assert await client.request("03 0000 0001") == "03 02 12 34"
        remove_before()
        remove_after = server.after_request(lambda request, ctx, answer: seen.append(("after", 1)))
        assert await client.request("06 0001 0007") == "06 00 01 00 07"
        remove_after()
        assert server._at_once.answered == 0
        assert await client.request("03 0001 0001") == "03 02 00 07"
        assert server._at_once.answered == 1
    assert seen == [("before", UNIT), ("after", 1)]


async def test_rtu_over_tcp_connections_have_no_tap() -> None:
    """An MBAP request on an RTU-over-TCP connection is noise to its framing, not a request
    the Modbus TCP shortcut answers."""
    async with serve("rtu+tcp://127.0.0.1:0", {UNIT: device()}) as server:
        assert isinstance(server, RtuOverTcpServer)
        async with await anyio.connect_tcp("127.0.0.1", server.port) as stream:
            await stream.send(encode_adu(1, UNIT, bytes.fromhex("03 0000 0001")))
            with anyio.move_on_after(0.3) as silent:
                await stream.receive()
            assert silent.cancelled_caught, "an RTU server answered an MBAP request"
            await stream.send(encode_frame(UNIT, bytes.fromhex("03 0000 0001")))
            assert decode_frame(await stream.receive()).pdu.hex() == "03021234"
        assert server._at_once.answered == 0

"""`--listen udp://` on the gateway: each datagram answered to its source, each source a
connection of the gateway's own (window, limit, idle timeout), malformed datagrams refused."""

from __future__ import annotations

import anyio
import anyio.abc
import pytest

from aiortu.core.mbap import Adu, decode_adu, encode_adu
from aiortu.master import open_master
from aiortu.transport import PEER_BACKLOG, DatagramListener
from tests.gateway.helpers import UNIT, line

pytestmark = pytest.mark.timeout(30)

_READ = bytes.fromhex("03 0000 0002")


async def _ask(sock: anyio.abc.UDPSocket, port: int, tid: int, pdu: bytes = _READ) -> Adu:
    await sock.sendto(encode_adu(tid, UNIT, pdu), "127.0.0.1", port)
    with anyio.fail_after(5):
        data, _ = await sock.receive()
    return decode_adu(data)


async def test_a_master_reads_through_a_udp_listener() -> None:
    async with line(listen=("udp://127.0.0.1:0",)) as bus:
        url = f"udp://127.0.0.1:{bus.gateway.port}"
        async with open_master(url, timeout=2, retries=0) as master:
            first = await master.read_holding_registers(UNIT, 0, 2)
            again = await master.read_holding_registers(UNIT, 0, 2)
        assert first == again
        assert len(first) == 2
        assert bus.messages == 2
        assert bus.gateway.counters.requests == 2


async def test_each_source_gets_its_own_answers_and_connection() -> None:
    async with line(listen=("udp://127.0.0.1:0",)) as bus:
        port = bus.gateway.port
        async with (
            await anyio.create_udp_socket(local_host="127.0.0.1") as one,
            await anyio.create_udp_socket(local_host="127.0.0.1") as two,
        ):
            reply_one = await _ask(one, port, 7)
            reply_two = await _ask(two, port, 9)
            assert (reply_one.transaction_id, reply_two.transaction_id) == (7, 9)
            assert reply_one.pdu == reply_two.pdu
            assert reply_one.pdu[0] == 3
            assert bus.gateway.connections == 2
            assert bus.gateway.counters.connections_accepted == 2


async def test_malformed_datagrams_are_refused_and_the_source_still_served() -> None:
    async with line(listen=("udp://127.0.0.1:0",)) as bus:
        port = bus.gateway.port
        async with await anyio.create_udp_socket(local_host="127.0.0.1") as sock:
            good = encode_adu(1, UNIT, _READ)
            for bad in (good[:-1], good + b"\x00", b"\x00" * 300, good[:5]):
                await sock.sendto(bad, "127.0.0.1", port)
            reply = await _ask(sock, port, 2)
            assert reply.transaction_id == 2  # nothing answered before it
            assert bus.gateway.counters.requests == 1


async def test_sources_over_the_limit_are_not_served() -> None:
    async with line(listen=("udp://127.0.0.1:0",), max_connections=1) as bus:
        port = bus.gateway.port
        async with (
            await anyio.create_udp_socket(local_host="127.0.0.1") as one,
            await anyio.create_udp_socket(local_host="127.0.0.1") as two,
        ):
            await _ask(one, port, 1)
            await two.sendto(encode_adu(2, UNIT, _READ), "127.0.0.1", port)
            with anyio.move_on_after(0.3) as waited:
                await two.receive()
            assert waited.cancelled_caught
            assert bus.gateway.counters.connections_refused >= 1
            assert (await _ask(one, port, 3)).transaction_id == 3


async def test_an_idle_source_is_closed_and_served_again_later() -> None:
    async with line(listen=("udp://127.0.0.1:0",), idle_timeout=0.1) as bus:
        port = bus.gateway.port
        async with await anyio.create_udp_socket(local_host="127.0.0.1") as sock:
            await _ask(sock, port, 1)
            with anyio.fail_after(5):
                while bus.gateway.connections:  # noqa: ASYNC110
                    await anyio.sleep(0.02)
            assert bus.gateway.counters.connections_idle == 1
            assert (await _ask(sock, port, 2)).transaction_id == 2
            assert bus.gateway.counters.connections_accepted == 2


async def test_a_flood_past_the_backlog_is_dropped_not_queued() -> None:
    sock = await anyio.create_udp_socket(local_host="127.0.0.1")
    port = sock.extra(anyio.abc.SocketAttribute.local_port)
    listener = DatagramListener(sock, f"udp://127.0.0.1:{port}")
    served: list[anyio.abc.ByteStream] = []

    async def hold(stream: anyio.abc.ByteStream) -> None:
        served.append(stream)  # reads nothing: every datagram waits
        await anyio.sleep_forever()

    async with anyio.create_task_group() as tasks, listener:
        tasks.start_soon(listener.serve, hold)
        async with await anyio.create_udp_socket(local_host="127.0.0.1") as client:
            for tid in range(PEER_BACKLOG + 5):
                await client.sendto(encode_adu(tid, UNIT, _READ), "127.0.0.1", port)
            with anyio.fail_after(5):
                while listener.counters.received < PEER_BACKLOG + 5:  # noqa: ASYNC110
                    await anyio.sleep(0.01)
        assert len(served) == 1
        assert listener.counters.refused == 5
        assert [decode_adu(await served[0].receive()).transaction_id for _ in range(3)] == [0, 1, 2]
        tasks.cancel_scope.cancel()

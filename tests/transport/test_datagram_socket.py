"""The datagram socket both ends of Modbus UDP read on asyncio: a full send buffer, an error the
socket reports, and closing while a writer waits."""

from __future__ import annotations

import logging
import socket
from typing import Any

import anyio
import anyio.lowlevel
import pytest

import aiortu
from aiortu.core.mbap import Adu, decode_adu, encode_adu
from aiortu.errors import PortBusy
from aiortu.transport import (
    DatagramCounters,
    DatagramServer,
    ModbusTcpCounters,
    PushDatagramStream,
    check_datagram,
)
from aiortu.transport._datagram_socket import DatagramSocket

pytestmark = pytest.mark.timeout(30)

REQUEST = bytes.fromhex("01 03 00 00 00 01 84 0A")


class _FullOnce(socket.socket):
    """A datagram socket whose send buffer is full for the first `full` sends; `seen` gets
    the value of `clock` at each send tried."""

    full = 1
    clock: list[int] = [0]  # noqa: RUF012 - set per test
    seen: list[int] = []  # noqa: RUF012 - set per test

    def sendto(self, data: Any, *args: Any) -> int:  # type: ignore[override]
        self.seen.append(self.clock[0])
        if self.full:
            self.full -= 1
            raise BlockingIOError
        return super().sendto(data, *args)


class _RefusedOnce(socket.socket):
    """A datagram socket that reports an ICMP error (port unreachable) on its first read."""

    refused = True

    def recvfrom(self, size: int, *args: Any) -> Any:  # type: ignore[override]
        if self.refused:
            self.refused = False
            raise ConnectionRefusedError(111, "Connection refused")
        return super().recvfrom(size, *args)


def _pushed(sock: socket.socket, port: int) -> PushDatagramStream:
    stream = PushDatagramStream(
        ("127.0.0.1", port), ModbusTcpCounters(), "udp://test", check_datagram
    )
    stream.socket = DatagramSocket(sock, stream.datagram, stream.closed, stream.where)
    return stream


async def test_a_request_the_socket_cannot_take_now_goes_when_it_can() -> None:
    full = _FullOnce(socket.AF_INET, socket.SOCK_DGRAM)
    full.full, full.clock, full.seen = 3, [0], []

    async def ticks() -> None:  # counts the event loop's turns
        while True:
            await anyio.lowlevel.checkpoint()
            full.clock[0] += 1

    async with (
        await anyio.create_udp_socket(local_host="127.0.0.1") as peer,
        anyio.create_task_group() as group,
    ):
        group.start_soon(ticks)
        port = peer.extra(anyio.abc.SocketAttribute.local_port)
        stream = _pushed(full, port)
        async with stream:
            assert not stream.send_nowait(REQUEST)
            # Nothing went: the transaction id and the count are as before.
            assert (stream.counters.next_transaction_id, stream.counters.requests) == (0, 0)
            with anyio.fail_after(5):
                await stream.send(REQUEST)  # waits for the socket between tries, then sends
                data, _ = await peer.receive()
            assert decode_adu(data) == Adu(0, 1, bytes.fromhex("03 0000 0001"))
            assert (stream.counters.next_transaction_id, stream.counters.requests) == (1, 1)
        group.cancel_scope.cancel()
    assert len(full.seen) == 4
    assert full.seen[1] < full.seen[2] < full.seen[3], "no wait between the tries"


async def test_an_error_the_socket_reports_is_logged_and_reading_goes_on(
    caplog: pytest.LogCaptureFixture,
) -> None:
    caplog.set_level(logging.DEBUG, logger="aiortu")
    async with await anyio.create_udp_socket(local_host="127.0.0.1") as peer:
        port = peer.extra(anyio.abc.SocketAttribute.local_port)
        stream = _pushed(_RefusedOnce(socket.AF_INET, socket.SOCK_DGRAM), port)
        async with stream:
            await stream.send(REQUEST)
            _, source = await peer.receive()
            reply = encode_adu(0, 1, bytes.fromhex("03 02 0007"))
            await peer.sendto(reply, *source)  # read first as the error, then as itself
            with anyio.fail_after(5):
                frame = await stream.receive()
            assert frame[:5] == bytes.fromhex("01 03 02 0007")
    assert any("Connection refused" in r.getMessage() for r in caplog.records)


async def test_closing_wakes_a_writer_waiting_for_the_socket() -> None:
    closed: list[bool] = []
    sock = DatagramSocket(
        socket.socket(socket.AF_INET, socket.SOCK_DGRAM),
        lambda data, source: None,
        lambda: closed.append(True),
        "udp://test",
    )
    waited = anyio.Event()

    async def wait() -> None:
        await sock.wait_writable()
        waited.set()

    async with anyio.create_task_group() as group:
        group.start_soon(wait)
        # The waiter registers and sleeps before the loop next polls the socket: closing
        # now, its writer callback never runs; only the close can wake it.
        await anyio.lowlevel.checkpoint()
        sock.close()
        with anyio.fail_after(5):
            await waited.wait()
    assert closed == [True]
    assert not sock.sendto(b"x", ("127.0.0.1", 9))
    sock.close()  # once only
    assert closed == [True]


async def test_a_reply_the_socket_cannot_take_is_lost_and_counted(
    caplog: pytest.LogCaptureFixture,
) -> None:
    async def answer(adu: Adu) -> bytes | None:
        return None

    counters = DatagramCounters()
    server = DatagramServer(answer, counters)
    await server.bind("127.0.0.1", 0)
    assert server.socket is not None
    full = _FullOnce(socket.AF_INET, socket.SOCK_DGRAM)
    full.full = 2
    server.socket.close()
    server.socket = DatagramSocket(full, server.datagram_received, lambda: None, "udp://test")
    caplog.set_level(logging.DEBUG, logger="aiortu")
    async with await anyio.create_udp_socket(local_host="127.0.0.1") as peer:
        port = peer.extra(anyio.abc.SocketAttribute.local_port)
        for _ in range(3):
            server.reply(encode_adu(1, 1, b"\x03\x00"), ("127.0.0.1", port))
        with anyio.fail_after(5):
            data, _ = await peer.receive()
    server.socket.close()
    assert decode_adu(data).transaction_id == 1
    assert (counters.replies, counters.unsent) == (1, 2)
    lost = [r.levelno for r in caplog.records if "was lost" in r.getMessage()]
    assert lost == [logging.WARNING, logging.DEBUG]


async def test_a_port_in_use_is_a_port_error() -> None:
    async with aiortu.serve("udp://127.0.0.1:0", {1: aiortu.MemoryStore()}) as server:
        with pytest.raises(PortBusy, match=r"^udp://127\.0\.0\.1:\d+: the port is in use"):
            async with aiortu.serve(f"udp://127.0.0.1:{server.port}", {1: aiortu.MemoryStore()}):
                pass

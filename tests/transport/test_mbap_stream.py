"""ModbusTcpStream: RTU frames out as ADUs, ADUs of the outstanding transaction back as RTU
frames, whatever the TCP chunks; others dropped and counted; a bad header ends the stream."""

from __future__ import annotations

import random
from collections.abc import AsyncIterator
from contextlib import asynccontextmanager

import anyio
import anyio.abc
import anyio.lowlevel
import pytest

from aiortu.core.mbap import AduDecoder, encode_adu
from aiortu.core.rtu import FrameReceived, crc16
from aiortu.line import Link
from aiortu.transport import FramedStream, ModbusTcpCounters, ModbusTcpStream

pytestmark = pytest.mark.timeout(20)


def rtu(unit: int, pdu: bytes) -> bytes:
    frame = bytes((unit,)) + pdu
    crc = crc16(frame)
    return frame + bytes((crc & 0xFF, crc >> 8))


@asynccontextmanager
async def pair(
    counters: ModbusTcpCounters | None = None,
) -> AsyncIterator[tuple[ModbusTcpStream, anyio.abc.SocketStream]]:
    """A ModbusTcpStream and the server's end of its TCP connection."""
    listener = await anyio.create_tcp_listener(local_host="127.0.0.1", local_port=0)
    port = listener.extra(anyio.abc.SocketAttribute.local_port)
    async with listener:
        client = await anyio.connect_tcp("127.0.0.1", port)
        server = await listener.listeners[0].accept()  # type: ignore[attr-defined]
        async with client, server:
            yield ModbusTcpStream(client, counters), server


async def read_adus(server: anyio.abc.SocketStream, count: int) -> list[tuple[int, int, bytes]]:
    decoder, adus = AduDecoder(), []
    with anyio.fail_after(5):
        while len(adus) < count:
            adus += decoder.feed(await server.receive())
    return [(adu.transaction_id, adu.unit, adu.pdu) for adu in adus]


async def test_a_frame_goes_out_as_an_adu_with_the_next_transaction_id() -> None:
    async with pair(ModbusTcpCounters(next_transaction_id=0xFFFF)) as (stream, server):
        assert isinstance(stream, FramedStream)
        await stream.send(rtu(17, b"\x03\x00\x00\x00\x02"))
        await stream.send(rtu(18, b"\x41"))
        assert await read_adus(server, 2) == [
            (0xFFFF, 17, b"\x03\x00\x00\x00\x02"),
            (0, 18, b"\x41"),  # wraps
        ]
        assert stream.counters.next_transaction_id == 1


async def test_only_the_outstanding_reply_comes_back_whatever_the_chunks() -> None:
    seed = random.randrange(2**32)
    chooser = random.Random(seed)
    async with pair() as (stream, server):
        for transaction_id in range(20):
            await stream.send(rtu(5, b"\x03\x00\x00\x00\x01"))
            reply = bytes((3, 2, 0, transaction_id))
            wire = (
                encode_adu((transaction_id - 1) & 0xFFFF, 5, b"\x03\x02\xde\xad")  # stale
                + encode_adu(transaction_id, 5, reply)
                + encode_adu(transaction_id, 5, b"\x03\x02\xbe\xef")  # a second reply
            )
            cut = chooser.randrange(1, len(wire))
            await server.send(wire[:cut])
            await anyio.lowlevel.checkpoint()
            await server.send(wire[cut:])
            with anyio.fail_after(5):
                assert await stream.receive() == rtu(5, reply), f"seed {seed}"
        counters = stream.counters
        assert (counters.requests, counters.replies, counters.dropped) == (20, 20, 40), seed


async def test_a_malformed_header_closes_the_stream() -> None:
    async with pair() as (stream, server):
        await stream.send(rtu(1, b"\x03\x00\x00\x00\x01"))
        await server.send(b"\x00\x00\x00\x01\x00\x05\x01\x03\x02\x00\x07")  # protocol id 1
        with pytest.raises(anyio.BrokenResourceError, match="protocol id is 1"):
            await stream.receive()
        with pytest.raises(anyio.ClosedResourceError):
            await stream.send(rtu(1, b"\x03\x00\x00\x00\x01"))


async def test_a_link_ends_a_frame_of_unknown_length_as_it_arrives() -> None:
    async with pair() as (stream, server):
        link = Link(stream)
        assert (link.frame_gap, link.char_time, link.receiver.frame_silence) == (0, 0, 0)
        async with link:
            await link.send(rtu(9, b"\x41\x01"))
            (_, unit, _), *_ = await read_adus(server, 1)
            await server.send(encode_adu(0, unit, b"\x41\x01\x02\x03"))
            with anyio.fail_after(5):
                event = await link.receive()
        assert isinstance(event, FrameReceived)
        assert event.frame == rtu(9, b"\x41\x01\x02\x03")

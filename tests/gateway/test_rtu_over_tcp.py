"""The `rtu+tcp://` listener: RTU frames over TCP, as a serial device server sends them. A frame
of unknown length ends after a silence, and a dropped frame is asserted by a wait: those tests
run on a virtual clock, their clients on in-memory streams served as the listener serves a
socket. The server framings' own rules are checked without I/O."""

from __future__ import annotations

from dataclasses import replace

import anyio
import anyio.abc
import pytest

from aiortu.core.ascii import encode_ascii_frame
from aiortu.core.mbap import encode_adu
from aiortu.core.pdu import RawPDU
from aiortu.core.rtu import encode_frame
from aiortu.slave import RequestContext
from aiortu.transport import RTU_SILENCE, AsciiFraming, Framing, MbapFraming, RtuFraming
from tests.gateway.helpers import UNIT, line, memory_stream
from tests.virtual_clock import on_virtual_clock

pytestmark = pytest.mark.timeout(30)


async def _reply(stream: anyio.abc.ByteStream, wait: float = 3.0) -> bytes | None:
    """The bytes the gateway sends next, or None when it sends nothing within `wait`."""
    with anyio.move_on_after(wait):
        return await stream.receive()
    return None


def _echo(request: object, context: RequestContext) -> RawPDU:
    assert isinstance(request, RawPDU)
    return RawPDU(0x41, request.data)


@on_virtual_clock
async def test_rtu_frames_are_answered_with_rtu_frames() -> None:
    async with line(listen=()) as bench:
        bench.slave.set_handler(0x41, _echo)
        async with memory_stream(bench.gateway, rtu_framing=True) as stream:
            await stream.send(encode_frame(UNIT, bytes.fromhex("03 0001 0002")))
            assert await _reply(stream) == encode_frame(UNIT, bytes.fromhex("03 04 ABCD 0007"))
            # A user-defined code: its length is unknown, a silence ends it. The gateway waits
            # that silence, then the transaction takes what it takes on the line.
            start = anyio.current_time()
            await bench.master.execute(UNIT, RawPDU(0x41, b"\x01\x02"))
            on_the_line = anyio.current_time() - start
            start = anyio.current_time()
            await stream.send(encode_frame(UNIT, bytes.fromhex("41 0102")))
            assert await _reply(stream) == encode_frame(UNIT, bytes.fromhex("41 0102"))
            elapsed = anyio.current_time() - start
            assert elapsed == pytest.approx(RTU_SILENCE + on_the_line, abs=1e-9)
            # Two frames in one chunk: answered in order, one at a time.
            two = encode_frame(UNIT, bytes.fromhex("03 0000 0001")) + encode_frame(
                UNIT, bytes.fromhex("04 0000 0001")
            )
            await stream.send(two)
            replies = b""
            with anyio.fail_after(3):
                while len(replies) < 14:
                    replies += await stream.receive()
            assert replies == encode_frame(UNIT, bytes.fromhex("03 02 1234")) + encode_frame(
                UNIT, bytes.fromhex("04 02 000B")
            )


@on_virtual_clock
async def test_a_bad_crc_is_dropped_and_the_connection_goes_on() -> None:
    async with line(listen=()) as bench, memory_stream(bench.gateway, rtu_framing=True) as stream:
        frame = bytearray(encode_frame(UNIT, bytes.fromhex("03 0000 0001")))
        frame[-1] ^= 0xFF
        await stream.send(bytes(frame))
        assert await _reply(stream, wait=10) is None
        assert bench.messages == 0
        await stream.send(encode_frame(UNIT, bytes.fromhex("03 0000 0001")))
        assert await _reply(stream) == encode_frame(UNIT, bytes.fromhex("03 02 1234"))


READ = bytes.fromhex("03 0000 0001")


@pytest.mark.parametrize(
    ("framing", "request_bytes"),
    [
        (MbapFraming(), encode_adu(7, UNIT, READ)),
        (RtuFraming(), encode_frame(UNIT, READ)),
        (AsciiFraming(), encode_ascii_frame(UNIT, READ)),
    ],
    ids=lambda value: type(value).__name__,
)
def test_a_framing_whose_replies_carry_no_transaction_id_keeps_them_in_order(
    framing: Framing, request_bytes: bytes
) -> None:
    # A server pipelines a connection's requests only when its replies say which they answer.
    (request,) = framing.feed(request_bytes)
    assert request.pdu == READ
    assert framing.discarded == 0
    ids = {framing.encode(replace(request, transaction_id=i), b"\x83\x02") for i in (1, 2)}
    assert framing.in_order is (len(ids) == 1)


@pytest.mark.parametrize(
    ("framing", "bad", "good"),
    [
        (RtuFraming(), encode_frame(UNIT, READ)[:-1] + b"\x00", encode_frame(UNIT, READ)),
        (
            AsciiFraming(),
            encode_ascii_frame(UNIT, READ)[:-4] + b"00\r\n",
            encode_ascii_frame(UNIT, READ),
        ),
    ],
    ids=lambda value: type(value).__name__,
)
def test_a_framing_counts_each_frame_it_drops_once(
    framing: Framing, bad: bytes, good: bytes
) -> None:
    assert framing.discarded == 0
    assert [request.pdu for request in framing.feed(bad + good)] == [READ]
    assert framing.discarded == 1

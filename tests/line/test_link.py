"""The link: a byte stream pumped through the receiver, with the silence kept before sending."""

from __future__ import annotations

import anyio
import pytest

from aiortu.core.rtu import DiscardReason, FrameDiscarded, FrameReceived, Role, encode_frame
from aiortu.core.serial import LineSettings
from aiortu.errors import ConnectionLost
from aiortu.line import Link
from aiortu.testing import virtual_pair

H = bytes.fromhex
REQUEST = H("11 03 00 6B 00 03 76 87")
REPLY = H("11 03 06 AE 41 56 52 43 40 49 AD")
FAST = LineSettings(115200)
GAP = 0.050
"""A frame gap far longer than scheduling noise, so the timing checks are not flaky."""


async def _settle() -> None:
    """Let the link's reader open: it ignores what arrives in its first frame silence."""
    await anyio.sleep(0.03)


async def test_delivers_frames_from_the_other_end() -> None:
    near, far = virtual_pair()
    async with Link(near, FAST, role=Role.SLAVE, units={0x11}, frame_gap=0) as link:
        await _settle()
        await far.send(REQUEST)
        await anyio.sleep(0.03)
        await far.send(REQUEST[:4])
        await far.send(REQUEST[4:])
        with anyio.fail_after(2):
            first = await link.receive()
            second = await link.receive()
        assert isinstance(first, FrameReceived)
        assert first.frame == REQUEST
        assert isinstance(second, FrameReceived)
        assert second.frame == REQUEST
        assert link.frames_received == 2


async def test_garbage_is_reported_as_a_discard() -> None:
    near, far = virtual_pair()
    async with Link(near, FAST, role=Role.MASTER, frame_gap=0) as link:
        await _settle()
        await far.send(b"\x99\x98\x97\x96\x95")
        with anyio.fail_after(2):
            event = await link.receive()
        assert isinstance(event, FrameDiscarded)
        assert link.discarded[event.reason] == 1
        await far.send(REPLY)
        with anyio.fail_after(2):
            event = await link.receive()
        assert isinstance(event, FrameReceived)
        assert event.frame == REPLY


async def test_send_waits_for_the_gap_after_the_last_byte_received() -> None:
    near, far = virtual_pair()
    async with Link(near, FAST, role=Role.MASTER, frame_gap=GAP) as link:
        await _settle()
        await far.send(REPLY)
        with anyio.fail_after(2):
            event = await link.receive()
        assert isinstance(event, FrameReceived)
        end = await link.send(REQUEST)
        start = end - FAST.wire_time(len(REQUEST))
        assert start >= event.end + GAP
        assert start < event.end + GAP + 0.5
        assert end >= link.clock() - 0.5
        with anyio.fail_after(2):
            assert await far.receive() == REQUEST


async def test_send_waits_for_the_gap_after_its_own_frame() -> None:
    near, far = virtual_pair()
    async with Link(near, FAST, frame_gap=GAP) as link:
        first_end = await link.send(REQUEST)
        assert first_end == link.last_activity
        second_end = await link.send(REQUEST)
        second_start = second_end - FAST.wire_time(len(REQUEST))
        assert second_start >= first_end + GAP
        assert link.frames_sent == 2
        with anyio.fail_after(2):
            received = b""
            while len(received) < 2 * len(REQUEST):
                received += await far.receive()
        assert received == REQUEST * 2


async def test_send_returns_start_plus_wire_time() -> None:
    near, _far = virtual_pair()
    slow = LineSettings(9600)
    times = iter([100.0, 100.0, 100.0, 100.0])
    # A clock that stands still: the write takes no time, so the end is start + wire time.
    link = Link(near, slow, frame_gap=0, clock=lambda: next(times, 100.0))
    assert await link.send(REQUEST) == 100.0 + 8 * 11 / 9600
    assert link.last_activity == 100.0 + 8 * 11 / 9600


async def test_zero_gap_sends_at_once() -> None:
    near, far = virtual_pair()
    async with Link(near, FAST, role=Role.MASTER, frame_gap=0) as link:
        await _settle()
        await far.send(REPLY)
        with anyio.fail_after(2):
            event = await link.receive()
        assert isinstance(event, FrameReceived)
        before = link.clock()
        end = await link.send(REQUEST)
        start = end - FAST.wire_time(len(REQUEST))
        assert start - before < 0.02


async def test_closed_peer_gives_connection_lost() -> None:
    near, far = virtual_pair()
    async with Link(near, FAST, frame_gap=0) as link:
        await far.send(REPLY)
        await anyio.sleep(0.05)
        await far.aclose()
        with anyio.fail_after(2):
            # The queued frame first, then the loss.
            assert isinstance(await link.receive(), FrameReceived)
            with pytest.raises(ConnectionLost):
                await link.receive()
        with pytest.raises(ConnectionLost):
            await link.send(REQUEST)
        with pytest.raises(ConnectionLost):
            link.receive_nowait()


async def test_broken_stream_on_send_gives_connection_lost() -> None:
    send, receive = anyio.create_memory_object_stream[bytes](10)

    class Broken(anyio.abc.ByteStream):
        async def receive(self, max_bytes: int = 65536) -> bytes:
            return await receive.receive()

        async def send(self, item: bytes) -> None:
            raise anyio.BrokenResourceError

        async def send_eof(self) -> None:
            raise NotImplementedError

        async def aclose(self) -> None:
            await send.aclose()
            await receive.aclose()

    async with Link(Broken(), FAST, frame_gap=0) as link:
        with pytest.raises(ConnectionLost):
            await link.send(REQUEST)


async def test_full_queue_drops_the_oldest() -> None:
    near, far = virtual_pair()
    frames = [encode_frame(unit, H("03 02 00 00")) for unit in range(1, 6)]
    async with Link(near, FAST, role=Role.MASTER, frame_gap=0, queue_size=2) as link:
        await _settle()
        for frame in frames:
            await far.send(frame)
        await anyio.sleep(0.2)  # far longer than the pump needs; nothing reads meanwhile
        assert link.frames_received == len(frames)
        assert link.events_dropped == 3
        kept = [link.receive_nowait(), link.receive_nowait()]
        assert [event.frame for event in kept if isinstance(event, FrameReceived)] == frames[-2:]
        assert link.receive_nowait() is None


async def test_bytes_in_the_first_silence_are_noise() -> None:
    # A stream read by a task, like a serial port: it may open mid-frame. (A pushing
    # in-memory bus never does: its link starts between frames.)
    near, far = virtual_pair(chunk_size=256)
    # A tail of a frame already on the line when the link opens. At 1200 baud the first
    # silence lasts 32 ms, so a busy machine that reads the bytes late does not turn them
    # into the start of a frame.
    await far.send(REPLY[5:])
    async with Link(near, LineSettings(1200), role=Role.MASTER, frame_gap=0) as link:
        with anyio.fail_after(2):
            event = await link.receive()
        assert isinstance(event, FrameDiscarded)
        assert event.reason is DiscardReason.NOISE


def test_bad_frame_gap_is_refused() -> None:
    near, _far = virtual_pair()
    with pytest.raises(ValueError, match="frame_gap"):
        Link(near, frame_gap=-1.0)
    with pytest.raises(ValueError, match="frame_gap"):
        Link(near, frame_gap=float("nan"))

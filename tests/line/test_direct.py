"""The direct link (`Link.direct`): which links are direct, and what a direct link does with
the reply it expects and with a frame it sends. The differential test against the general
route is tests/master/test_direct_link.py."""

from __future__ import annotations

from collections.abc import Callable

import anyio
import anyio.abc
import anyio.lowlevel
import pytest

from aiortu.core.codes import MBAP_UNIT_IDS, UnitIds
from aiortu.core.rtu import FrameReceived, encode_frame
from aiortu.line import Link, LinkEvent, ReplyTap

REQUEST = encode_frame(1, bytes.fromhex("03 0000 0002"))
REPLY = encode_frame(1, bytes.fromhex("03 04 0007 0008"))


class _Frames(anyio.abc.ByteStream):
    """A push stream of whole frames, as a master's pushed Modbus TCP stream is."""

    def __init__(self, whole: bool = True) -> None:
        self.whole = whole
        self.sent: list[bytes] = []
        self.receiver: Callable[[bytes], None] | None = None
        self._closed = anyio.Event()

    @property
    def whole_frames(self) -> bool:
        return self.whole

    @property
    def unit_ids(self) -> UnitIds:
        return MBAP_UNIT_IDS

    def set_receiver(
        self,
        receiver: Callable[[bytes], None] | None,
        on_lost: Callable[[], None] | None = None,
    ) -> None:
        self.receiver = receiver

    def send_nowait(self, item: bytes) -> bool:
        self.sent.append(item)
        return True

    def push(self, frame: bytes) -> None:
        assert self.receiver is not None
        self.receiver(frame)

    async def receive(self, max_bytes: int = 65536) -> bytes:
        await self._closed.wait()
        raise anyio.ClosedResourceError

    async def send(self, item: bytes) -> None:
        self.sent.append(item)

    async def send_eof(self) -> None:
        pass

    async def aclose(self) -> None:
        self._closed.set()


async def _opened(link: Link) -> None:
    """Let the link's reader task hand the stream its receiver."""
    for _ in range(10):
        await anyio.lowlevel.checkpoint()


@pytest.mark.parametrize(
    ("whole", "frame_gap", "direct"),
    [(True, None, True), (True, 0.0, True), (True, 0.01, False), (False, 0.0, False)],
)
async def test_only_a_pushed_stream_of_whole_frames_with_no_gap_is_direct(
    whole: bool, frame_gap: float | None, direct: bool
) -> None:
    async with Link(_Frames(whole), frame_gap=frame_gap) as link:
        assert link.direct is direct


async def test_a_direct_link_sends_at_once_and_counts_the_frame() -> None:
    now = [5.0]
    stream = _Frames()
    async with Link(stream, clock=lambda: now[0]) as link:
        await _opened(link)
        now[0] = 6.0
        assert link.send_now(REQUEST) == 6.0  # no wire time
        assert stream.sent == [REQUEST]
        assert (link.frames_sent, link.writes_begun, link.last_write_start) == (1, 1, 6.0)
        assert link.last_activity == 6.0
        assert link.quiet_at() == 6.0


async def test_a_direct_link_hands_the_expected_reply_over_and_nothing_else() -> None:
    now = [5.0]
    stream = _Frames()
    taken: list[tuple[bytes, float]] = []
    events: list[LinkEvent | None] = []
    tap = ReplyTap(REPLY[:3], len(REPLY), lambda frame, end: taken.append((frame, end)), None)
    bad_crc = REPLY[:-1] + bytes((REPLY[-1] ^ 1,))
    async with Link(stream, clock=lambda: now[0]) as link:
        link.listen(events.append)
        await _opened(link)
        link.expect(tap)
        now[0] = 6.0
        stream.push(REPLY)
        assert taken == [(REPLY, 6.0)]
        assert (link.frames_received, link.last_activity, events) == (1, 6.0, [])
        stream.push(REPLY)  # once only
        assert taken == [(REPLY, 6.0)]
        link.expect(tap)
        now[0] = 7.0
        stream.push(bad_crc)  # the shape, not the CRC: the receiver's way
        other = encode_frame(2, bytes.fromhex("03 04 0007 0008"))
        stream.push(other)  # another unit: the receiver's way too
        short = encode_frame(1, bytes.fromhex("03 04 0007"))
        stream.push(short)  # the first bytes, not the length: the receiver's way
        await anyio.sleep(0.01)  # its silence ends what it made of it
        assert taken == [(REPLY, 6.0)]
        link.forget_expected()
        stream.push(REPLY)  # not expected any more
        for _ in range(10):
            await anyio.lowlevel.checkpoint()
        assert link.last_activity == 7.0
    received = [event.frame for event in events if isinstance(event, FrameReceived)]
    # The receiver's own way with each: the bad CRC and the short frame (shorter than its
    # first bytes say) discarded, the others received.
    assert received == [REPLY, other, REPLY]
    assert link.frames_received == 1 + len(received)
    assert sum(link.discarded.values()) == 2

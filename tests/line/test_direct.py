"""The direct link (`Link.direct`): which links are direct, and what a direct link does with
the reply it expects and with a frame it sends, and how its reply tap (`PushReader.on_frame`,
which never touches the receiver's silence timer) meets that timer, armed by a malformed frame
just before. The differential tests against the general route are
tests/master/test_direct_link.py and tests/master/test_direct_link_sequences.py."""

from __future__ import annotations

from collections.abc import Awaitable, Callable

import anyio
import anyio.lowlevel
import pytest

from aiortu.core.rtu import DiscardReason, FrameDiscarded, FrameReceived, encode_frame
from aiortu.line import Link, LinkEvent, ReplyTap
from tests.line.fakes import PushedFrames, silence_timer
from tests.virtual_clock import VirtualTimeLoop

REQUEST = encode_frame(1, bytes.fromhex("03 0000 0002"))
REPLY = encode_frame(1, bytes.fromhex("03 04 0007 0008"))


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
    async with Link(PushedFrames(whole=whole), frame_gap=frame_gap) as link:
        assert link.direct is direct


async def test_a_direct_link_sends_at_once_and_counts_the_frame() -> None:
    now = [5.0]
    stream = PushedFrames()
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
    stream = PushedFrames()
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
    # The receiver's own way with each, each a frame of its own though all three came at
    # once: the bad CRC discarded, the others received (the short one's CRC holds: a
    # master finds it misshapen).
    assert received == [REPLY, other, short, REPLY]
    assert link.frames_received == 1 + len(received)
    assert link.discarded == {DiscardReason.CRC: 1}


# -- the reply tap and the receiver's silence timer -----------------------------------------

BAD_CRC = REPLY[:-1] + bytes((REPLY[-1] ^ 0x5A,))
"""The expected reply's shape, not its CRC: the receiver holds it until a silence ends it."""
SHORT = encode_frame(1, bytes.fromhex("03 04 0007"))
"""The expected reply's first bytes, a register missing: the receiver waits for the rest."""
HEAD = REPLY[:5]
"""The first part of the expected reply, split."""


class _Watched:
    """A direct link's expected replies taken by the tap, and what its listener got."""

    def __init__(self, link: Link, stream: PushedFrames) -> None:
        self.link = link
        self.stream = stream
        self.taken: list[tuple[bytes, float]] = []
        self.events: list[LinkEvent | None] = []
        self.tap = ReplyTap(REPLY[:3], len(REPLY), self._take, None)
        link.listen(self.events.append)

    def _take(self, frame: bytes, end: float) -> None:
        self.taken.append((frame, end))

    @property
    def timer(self) -> object:
        """The receiver's silence timer, where one is armed."""
        return silence_timer(self.link)

    def one_read(self, *frames: bytes) -> None:
        """`frames` handed over in one callback, as one read of a socket holds several ADUs;
        no timer of the loop runs in between."""
        for frame in frames:
            self.stream.push(frame)


def _on_a_virtual_clock(
    scenario: Callable[[_Watched], Awaitable[None]], *, whole: bool = True
) -> None:
    """Run `scenario` on a direct link (asyncio: the push path) on the virtual clock; on a
    pushed link of a serial line (its frame silence 20 ms), not `whole`."""

    async def run() -> None:
        stream = PushedFrames(whole=whole)
        async with Link(stream) as link:
            await _opened(link)
            assert link.direct is whole
            watched = _Watched(link, stream)
            link.expect(watched.tap)
            await scenario(watched)

    anyio.run(run, backend="asyncio", backend_options={"loop_factory": VirtualTimeLoop})


def _discarded(event: LinkEvent | None) -> tuple[bytes, DiscardReason] | None:
    return (event.data, event.reason) if isinstance(event, FrameDiscarded) else None


@pytest.mark.parametrize(
    ("malformed", "reason"),
    [
        (BAD_CRC, DiscardReason.CRC),
        (HEAD, DiscardReason.CRC),
        (b"\x00\xff", DiscardReason.TOO_SHORT),
    ],
)
def test_the_expected_reply_behind_a_malformed_frame_in_one_read_goes_the_receivers_way(
    malformed: bytes, reason: DiscardReason | None
) -> None:
    """The malformed frame armed the timer; the reply comes before it fires and finds the
    receiver mid-frame: the tap does not take it. The receiver closes the malformed frame
    first (a stream of whole frames ends a frame on no silence), then takes the reply, and
    the timer is cancelled: nothing comes later."""

    async def scenario(watched: _Watched) -> None:
        now = anyio.current_time()
        watched.one_read(malformed)
        assert watched.timer is not None
        assert watched.events == []
        watched.one_read(REPLY)
        assert watched.timer is None
        assert watched.taken == []
        *discards, received = watched.events
        assert isinstance(received, FrameReceived)
        assert (received.frame, received.end) == (REPLY, now)
        if reason is not None:
            assert [_discarded(event) for event in discards] == [(malformed, reason)]
        assert watched.link.frames_received == 1
        await anyio.sleep(1.0)
        assert len(watched.events) == len(discards) + 1  # nothing more
        # The tap was not used: it still waits (a master forgets it on the discard).
        assert watched.link._push_reader is not None
        assert watched.link._push_reader.reply_tap is watched.tap

    _on_a_virtual_clock(scenario)


@pytest.mark.parametrize(
    ("malformed", "reason"), [(BAD_CRC, DiscardReason.CRC), (HEAD, DiscardReason.CRC)]
)
def test_the_timer_ends_a_malformed_frame_and_the_tap_takes_the_reply_after_it(
    malformed: bytes, reason: DiscardReason | None
) -> None:
    """The malformed frame's timer fires at once (a loop turn, no time passing), ends it, and
    leaves an IDLE receiver with no timer: the reply after it goes to the tap, which takes it
    without an event and leaves no timer."""

    async def scenario(watched: _Watched) -> None:
        now = anyio.current_time()
        watched.one_read(malformed)
        assert watched.timer is not None
        for _ in range(3):
            await anyio.lowlevel.checkpoint()
        assert anyio.current_time() == now
        assert watched.timer is None
        assert len(watched.events) == 1
        if reason is not None:
            assert _discarded(watched.events[0]) == (malformed, reason)
        watched.one_read(REPLY)
        assert watched.taken == [(REPLY, now)]
        assert watched.timer is None
        assert len(watched.events) == 1
        assert watched.link.frames_received == 1
        await anyio.sleep(1.0)
        assert len(watched.events) == 1

    _on_a_virtual_clock(scenario)


def test_the_tap_takes_the_reply_on_an_idle_receiver_and_arms_no_timer() -> None:
    async def scenario(watched: _Watched) -> None:
        now = anyio.current_time()
        watched.one_read(REPLY)
        assert watched.taken == [(REPLY, now)]
        assert watched.timer is None
        watched.link.expect(watched.tap)
        watched.one_read(SHORT)  # a shorter frame of the same first bytes: the receiver's
        assert watched.timer is not None
        await anyio.sleep(1.0)
        assert watched.timer is None
        assert watched.taken == [(REPLY, now)]
        assert [type(event) for event in watched.events] == [FrameReceived]  # its CRC holds

    _on_a_virtual_clock(scenario)


@pytest.mark.parametrize(("whole", "reply_after"), [(True, False), (True, True), (False, False)])
def test_the_links_end_behind_a_malformed_frame_leaves_no_timer(
    whole: bool, reply_after: bool
) -> None:
    """The stream ends right behind a malformed frame, before its timer fires (and, as frames
    decoded from the same read may, the expected reply comes after the end, before the reader
    stops). The reader stops with its timer cancelled; `None` is the listener's last call,
    and nothing comes after it. (On a direct link the timer is due at once, and may fire
    before the reader stops; on a serial line's it is due after the frame silence.)"""

    async def scenario(watched: _Watched) -> None:
        await anyio.sleep(0.1)  # a serial line's receiver waits for silence first
        watched.one_read(BAD_CRC)
        watched.stream.end()
        if reply_after:
            watched.one_read(REPLY)  # the receiver is mid-frame: the receiver's way
            discard, received = watched.events
            assert _discarded(discard) == (BAD_CRC, DiscardReason.CRC)
            assert isinstance(received, FrameReceived)
            assert received.frame == REPLY
        before = list(watched.events)
        with anyio.fail_after(1.0):
            await watched.link.wait_closed()
        reader = watched.link._push_reader
        assert reader is not None
        assert reader.timer is None
        assert watched.taken == []
        assert watched.events[-1] is None
        assert watched.events[: len(before)] == before
        # Before the end, at most what the timer would have made of the malformed frame.
        assert [_discarded(event) for event in watched.events[len(before) : -1]] in (
            [],
            [(BAD_CRC, DiscardReason.CRC)],
        )
        count = len(watched.events)
        await anyio.sleep(1.0)
        assert len(watched.events) == count

    _on_a_virtual_clock(scenario, whole=whole)

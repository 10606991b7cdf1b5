"""A pushed stream of whole frames for the direct link's tests (tests/line/test_direct.py,
tests/master/test_direct_link_sequences.py), and what its reply tap relies on."""

from __future__ import annotations

import asyncio
from collections.abc import Callable

import anyio
import anyio.abc
import anyio.lowlevel

from aiortu.core.codes import MBAP_UNIT_IDS, UnitIds
from aiortu.line import Link


class PushedFrames(anyio.abc.ByteStream):
    """A push stream of whole frames, as a master's Modbus TCP stream is on asyncio (not
    `whole`: of chunks, as a serial line's is). What is sent is kept in `sent` and handed to
    `answer`; `push` hands a frame to the link's receiver, `end` ends the connection.

    `turn_at_end`: `receive()` lets the loop turn once before it raises, as `MbapPushStream`'s
    does, so a timer due at once fires before the link's reader stops; without it, the reader
    stops at once."""

    def __init__(
        self,
        answer: Callable[[bytes], None] | None = None,
        *,
        whole: bool = True,
        turn_at_end: bool = True,
    ) -> None:
        self.answer = answer
        self.whole = whole
        self.turn_at_end = turn_at_end
        self.sent: list[bytes] = []
        self.receiver: Callable[[bytes], None] | None = None
        self.on_lost: Callable[[], None] | None = None
        self.ended = asyncio.Event()  # the push path is asyncio's
        self._closed_here = False

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
        self.on_lost = on_lost if receiver is not None else None

    def push(self, frame: bytes) -> None:
        """One frame handed over, as from the stream's read callback."""
        assert self.receiver is not None
        self.receiver(frame)

    def end(self) -> None:
        """The connection ends (as a pushed stream tells it, from its callback)."""
        self.ended.set()
        if self.on_lost is not None:
            self.on_lost()

    def send_nowait(self, item: bytes) -> bool:
        if self.ended.is_set():
            return False
        self._take(item)
        return True

    async def send(self, item: bytes) -> None:
        if self.ended.is_set():
            raise anyio.BrokenResourceError
        self._take(item)

    def _take(self, item: bytes) -> None:
        self.sent.append(item)
        if self.answer is not None:
            self.answer(item)

    async def receive(self, max_bytes: int = 65536) -> bytes:
        if self.turn_at_end:
            await anyio.lowlevel.checkpoint()
        await self.ended.wait()
        raise anyio.ClosedResourceError if self._closed_here else anyio.EndOfStream

    async def send_eof(self) -> None:
        pass

    async def aclose(self) -> None:
        self._closed_here = True
        self.ended.set()


def silence_timer(link: Link) -> object:
    """The direct link's silence timer, where the receiver has one armed."""
    reader = link._push_reader
    assert reader is not None
    # What the reply tap relies on: a receiver with a deadline has its timer, and one
    # without has none (an IDLE receiver, the only one an expected frame is taken by).
    assert (reader.timer is None) == (link.receiver.next_deadline() is None)
    return reader.timer

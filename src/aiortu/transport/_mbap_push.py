"""What a master's pushed MBAP streams share: replies handed over from the event loop's
callback, requests written without a yield.

On asyncio a master's Modbus UDP, Modbus TCP and Modbus/TCP Security streams are asyncio
protocols rather than byte streams read by a task (see
[`PushDatagramStream`][aiortu.transport.PushDatagramStream] and
[`PushConnectionStream`][aiortu.transport.PushConnectionStream]). `PushedMbap` is their
common part: it matches each reply ADU to the transaction outstanding (`reply_frame`, as
[`ModbusTcpStream`][aiortu.transport.ModbusTcpStream] does), hands its RTU frame to the link's
receiver (the push extension, [`PushStream`][aiortu.transport.PushStream]) or keeps it for
`receive()`, and records how the stream ended. Each subclass says how a request is written.

A poll sends the same request again and again, and mostly gets the same reply: the last request
again reuses its ADU but for the transaction id (`next_adu`), and the last reply that came alone
(a datagram, or a chunk that was one whole ADU) again, byte for byte after its transaction id,
reuses the RTU frame made for it then, CRC and all (`repeated_reply`). Both give exactly what
the general route gives; the differential tests feed the same bytes both ways.
"""

from __future__ import annotations

import asyncio
from abc import abstractmethod
from collections import deque
from collections.abc import Callable
from typing import Any

import anyio
import anyio.abc
import anyio.lowlevel

from aiortu.core.codes import MBAP_UNIT_IDS, UnitIds
from aiortu.core.mbap import Adu
from aiortu.transport._mbap_stream import (
    NONE_OUTSTANDING,
    ModbusTcpCounters,
    reply_frame,
    reply_taken,
    request_adu,
    take_transaction_id,
)

__all__ = ("PushedMbap",)


class PushedMbap(anyio.abc.ByteStream):
    """The reply side of a pushed MBAP stream, and the request's transaction id (see the
    module docstring); `counters` count requests, replies and dropped ADUs, `where` names the
    server in log lines."""

    def __init__(self, counters: ModbusTcpCounters, where: str) -> None:
        self.counters = counters
        """Requests, replies and dropped (and, over UDP, refused and strangers') ADUs."""
        self.where = where
        self._outstanding = NONE_OUTSTANDING
        self._receiver: Callable[[bytes], None] | None = None
        self._on_lost: Callable[[], None] | None = None
        self._kept: deque[bytes] = deque()
        self._waiter: asyncio.Future[None] | None = None
        self._error: BaseException | None = None
        self._last_tail: bytes | None = None
        """The last reply taken that came alone, after its transaction id (`repeated_reply`)."""
        self._last_frame = b""
        """Its RTU frame."""
        self._last_request: bytes | None = None
        """The last request's RTU frame (`next_adu`)."""
        self._last_request_tail = b""
        """Its ADU, after the transaction id."""

    @property
    def whole_frames(self) -> bool:
        """True: each frame handed over is one whole RTU frame."""
        return True

    @property
    def unit_ids(self) -> UnitIds:
        """Any byte of the MBAP header, each a unit whose reply is awaited."""
        return MBAP_UNIT_IDS

    # -- receiving -------------------------------------------------------------------

    def hand_on(self, adu: Adu, alone: bytes | None = None) -> None:
        """Hand on the RTU frame of `adu` if it answers the request outstanding; drop it
        (counted) if not. `alone`: the bytes of `adu`, where they came by themselves (a
        datagram, a chunk that was this one ADU), for `repeated_reply` to know them again."""
        frame = reply_frame(self.counters, self._outstanding, adu)
        if frame is not None:
            if alone is not None:
                self._last_tail, self._last_frame = alone[2:], frame
            self.deliver(frame)

    def repeated_reply(self, data: bytes) -> bool:
        """Whether `data`, a whole ADU by itself, is the last reply that came alone again, byte
        for byte after its transaction id (a poll's usual reply): then it was checked and its
        RTU frame made the first time, and it is handed on with that frame, or dropped (counted)
        when its id is not the one outstanding, as `hand_on` would."""
        if data[2:] != self._last_tail:
            return False
        if reply_taken(self.counters, self._outstanding, (data[0] << 8) | data[1]):
            self.deliver(self._last_frame)
        return True

    def forget_replies(self) -> None:
        """Know no reply again (the stream broke: what comes after it is not a reply)."""
        self._last_tail = None

    def deliver(self, frame: bytes) -> None:
        """Hand on `frame`, the RTU frame of the reply to the request outstanding."""
        self._outstanding = NONE_OUTSTANDING  # one reply per request
        if self._receiver is not None:
            self._receiver(frame)
            return
        self._kept.append(frame)
        self._wake()

    def lost(self, error: BaseException) -> None:
        """The stream ended with `error` (what `receive()` raises from now on); the first
        one counts."""
        if self._error is None:
            self._error = error
        self._wake()
        if self._on_lost is not None:
            on_lost, self._on_lost = self._on_lost, None
            on_lost()

    def _wake(self) -> None:
        waiter = self._waiter
        if waiter is not None and not waiter.done():
            waiter.set_result(None)

    def set_receiver(
        self,
        receiver: Callable[[bytes], None] | None,
        on_lost: Callable[[], None] | None = None,
    ) -> None:
        """The push extension: hand each reply to `receiver` (None: keep them for
        `receive()`)."""
        self._receiver = receiver
        self._on_lost = on_lost if receiver is not None else None
        if receiver is None:
            return
        while self._kept:
            receiver(self._kept.popleft())
        if self._error is not None:
            self.lost(self._error)

    async def receive(self, max_bytes: int = 65536) -> bytes:
        """The next reply to the request outstanding, as an RTU frame."""
        await anyio.lowlevel.checkpoint()
        while not self._kept:
            if self._error is not None:
                raise self._error
            self._waiter = asyncio.get_running_loop().create_future()
            try:
                await self._waiter
            finally:
                self._waiter = None
        return self._kept.popleft()

    # -- sending ---------------------------------------------------------------------

    def next_adu(self, item: bytes) -> tuple[int, bytes]:
        """The transaction id and the ADU that carry the RTU frame `item`, the id taken and the
        request counted (as `request_adu`); the last request again reuses its ADU but for the
        id."""
        counters = self.counters
        if item == self._last_request:
            transaction_id = take_transaction_id(counters)
            return transaction_id, transaction_id.to_bytes(2, "big") + self._last_request_tail
        transaction_id, adu = request_adu(counters, item)
        self._last_request, self._last_request_tail = item, adu[2:]
        return transaction_id, adu

    def request(self, item: bytes) -> bytes:
        """The ADU that carries the RTU frame `item`, with the next transaction id, now the
        one outstanding: nothing that came before answers it."""
        transaction_id, adu = self.next_adu(item)
        self._outstanding = transaction_id
        self._kept.clear()
        return adu

    @abstractmethod
    def send_nowait(self, item: bytes) -> bool:
        """The push extension: send the RTU frame `item` now, if the stream can take it."""

    async def send(self, item: bytes) -> None:
        """Send the RTU frame `item` with the next transaction id."""
        await anyio.lowlevel.checkpoint()
        if not self.send_nowait(item):
            raise self._error or anyio.ClosedResourceError()

    @property
    def extra_attributes(self) -> Any:
        return {}

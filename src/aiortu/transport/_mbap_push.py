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
    request_adu,
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

    @property
    def whole_frames(self) -> bool:
        """True: each frame handed over is one whole RTU frame."""
        return True

    @property
    def unit_ids(self) -> UnitIds:
        """Any byte of the MBAP header, each a unit whose reply is awaited."""
        return MBAP_UNIT_IDS

    # -- receiving -------------------------------------------------------------------

    def hand_on(self, adu: Adu) -> None:
        """Hand on the RTU frame of `adu` if it answers the request outstanding; drop it
        (counted) if not."""
        frame = reply_frame(self.counters, self._outstanding, adu)
        if frame is not None:
            self.deliver(frame)

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

    def request(self, item: bytes) -> bytes:
        """The ADU that carries the RTU frame `item`, with the next transaction id, now the
        one outstanding: nothing that came before answers it."""
        transaction_id, adu = request_adu(self.counters, item)
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

"""Modbus ASCII on any byte stream: RTU frames in and out, ASCII frames on the wire.

The master, the slave and their engines speak RTU frames (unit, PDU, CRC). As
[`ModbusTcpStream`][aiortu.transport.ModbusTcpStream] does for MBAP,
[`AsciiStream`][aiortu.transport.AsciiStream] translates at the edge:

- each RTU frame written goes out as one ASCII frame (`:`, hex, LRC, CR and the delimiter), its
  CRC dropped;
- the bytes read go through the spec's ASCII receiver
  ([`AsciiReceiver`][aiortu.core.ascii.AsciiReceiver]); each frame whose LRC checks comes back
  from `receive()` as one RTU frame, its CRC computed, and everything else is discarded and
  counted by reason in [`discarded`][aiortu.transport.AsciiStream.discarded] (logged at debug
  level with its one-sentence reason).

Frames are told apart by their delimiters, so the stream hands over whole frames
([`whole_frames`][aiortu.transport.FramedStream]) and the [`Link`][aiortu.line.Link] keeps no
t3.5 silence; the receiver's inter-character timeout (`timeout`, 1 s by default) drops a frame
whose characters stop coming. Diagnostics 08/03 (change ASCII input delimiter) is honoured
where the framing sees it: a slave's stream takes the new delimiter once its reply has gone
out, and a master's stream ends its later requests to that unit with it once the reply has
come back.
"""

from __future__ import annotations

import logging
from collections import Counter, deque
from typing import Any, Final

import anyio
import anyio.abc
import anyio.lowlevel

from aiortu._log import get_logger
from aiortu.core.ascii import (
    DEFAULT_ASCII_TIMEOUT,
    LF,
    AsciiDiscardReason,
    AsciiFrameReceived,
    AsciiReceiver,
    encode_ascii_frame,
)
from aiortu.core.codes import SERIAL_UNIT_IDS, UnitIds
from aiortu.core.rtu import crc16
from aiortu.core.serial import LineSettings
from aiortu.errors import InvalidValue

__all__ = ("ASCII_BYTESIZE", "AsciiStream", "check_ascii_settings")

_log = get_logger(__name__)

ASCII_BYTESIZE: Final = 7
"""The spec's data bits for ASCII characters (7E1, or 7N2 without parity)."""

_CHANGE_DELIMITER: Final = b"\x08\x00\x03"
"""Diagnostics, sub-function 03: change ASCII input delimiter."""


def check_ascii_settings(port: str, settings: LineSettings) -> None:
    """Say, once, when a serial port opened for ASCII does not have the spec's 7 data bits
    (many devices are set up that way; the spec's are 7E1, or 7N2 without parity)."""
    if settings.bytesize != ASCII_BYTESIZE:
        _log.warning(
            "%s: Modbus ASCII characters have 7 data bits (7E1, or 7N2 without parity); "
            "opening with %d as asked (bytesize=7 for the spec's)",
            port,
            settings.bytesize,
        )


class AsciiStream(anyio.abc.ByteStream):
    """RTU frames over Modbus ASCII on `stream` (see the module docstring).

    `settings` give the receiver its character time, `timeout` is the inter-character
    timeout in seconds, and `delimiter` the character that ends frames after CR (LF).
    `answering` says which end this is for Diagnostics 08/03, whose request and reply look
    alike: a slave's (True; a [`Slave`][aiortu.slave.Slave] sets it) or a master's.
    """

    def __init__(
        self,
        stream: anyio.abc.ByteStream,
        settings: LineSettings | None = None,
        *,
        timeout: float = DEFAULT_ASCII_TIMEOUT,
        delimiter: int = LF,
        answering: bool = False,
    ) -> None:
        self.stream = stream
        self.answering = answering
        """Whether this end answers requests (a slave's) rather than sends them."""
        self.receiver = AsciiReceiver(settings, timeout=timeout, delimiter=delimiter)
        """The ASCII receiver; its `delimiter` ends the frames this end receives."""
        self.send_delimiters: dict[int, int] = {}
        """The delimiter that ends the frames sent to a unit whose own was changed by 08/03
        (LF for the others)."""
        self.frames_received = 0
        """Frames whose LRC checked, handed on."""
        self.discarded: Counter[AsciiDiscardReason] = Counter()
        """Characters that did not make a frame, counted by reason."""
        self._ready: deque[bytes] = deque()
        # The last frame received (unit, PDU, LRC) and its RTU frame.
        self._last_received = b""
        self._last_frame = b""
        # The last RTU frame sent, the delimiter it went with, and its ASCII frame.
        self._sent_item = b""
        self._sent_delimiter = LF
        self._sent_frame = b""

    @property
    def whole_frames(self) -> bool:
        """True: each `receive()` returns exactly one RTU frame."""
        return True

    @property
    def unit_ids(self) -> UnitIds:
        """A serial line's: 1..247, and 0 the broadcast."""
        return SERIAL_UNIT_IDS

    @property
    def extra_attributes(self) -> Any:
        return self.stream.extra_attributes

    async def send(self, item: bytes) -> None:
        """Send the RTU frame `item` (unit, PDU, CRC) as one ASCII frame."""
        await self.stream.send(self.encode(item))
        self.sent(item)

    def encode(self, item: bytes) -> bytes:
        """The ASCII frame that carries the RTU frame `item` (unit, PDU, CRC) to its unit."""
        if len(item) < 4:
            raise InvalidValue("len(item)", len(item), "at least 4 (unit, PDU and CRC)")
        unit = item[0]
        delimiter = self.send_delimiters.get(unit, LF)
        if item == self._sent_item and delimiter == self._sent_delimiter:
            return self._sent_frame  # the same frame again: a poll's request, a store's reply
        frame = encode_ascii_frame(unit, item[1:-2], delimiter)
        self._sent_item, self._sent_delimiter, self._sent_frame = bytes(item), delimiter, frame
        return frame

    def sent(self, item: bytes) -> None:
        """The RTU frame `item` has gone out: a slave's reply to 08/03 changes the delimiter
        that ends the frames it receives from now on."""
        if self.answering and item[1:4] == _CHANGE_DELIMITER and len(item) >= 7:
            self.receiver.delimiter = item[4]

    async def receive(self, max_bytes: int = 65536) -> bytes:
        """The next frame received, as an RTU frame (`max_bytes` is ignored: a frame is never
        split)."""
        await anyio.lowlevel.checkpoint()
        receiver = self.receiver
        while not self._ready:
            deadline = receiver.next_deadline()
            if deadline is None:
                data = await self.stream.receive()
            else:
                with anyio.move_on_after(max(deadline - anyio.current_time(), 0) + 0.001):
                    data = await self.stream.receive()
                    self._take(receiver.feed(data, anyio.current_time()))
                    continue
                self._take(receiver.expire(anyio.current_time()))
                continue
            self._take(receiver.feed(data, anyio.current_time()))
        return self._ready.popleft()

    def _take(self, outputs: list[Any]) -> None:
        self._ready.extend(self.frames(outputs))

    def frames(self, outputs: list[Any]) -> list[bytes]:
        """The RTU frames (CRC computed) of the frames among the receiver's `outputs`; the rest
        counted in [`discarded`][aiortu.transport.AsciiStream.discarded] by reason. A unit's reply
        to 08/03 ends our later requests to it with its new delimiter."""
        frames = []
        for out in outputs:
            if type(out) is AsciiFrameReceived:
                self.frames_received += 1
                received = out.frame  # unit, PDU and LRC
                if received == self._last_received:
                    frame = self._last_frame  # a poll's unchanged reply: its CRC is known
                else:
                    body = received[:-1]
                    crc = crc16(body)
                    frame = self._last_frame = body + bytes((crc & 0xFF, crc >> 8))
                    self._last_received = received
                frames.append(frame)
                if (
                    received.startswith(_CHANGE_DELIMITER, 1)
                    and len(received) >= 6  # the new delimiter, then the LRC
                    and not self.answering
                ):
                    self.send_delimiters[received[0]] = received[4]
            else:
                self.discarded[out.reason] += 1
                if _log.isEnabledFor(logging.DEBUG):
                    _log.debug("ASCII: dropped %r: %s", out.data[:40], out.detail)
        return frames

    async def send_eof(self) -> None:
        await self.stream.send_eof()

    async def aclose(self) -> None:
        await self.stream.aclose()

"""How a server connection's bytes become requests, and replies bytes: Modbus TCP, RTU over
TCP or ASCII over TCP (the server framings, one home for all).

- **Modbus TCP** (`tcp://`): MBAP headers; a reply carries the request's transaction id and
  unit id. A malformed header ends the connection (nothing marks where the next ADU starts).
- **RTU over TCP** (`rtu+tcp://`): RTU frames (unit, PDU, CRC) as a serial device server
  sends them. A frame's length comes from its function code; a frame whose length the code
  does not tell (a user-defined code) ends after `RTU_SILENCE` seconds without bytes. After
  noise (bytes that do not make a frame whose CRC checks) the framing resynchronises: the
  core's [`FrameSearch`][aiortu.core.rtu.FrameSearch] finds where the next valid request
  starts in the bytes held, and what comes before it is dropped (counted in `discarded`); a
  silence frames everything held. The buffer never holds more than `MAX_FRAME_LENGTH` (256)
  bytes between reads: a client that streams a code of unknown length without a pause has
  the bytes dropped, so it holds at most 256 bytes and one read. The gateway and the slave's
  RTU-over-TCP server both use it.
  RTU frames carry no transaction id, so such a connection has one request at a time and
  its replies keep the order of its requests.
"""

from __future__ import annotations

import time
from typing import Final, Protocol

from aiortu.core.ascii import (
    DEFAULT_ASCII_TIMEOUT,
    AsciiFrameDiscarded,
    AsciiFrameReceived,
    AsciiReceiver,
    encode_ascii_frame,
)
from aiortu.core.errors import FrameError
from aiortu.core.mbap import Adu, AduDecoder, encode_adu
from aiortu.core.rtu import (
    CANNOT_KNOW,
    MAX_FRAME_LENGTH,
    MIN_FRAME_LENGTH,
    NEED_MORE,
    FrameSearch,
    decode_frame,
    encode_frame,
    expected_request_length,
)

__all__ = ("RTU_SILENCE", "AsciiFraming", "Framing", "MbapFraming", "RtuFraming")

RTU_SILENCE: Final = 0.02
"""Seconds without bytes that end an RTU frame of unknown length (as a tolerant receiver)."""


class Framing(Protocol):
    """Splits one connection's bytes into requests and encodes its replies."""

    in_order: bool
    """Whether replies must keep the order of the requests (no transaction ids)."""
    discarded: int
    """Frames dropped (bad CRC, wrong length)."""

    @property
    def buffered(self) -> int:
        """Bytes held for a frame not complete yet."""
        ...

    def feed(self, data: bytes) -> list[Adu]:
        """The requests the bytes so far complete (`MalformedHeader` ends the connection)."""
        ...

    def waiting_for_silence(self) -> bool:
        """Whether buffered bytes make a frame that only a silence can end."""
        ...

    def silence(self) -> list[Adu]:
        """The requests a silence completes (the buffered frame, if it checks)."""
        ...

    def encode(self, request: Adu, pdu: bytes) -> bytes:
        """The reply to `request` with `pdu`."""
        ...


class MbapFraming:
    """Modbus TCP: see the module docstring."""

    in_order = False

    def __init__(self) -> None:
        self.discarded = 0
        self._decoder = AduDecoder()

    @property
    def buffered(self) -> int:
        return self._decoder.buffered

    def feed(self, data: bytes) -> list[Adu]:
        return self._decoder.feed(data)

    def waiting_for_silence(self) -> bool:
        return False

    def silence(self) -> list[Adu]:
        return []

    def encode(self, request: Adu, pdu: bytes) -> bytes:
        return encode_adu(request.transaction_id, request.unit, pdu)


class RtuFraming:
    """RTU frames over TCP: see the module docstring."""

    in_order = True

    def __init__(self) -> None:
        self.discarded = 0
        self._buffer = bytearray()
        self._search: FrameSearch | None = None  # made at the first noise

    @property
    def buffered(self) -> int:
        return len(self._buffer)

    def feed(self, data: bytes) -> list[Adu]:
        self._buffer += data
        requests: list[Adu] = []
        while True:
            self._take(requests)
            if len(self._buffer) <= MAX_FRAME_LENGTH:
                return requests
            if not self._resynchronise():  # more than a frame, none in it: noise
                return requests

    def _take(self, requests: list[Adu]) -> None:
        """Move the complete requests at the buffer's start to `requests`, resynchronising
        after noise."""
        buffer = self._buffer
        while len(buffer) >= 2:
            length = expected_request_length(buffer)
            if length in (NEED_MORE, CANNOT_KNOW) or length > len(buffer):
                return
            request = self._checked(bytes(buffer[:length]))
            if request is None:
                if not self._resynchronise():
                    return
                continue
            del buffer[:length]
            requests.append(request)

    def waiting_for_silence(self) -> bool:
        return bool(self._buffer)

    def silence(self) -> list[Adu]:
        requests: list[Adu] = []
        while self._buffer:
            frame = bytes(self._buffer)
            request = self._checked(frame) if len(frame) >= MIN_FRAME_LENGTH else None
            if request is not None:
                self._buffer.clear()
                requests.append(request)
            elif self._resynchronise():  # noise, then what may be frames: frame them
                requests += self.feed(b"")
        return requests

    def _resynchronise(self) -> bool:
        """Drop the buffer's bytes up to the next offset where a valid request starts, or may
        start once more bytes come; False when there is none (the buffer is noise, dropped)."""
        buffer = self._buffer
        search = self._search
        if search is None:
            search = self._search = FrameSearch(range(256), requests=True, replies=False)
        search.forget()
        self.discarded += 1
        start = next(
            (
                offset
                for offset in search.offsets(buffer, len(buffer) - 2)
                if offset and search.frame_at(buffer, offset) != CANNOT_KNOW  # maybe a frame
            ),
            None,
        )
        if start is None:
            buffer.clear()
            return False
        del buffer[:start]
        return True

    def encode(self, request: Adu, pdu: bytes) -> bytes:
        return encode_frame(request.unit, pdu)

    @staticmethod
    def _checked(frame: bytes) -> Adu | None:
        try:
            checked = decode_frame(frame)
        except FrameError:
            return None
        return Adu(0, checked.unit, checked.pdu)


class AsciiFraming:
    """Modbus ASCII frames over TCP (':' to CR LF, checked by their LRC), told apart by their
    delimiters: the core's [`AsciiReceiver`][aiortu.core.ascii.AsciiReceiver], with `timeout`
    the longest gap between two characters of a frame. Like RTU frames they carry no
    transaction id: one request at a time, replies in order."""

    in_order = True

    def __init__(self, timeout: float = DEFAULT_ASCII_TIMEOUT) -> None:
        self.discarded = 0
        self._receiver = AsciiReceiver(timeout=timeout)

    @property
    def buffered(self) -> int:
        return 0  # the receiver holds at most one frame, bounded by the spec's length

    def feed(self, data: bytes) -> list[Adu]:
        requests = []
        for output in self._receiver.feed(data, time.monotonic()):
            if isinstance(output, AsciiFrameReceived):
                requests.append(Adu(0, output.unit, output.pdu))
            elif isinstance(output, AsciiFrameDiscarded):
                self.discarded += 1
        return requests

    def waiting_for_silence(self) -> bool:
        return False

    def silence(self) -> list[Adu]:
        return []

    def encode(self, request: Adu, pdu: bytes) -> bytes:
        return encode_ascii_frame(request.unit, pdu)

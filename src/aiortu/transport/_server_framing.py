"""How a server connection's bytes become requests, and replies bytes: Modbus TCP or RTU over
TCP (the gateway's framings, one home for both).

- **Modbus TCP** (`tcp://`): MBAP headers; a reply carries the request's transaction id and
  unit id. A malformed header ends the connection (nothing marks where the next ADU starts).
- **RTU over TCP** (`rtu+tcp://`): RTU frames (unit, PDU, CRC) as a serial device server
  sends them. A frame's length comes from its function code; a frame whose length the code
  does not tell (a user-defined code) ends after `RTU_SILENCE` seconds without bytes. A frame
  with a bad CRC is dropped with whatever follows it in the buffer, as a slave drops noise.
  The buffer never holds more than `MAX_FRAME_LENGTH` (256) bytes between reads: a client
  that streams a code of unknown length without a pause has the bytes dropped (counted in
  `discarded`), so it holds at most 256 bytes and one read.
  RTU frames carry no transaction id, so such a connection has one request at a time and
  its replies keep the order of its requests.
"""

from __future__ import annotations

from typing import Final, Protocol

from aiortu.core.errors import FrameError
from aiortu.core.mbap import Adu, AduDecoder, encode_adu
from aiortu.core.rtu import (
    CANNOT_KNOW,
    MAX_FRAME_LENGTH,
    MIN_FRAME_LENGTH,
    NEED_MORE,
    decode_frame,
    encode_frame,
    expected_request_length,
)

__all__ = ("RTU_SILENCE", "Framing", "MbapFraming", "RtuFraming")

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

    @property
    def buffered(self) -> int:
        return len(self._buffer)

    def feed(self, data: bytes) -> list[Adu]:
        self._buffer += data
        requests: list[Adu] = []
        while len(self._buffer) >= 2:
            length = expected_request_length(self._buffer)
            if length in (NEED_MORE, CANNOT_KNOW) or length > len(self._buffer):
                break
            frame = bytes(self._buffer[:length])
            del self._buffer[:length]
            request = self._checked(frame)
            if request is None:
                self._buffer.clear()  # noise: what follows cannot be trusted either
                break
            requests.append(request)
        if len(self._buffer) > MAX_FRAME_LENGTH:
            self.discarded += 1
            self._buffer.clear()
        return requests

    def waiting_for_silence(self) -> bool:
        return bool(self._buffer)

    def silence(self) -> list[Adu]:
        frame = bytes(self._buffer)
        self._buffer.clear()
        if len(frame) < MIN_FRAME_LENGTH:
            self.discarded += 1
            return []
        request = self._checked(frame)
        return [] if request is None else [request]

    def encode(self, request: Adu, pdu: bytes) -> bytes:
        return encode_frame(request.unit, pdu)

    def _checked(self, frame: bytes) -> Adu | None:
        try:
            checked = decode_frame(frame)
        except FrameError:
            self.discarded += 1
            return None
        return Adu(0, checked.unit, checked.pdu)

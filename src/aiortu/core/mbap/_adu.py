"""Modbus TCP framing: the MBAP header in front of a PDU, and a stream decoder.

A Modbus TCP ADU is a 7-byte MBAP header followed by the PDU, at most 260 bytes in all:

    transaction id (2)  protocol id (2, always 0)  length (2)  unit id (1)  PDU (1..253)

`length` counts the bytes that follow it: the unit id and the PDU, so 2..254. Every
field is big-endian. There is no CRC: TCP already checks the bytes, and the length field
alone says where an ADU ends. That is also why a stream cannot be resynchronised after a
header that breaks these rules: nothing marks where the next ADU starts, so the decoder
refuses every later byte and the connection must be closed (the spec's advice).

`encode_adu` and `decode_adu` build and check whole ADUs;
`AduDecoder` takes a byte stream in any split, pipelined ADUs included.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Final

from aiortu.core.errors import FrameError, InvalidValue

__all__ = (
    "HEADER_LENGTH",
    "MAX_ADU_LENGTH",
    "MAX_PDU_LENGTH",
    "Adu",
    "AduDecoder",
    "MalformedHeader",
    "decode_adu",
    "encode_adu",
)

HEADER_LENGTH: Final = 7
"""Transaction id, protocol id, length and unit id."""

MAX_ADU_LENGTH: Final = 260
"""The longest Modbus TCP ADU the spec allows: the header and a 253-byte PDU."""

MAX_PDU_LENGTH: Final = MAX_ADU_LENGTH - HEADER_LENGTH
"""The longest PDU, the same as over a serial line."""

_LENGTH_RANGE = range(2, MAX_PDU_LENGTH + 2)
"""What the length field may say: the unit id and a PDU of 1..253 bytes."""

_WORD_RANGE = range(0x10000)
_UNIT_RANGE = range(0x100)
_PDU_RANGE = range(1, MAX_PDU_LENGTH + 1)


class MalformedHeader(FrameError):
    """An MBAP header that breaks the spec: a protocol id other than 0, or a length
    field outside 2..254. Caused by the peer; the stream cannot go on after it."""

    reason = "header"


@dataclass(frozen=True, slots=True)
class Adu:
    """A checked Modbus TCP ADU split into its fields (the protocol id is always 0)."""

    transaction_id: int
    unit: int
    pdu: bytes

    def encode(self) -> bytes:
        """The ADU's bytes (see `encode_adu`)."""
        return encode_adu(self.transaction_id, self.unit, self.pdu)


def encode_adu(transaction_id: int, unit: int, pdu: bytes) -> bytes:
    """Build the ADU `MBAP header + pdu`.

    `transaction_id` is 0..65535, `unit` 0..255, `pdu` 1..253 bytes. Raises
    [`InvalidValue`][aiortu.errors.InvalidValue].
    """
    if transaction_id not in _WORD_RANGE:
        raise InvalidValue("transaction_id", transaction_id, _WORD_RANGE)
    if unit not in _UNIT_RANGE:
        raise InvalidValue("unit", unit, _UNIT_RANGE)
    if len(pdu) not in _PDU_RANGE:
        raise InvalidValue("len(pdu)", len(pdu), _PDU_RANGE)
    length = len(pdu) + 1
    header = bytes(
        (transaction_id >> 8, transaction_id & 0xFF, 0, 0, length >> 8, length & 0xFF, unit)
    )
    return header + pdu


def _check_header(header: bytes | bytearray) -> int:
    """The length field of a 7-byte header (or more), after checking the header."""
    protocol = (header[2] << 8) | header[3]
    if protocol != 0:
        raise MalformedHeader(f"MBAP protocol id is {protocol}, not 0 (Modbus)")
    length = (header[4] << 8) | header[5]
    if length not in _LENGTH_RANGE:
        raise MalformedHeader(
            f"MBAP length field is {length}; it must be 2..{_LENGTH_RANGE.stop - 1} "
            "(the unit id and a PDU of 1..253 bytes)"
        )
    return length


def _split(adu: bytes | bytearray, length: int) -> Adu:
    end = HEADER_LENGTH - 1 + length
    return Adu((adu[0] << 8) | adu[1], adu[6], bytes(adu[HEADER_LENGTH:end]))


def decode_adu(adu: bytes) -> Adu:
    """Check a whole ADU and split it.

    Raises `MalformedHeader` for a protocol id other than 0 or a length field
    outside 2..254, and [`FrameError`][aiortu.errors.FrameError] (reason `"length"`) when the
    bytes given are not exactly as long as the length field says.
    """
    if len(adu) < HEADER_LENGTH + 1:
        raise FrameError(
            f"an MBAP ADU has at least {HEADER_LENGTH + 1} bytes, not {len(adu)}",
            reason="length",
        )
    length = _check_header(adu)
    if len(adu) != HEADER_LENGTH - 1 + length:
        raise FrameError(
            f"the MBAP length field says {length} bytes follow it, "
            f"but {len(adu) - HEADER_LENGTH + 1} do",
            reason="length",
        )
    return _split(adu, length)


class AduDecoder:
    """Splits a byte stream into ADUs, whatever the chunks: one ADU in many pieces,
    many ADUs in one piece, or both.

    `feed` returns the ADUs that the bytes so far complete. A header that breaks
    the spec raises `MalformedHeader`, and so does every later call: the length
    field is the only marker of where an ADU ends, so the stream is lost and the
    connection must be closed; ADUs that came before it in the same chunk are dropped
    with it. At most `MAX_ADU_LENGTH` - 1 bytes are kept between calls.
    """

    def __init__(self) -> None:
        self._buffer = bytearray()
        self._broken: MalformedHeader | None = None

    @property
    def buffered(self) -> int:
        """Bytes received that do not yet make a whole ADU."""
        return len(self._buffer)

    @property
    def broken(self) -> bool:
        """Whether a malformed header ended the stream."""
        return self._broken is not None

    def feed(self, data: bytes | bytearray | memoryview) -> list[Adu]:
        """Take the next bytes of the stream; return the ADUs they complete, in order."""
        if self._broken is not None:
            raise MalformedHeader(str(self._broken))
        buffer = self._buffer
        buffer += data
        adus: list[Adu] = []
        start = 0
        while len(buffer) - start >= HEADER_LENGTH:
            try:
                length = _check_header(buffer[start : start + HEADER_LENGTH])
            except MalformedHeader as error:
                self._broken = error
                del buffer[:]
                raise
            end = start + HEADER_LENGTH - 1 + length
            if end > len(buffer):
                break
            adus.append(_split(buffer[start:end], length))
            start = end
        del buffer[:start]
        return adus

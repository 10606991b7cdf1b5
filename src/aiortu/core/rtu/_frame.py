"""RTU frames: unit address, PDU and CRC, and the length of a frame from its first bytes.

An RTU frame (the spec's ADU) is `unit + PDU + CRC`, 4 to 256 bytes, the CRC sent low byte first.
[`encode_frame`][aiortu.core.rtu.encode_frame] and
[`decode_frame`][aiortu.core.rtu.decode_frame] build and check whole frames.

The receiver does not have to wait for t3.5 of silence to know that a frame has ended: for every
public function code the length follows from at most the first few bytes (the function code and, for
variable-length PDUs, a byte count). The predictors here answer, for the bytes received so far,
either the total frame length, [`NEED_MORE`][aiortu.core.rtu.NEED_MORE] (a few more bytes will
tell), or [`CANNOT_KNOW`][aiortu.core.rtu.CANNOT_KNOW] (a custom function code, or bytes that
break the layout). A request and a reply with the same function code usually have different layouts,
so there is one predictor for each direction.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Final

from aiortu.core.codes import EXCEPTION_BIT, MEI_READ_DEVICE_IDENTIFICATION, FunctionCode
from aiortu.core.errors import CRCError, InvalidValue, MalformedPDU
from aiortu.core.rtu._crc import crc16

__all__ = (
    "CANNOT_KNOW",
    "MAX_FRAME_LENGTH",
    "MIN_FRAME_LENGTH",
    "NEED_MORE",
    "Frame",
    "decode_frame",
    "encode_frame",
    "expected_request_length",
    "expected_response_length",
)

MIN_FRAME_LENGTH: Final = 4
"""Unit, function code and CRC: the shortest frame (e.g. read exception status)."""

MAX_FRAME_LENGTH: Final = 256
"""The longest RTU frame the spec allows."""

NEED_MORE: Final = 0
"""Prediction: the bytes so far do not tell the length yet; more will."""

CANNOT_KNOW: Final = -1
"""Prediction: the length cannot be known from the content; only silence ends the frame."""

_UNIT_RANGE = range(256)


@dataclass(frozen=True, slots=True)
class Frame:
    """A checked RTU frame split into its unit address and its PDU (CRC removed)."""

    unit: int
    pdu: bytes


def encode_frame(unit: int, pdu: bytes) -> bytes:
    """Build the frame `unit + pdu + CRC` (CRC low byte first).

    `unit` may be any byte (0 is broadcast, 248..255 are reserved but some devices use
    them); `pdu` must be 1..253 bytes. Raises [`InvalidValue`][aiortu.errors.InvalidValue].
    """
    if unit not in _UNIT_RANGE:
        raise InvalidValue("unit", unit, _UNIT_RANGE)
    if not 1 <= len(pdu) <= MAX_FRAME_LENGTH - 3:
        raise InvalidValue("len(pdu)", len(pdu), range(1, MAX_FRAME_LENGTH - 2))
    body = bytes((unit,)) + pdu
    crc = crc16(body)
    return body + bytes((crc & 0xFF, crc >> 8))


def decode_frame(frame: bytes) -> Frame:
    """Check the length and the CRC of a whole frame and split it.

    Raises [`MalformedPDU`][aiortu.errors.MalformedPDU] for a length outside 4..256 and
    [`CRCError`][aiortu.errors.CRCError] when the CRC does not match.
    """
    length = len(frame)
    if not MIN_FRAME_LENGTH <= length <= MAX_FRAME_LENGTH:
        raise MalformedPDU(
            "frame length",
            field="length",
            value=length,
            allowed=range(MIN_FRAME_LENGTH, MAX_FRAME_LENGTH + 1),
        )
    received = frame[-2] | frame[-1] << 8
    computed = crc16(frame[:-2])
    if received != computed:
        raise CRCError(received, computed)
    return Frame(frame[0], bytes(frame[1:-2]))


@dataclass(frozen=True, slots=True)
class _Counted:
    """A frame whose total length (unit and CRC included) is `base` plus the count in its
    `width` bytes (big-endian) at `offset`."""

    offset: int
    base: int
    width: int = 1


# A function code's frame length: an int when it is always that many bytes, a count otherwise.
# 2B (MEI) is in neither table: its length depends on the MEI type (see _predict_mei).
_Layout = int | _Counted
_ENCAPSULATED: Final = int(FunctionCode.ENCAPSULATED_INTERFACE_TRANSPORT)
_BYTE_COUNT_AT_2 = _Counted(2, 5)

_REQUEST_LAYOUTS: dict[int, _Layout] = {
    0x01: 8,
    0x02: 8,
    0x03: 8,
    0x04: 8,
    0x05: 8,
    0x06: 8,
    0x07: 4,
    # 08 sub-function 00 may echo any even amount of data; 8 bytes is every other
    # sub-function and the usual query, and a wrong guess only costs waiting for silence.
    0x08: 8,
    0x0B: 4,
    0x0C: 4,
    0x0F: _Counted(6, 9),
    0x10: _Counted(6, 9),
    0x11: 4,
    0x14: _BYTE_COUNT_AT_2,
    0x15: _BYTE_COUNT_AT_2,
    0x16: 10,
    0x17: _Counted(10, 13),
    0x18: 6,
}

_RESPONSE_LAYOUTS: dict[int, _Layout] = {
    0x01: _BYTE_COUNT_AT_2,
    0x02: _BYTE_COUNT_AT_2,
    0x03: _BYTE_COUNT_AT_2,
    0x04: _BYTE_COUNT_AT_2,
    0x05: 8,
    0x06: 8,
    0x07: 5,
    0x08: 8,
    0x0B: 8,
    0x0C: _BYTE_COUNT_AT_2,
    0x0F: 8,
    0x10: 8,
    0x11: _BYTE_COUNT_AT_2,
    0x14: _BYTE_COUNT_AT_2,
    0x15: _BYTE_COUNT_AT_2,
    0x16: 10,
    0x17: _BYTE_COUNT_AT_2,
    0x18: _Counted(2, 6, width=2),
}


def _predict(frame: bytes | bytearray, layouts: dict[int, _Layout], reply: bool) -> int:
    have = len(frame)
    if have < 2:
        return NEED_MORE
    function_code = frame[1]
    if function_code & EXCEPTION_BIT:
        # A request never has the top bit set; a reply with it is an exception: 5 bytes.
        return 5 if reply else CANNOT_KNOW
    layout = layouts.get(function_code)
    if type(layout) is int:
        return layout
    if isinstance(layout, _Counted):
        at = layout.offset
        if have < at + layout.width:
            return NEED_MORE
        total = layout.base + (frame[at] if layout.width == 1 else frame[at] << 8 | frame[at + 1])
        return total if total <= MAX_FRAME_LENGTH else CANNOT_KNOW
    return _predict_mei(frame, reply) if function_code == _ENCAPSULATED else CANNOT_KNOW


def _predict_mei(frame: bytes | bytearray, reply: bool) -> int:
    have = len(frame)
    if have < 3:
        return NEED_MORE
    if frame[2] != MEI_READ_DEVICE_IDENTIFICATION:
        return CANNOT_KNOW
    if not reply:
        return 7  # unit, 2B, 0E, read code, object id, CRC
    # unit 2B 0E code conformity more next count, then per object: id, length, value.
    if have < 8:
        return NEED_MORE
    position = 8
    for _ in range(frame[7]):
        if have < position + 2:
            return NEED_MORE
        position += 2 + frame[position + 1]
        if position + 2 > MAX_FRAME_LENGTH:
            return CANNOT_KNOW
    return position + 2


def expected_request_length(frame: bytes | bytearray) -> int:
    """The total length of the request frame that starts with `frame`.

    Returns the length in bytes (unit and CRC included), [`NEED_MORE`][aiortu.core.rtu.NEED_MORE],
    or [`CANNOT_KNOW`][aiortu.core.rtu.CANNOT_KNOW] for function codes without a known layout.

    >>> expected_request_length(bytes.fromhex("11 03 00"))
    8
    """
    return _predict(frame, _REQUEST_LAYOUTS, reply=False)


def expected_response_length(frame: bytes | bytearray) -> int:
    """The total length of the reply frame that starts with `frame`.

    Returns the length in bytes (unit and CRC included), [`NEED_MORE`][aiortu.core.rtu.NEED_MORE],
    or [`CANNOT_KNOW`][aiortu.core.rtu.CANNOT_KNOW] for function codes without a known layout.

    >>> expected_response_length(bytes.fromhex("11 03 06"))
    11
    """
    return _predict(frame, _RESPONSE_LAYOUTS, reply=True)

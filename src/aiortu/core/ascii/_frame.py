"""ASCII frames: ':' + two hex characters per byte (unit, PDU, LRC) + CR LF.

A frame is at most 513 characters (the spec's bound: 255 bytes of unit, PDU and LRC) and at
least 9 (unit, function code and LRC). Receivers must accept lower-case hex digits; this
module sends upper case, as the spec does. Anything else (an odd number of hex characters, a
character that is not a hex digit, a frame too short or too long, a missing ':' or end) is
refused with a one-sentence [`FrameError`][aiortu.errors.FrameError], and a frame whose LRC
does not check with an [`LRCError`][aiortu.errors.LRCError]. Nothing here ever hands hex text
to a parser that would skip spaces or read a partial byte.

    >>> encode_ascii_frame(1, bytes.fromhex("03 00 00 00 01"))
    b':010300000001FB\\r\\n'
"""

from __future__ import annotations

import re
from typing import Final

from aiortu.core.ascii._lrc import lrc
from aiortu.core.errors import FrameError, InvalidValue, LRCError
from aiortu.core.rtu import Frame

__all__ = (
    "ASCII_START",
    "CR",
    "LF",
    "MAX_ASCII_FRAME_LENGTH",
    "MIN_ASCII_FRAME_LENGTH",
    "check_ascii_body",
    "decode_ascii_frame",
    "encode_ascii_frame",
)

ASCII_START: Final = 0x3A
"""':', which starts every frame."""

CR: Final = 0x0D
"""The first end character."""

LF: Final = 0x0A
"""The second end character, unless Diagnostics 08/03 changed it."""

MAX_ASCII_FRAME_LENGTH: Final = 513
"""The longest frame in characters, start and end included."""

MIN_ASCII_FRAME_LENGTH: Final = 9
"""':', unit, function code, LRC, CR LF."""

_MAX_BODY: Final = MAX_ASCII_FRAME_LENGTH - 3
_MIN_BODY: Final = MIN_ASCII_FRAME_LENGTH - 3
_MAX_PDU: Final = _MAX_BODY // 2 - 2
_HEX_PAIRS: Final = re.compile(rb"(?:[0-9A-Fa-f]{2})*")
_UNIT_RANGE = range(256)


def encode_ascii_frame(unit: int, pdu: bytes, delimiter: int = LF) -> bytes:
    """Build the frame `':' + hex(unit + pdu + LRC) + CR + delimiter` in upper case.

    `pdu` must be 1..253 bytes; `delimiter` is LF unless the device's was changed with
    Diagnostics 08/03. Raises [`InvalidValue`][aiortu.errors.InvalidValue].
    """
    if unit not in _UNIT_RANGE:
        raise InvalidValue("unit", unit, _UNIT_RANGE)
    if not 1 <= len(pdu) <= _MAX_PDU:
        raise InvalidValue("len(pdu)", len(pdu), range(1, _MAX_PDU + 1))
    if delimiter not in _UNIT_RANGE or delimiter == ASCII_START:
        raise InvalidValue("delimiter", delimiter, "a byte other than ':'")
    body = bytes((unit,)) + pdu
    body += bytes((lrc(body),))
    return b":" + body.hex().upper().encode("ascii") + bytes((CR, delimiter))


def check_ascii_body(body: bytes | bytearray) -> bytes:
    """The bytes (unit, PDU and LRC) that the hex characters `body` spell, LRC checked.

    `body` is what lies between ':' and CR. Raises [`FrameError`][aiortu.errors.FrameError]
    (reason `"ascii"`) for malformed text and [`LRCError`][aiortu.errors.LRCError].
    """
    length = len(body)
    if length < _MIN_BODY or length > _MAX_BODY:
        raise FrameError(
            f"an ASCII frame holds {_MIN_BODY}..{_MAX_BODY} hex characters between ':' and "
            f"CR, not {length}",
            reason="ascii",
        )
    if length % 2:
        raise FrameError(
            f"an ASCII frame holds an even number of hex characters, not {length}",
            reason="ascii",
        )
    try:
        # fromhex skips whitespace between pairs and refuses every other non-hex character:
        # a text of hex digits only is exactly the one that gives length / 2 bytes.
        data = bytes.fromhex(body.decode("ascii"))
    except ValueError:  # UnicodeDecodeError included
        data = b""
    if 2 * len(data) != length:
        matched = _HEX_PAIRS.match(body)
        end = matched.end() if matched is not None else 0
        raise FrameError(
            f"an ASCII frame holds hex digits only, not {bytes(body[end : end + 1])!r} "
            f"at character {end + 1}",
            reason="ascii",
        )
    if sum(data) & 0xFF:
        raise LRCError(data[-1], lrc(data[:-1]))
    return data


def decode_ascii_frame(frame: bytes | bytearray, delimiter: int = LF) -> Frame:
    """Check a whole frame (':' to the delimiter) and split it into unit and PDU.

    Raises [`FrameError`][aiortu.errors.FrameError] (reason `"ascii"`) when it is malformed
    and [`LRCError`][aiortu.errors.LRCError] when its LRC does not check.
    """
    length = len(frame)
    if length > MAX_ASCII_FRAME_LENGTH:
        raise FrameError(
            f"an ASCII frame is at most {MAX_ASCII_FRAME_LENGTH} characters, not {length}",
            reason="ascii",
        )
    if length < 3 or frame[0] != ASCII_START:
        raise FrameError("an ASCII frame starts with ':'", reason="ascii")
    if frame[-2] != CR or frame[-1] != delimiter:
        raise FrameError(
            f"an ASCII frame ends with CR and 0x{delimiter:02X}, not {bytes(frame[-2:])!r}",
            reason="ascii",
        )
    data = check_ascii_body(frame[1:-2])
    return Frame(data[0], data[1:-1])

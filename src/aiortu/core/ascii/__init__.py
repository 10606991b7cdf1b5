"""Modbus ASCII framing: the LRC, the frame, and the ASCII receiver's state machine.

The serial line spec's second framing (2.5.2): each byte travels as two hexadecimal
characters between ':' and CR LF, checked by an LRC instead of a CRC, and frames are told
apart by their delimiters, not by silence. Like the rest of the core it uses the standard
library alone and takes time as an argument.

    >>> frame = encode_ascii_frame(17, bytes.fromhex("03 00 6B 00 03"))
    >>> frame
    b':1103006B00037E\\r\\n'
    >>> [out.pdu.hex() for out in AsciiReceiver().feed(frame, now=0.0)]
    ['03006b0003']
"""

from __future__ import annotations

from aiortu._public import publish
from aiortu.core.ascii._frame import (
    ASCII_START,
    CR,
    LF,
    MAX_ASCII_FRAME_LENGTH,
    MIN_ASCII_FRAME_LENGTH,
    check_ascii_body,
    decode_ascii_frame,
    encode_ascii_frame,
)
from aiortu.core.ascii._lrc import lrc
from aiortu.core.ascii._receiver import (
    ASCII_TRANSITIONS,
    DEFAULT_ASCII_TIMEOUT,
    AsciiDiscardReason,
    AsciiEvent,
    AsciiFrameDiscarded,
    AsciiFrameReceived,
    AsciiReceiver,
    AsciiReceiverOutput,
    AsciiState,
)

__all__ = (
    "ASCII_START",
    "ASCII_TRANSITIONS",
    "CR",
    "DEFAULT_ASCII_TIMEOUT",
    "LF",
    "MAX_ASCII_FRAME_LENGTH",
    "MIN_ASCII_FRAME_LENGTH",
    "AsciiDiscardReason",
    "AsciiEvent",
    "AsciiFrameDiscarded",
    "AsciiFrameReceived",
    "AsciiReceiver",
    "AsciiReceiverOutput",
    "AsciiState",
    "check_ascii_body",
    "decode_ascii_frame",
    "encode_ascii_frame",
    "lrc",
)

publish(__name__, __all__, globals())

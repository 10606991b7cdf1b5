"""RTU framing: the CRC, frames, the receiver's table machine and the bus decoder."""

from __future__ import annotations

from aiortu._public import publish
from aiortu.core.rtu._bus_decoder import (
    BusDecoder,
    CrcStatus,
    DecodedFrame,
    Direction,
    describe_frame,
)
from aiortu.core.rtu._crc import (
    CRC_INITIAL,
    check_crc,
    crc16,
    crc16_bytes,
)
from aiortu.core.rtu._frame import (
    CANNOT_KNOW,
    MAX_FRAME_LENGTH,
    MIN_FRAME_LENGTH,
    NEED_MORE,
    Frame,
    decode_frame,
    encode_frame,
    expected_request_length,
    expected_response_length,
)
from aiortu.core.rtu._frame_search import FrameSearch
from aiortu.core.rtu._receiver import (
    TOLERANT_FRAME_SILENCE,
    DiscardReason,
    FrameDiscarded,
    FrameReceived,
    Receiver,
    ReceiverError,
    ReceiverEvent,
    ReceiverState,
    Role,
    TimingMode,
)
from aiortu.core.rtu._receiver import TRANSITIONS as RECEIVER_TRANSITIONS

__all__ = (
    "BusDecoder",
    "CANNOT_KNOW",
    "CRC_INITIAL",
    "CrcStatus",
    "DecodedFrame",
    "Direction",
    "DiscardReason",
    "Frame",
    "FrameDiscarded",
    "FrameReceived",
    "FrameSearch",
    "MAX_FRAME_LENGTH",
    "MIN_FRAME_LENGTH",
    "NEED_MORE",
    "RECEIVER_TRANSITIONS",
    "Receiver",
    "ReceiverError",
    "ReceiverEvent",
    "ReceiverState",
    "Role",
    "TOLERANT_FRAME_SILENCE",
    "TimingMode",
    "check_crc",
    "crc16",
    "crc16_bytes",
    "decode_frame",
    "describe_frame",
    "encode_frame",
    "expected_request_length",
    "expected_response_length",
)

publish(__name__, __all__, globals())

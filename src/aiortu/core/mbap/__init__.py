"""Modbus TCP framing: the MBAP header and its stream decoder."""

from __future__ import annotations

from aiortu._public import publish
from aiortu.core.mbap._adu import (
    HEADER_LENGTH,
    MAX_ADU_LENGTH,
    MAX_PDU_LENGTH,
    Adu,
    AduDecoder,
    MalformedHeader,
    decode_adu,
    encode_adu,
)

__all__ = (
    "Adu",
    "AduDecoder",
    "HEADER_LENGTH",
    "MAX_ADU_LENGTH",
    "MAX_PDU_LENGTH",
    "MalformedHeader",
    "decode_adu",
    "encode_adu",
)

publish(__name__, __all__, globals())

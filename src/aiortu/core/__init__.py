"""The sans-IO Modbus RTU protocol core: pure functions and state machines, no I/O.

Everything here uses the standard library alone and takes time as an argument, so every
rule of the spec can be tested with exact numbers.
"""

from __future__ import annotations

from aiortu.core import pdu_bits, pdu_registers  # noqa: F401  (register the PDU classes)
from aiortu.core.codes import (
    DeviceIdObject,
    DeviceIdReadCode,
    DiagnosticSubFunction,
    ExceptionCode,
    FunctionCode,
)
from aiortu.core.pdu import ExceptionPDU, RawPDU, Request, Response, decode_request, decode_response
from aiortu.core.timing import LineSettings, Parity

__all__ = (
    "DeviceIdObject",
    "DeviceIdReadCode",
    "DiagnosticSubFunction",
    "ExceptionCode",
    "ExceptionPDU",
    "FunctionCode",
    "LineSettings",
    "Parity",
    "RawPDU",
    "Request",
    "Response",
    "decode_request",
    "decode_response",
)

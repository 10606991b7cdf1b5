"""The sans-IO Modbus RTU protocol core: pure functions and state machines, no I/O.

Everything here uses the standard library alone and takes time as an argument, so every
rule of the spec can be tested with exact numbers.
"""

from __future__ import annotations

# Importing the PDU modules registers their classes for decode_request/decode_response.
from aiortu.core import (  # noqa: F401
    pdu_bits,
    pdu_device_id,
    pdu_files,
    pdu_registers,
    pdu_serial_line,
)
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

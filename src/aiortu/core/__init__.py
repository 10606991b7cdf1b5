"""The sans-IO Modbus protocol core: pure functions and state machines, no I/O.

Everything here uses the standard library alone and takes time as an argument, so every
rule of the spec can be tested with exact numbers. The subpackages follow the protocol's
parts: [`pdu`][aiortu.core.pdu] (the application layer), [`rtu`][aiortu.core.rtu] and
[`mbap`][aiortu.core.mbap] (the framings), [`serial`][aiortu.core.serial] (serial-line
settings and character times), [`machines`][aiortu.core.machines] (the master's and the
slave's state machines) and [`model`][aiortu.core.model] (the data model). This package
re-exports the names most programs need.
"""

from __future__ import annotations

from aiortu._public import publish
from aiortu.core import machines, mbap, model, pdu, rtu, serial
from aiortu.core.codes import (
    DeviceIdObject,
    DeviceIdReadCode,
    DiagnosticSubFunction,
    ExceptionCode,
    FunctionCode,
)
from aiortu.core.pdu import ExceptionPDU, RawPDU, Request, Response, decode_request, decode_response
from aiortu.core.serial import LineSettings, Parity

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
    "machines",
    "mbap",
    "model",
    "pdu",
    "rtu",
    "serial",
)

publish(__name__, __all__, globals())

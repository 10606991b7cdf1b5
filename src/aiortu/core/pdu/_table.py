"""The table of function codes and their PDU classes, and decoding by function code.

Every function code aiortu has classes for is in
[`PDU_CLASSES`][aiortu.core.pdu.PDU_CLASSES], written out once here; decoding looks the code
up there and nowhere else.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from types import MappingProxyType
from typing import Final

from aiortu.core.codes import EXCEPTION_BIT, ExceptionCode, FunctionCode
from aiortu.core.errors import MalformedPDU
from aiortu.core.pdu._base import MAX_PDU_LENGTH, ExceptionPDU, RawPDU, Request, Response
from aiortu.core.pdu._bits import (
    ReadCoilsRequest,
    ReadCoilsResponse,
    ReadDiscreteInputsRequest,
    ReadDiscreteInputsResponse,
    WriteMultipleCoilsRequest,
    WriteMultipleCoilsResponse,
    WriteSingleCoilRequest,
    WriteSingleCoilResponse,
)
from aiortu.core.pdu._device_id import decode_mei_request, decode_mei_response
from aiortu.core.pdu._files import (
    ReadFileRecordRequest,
    ReadFileRecordResponse,
    WriteFileRecordRequest,
    WriteFileRecordResponse,
)
from aiortu.core.pdu._registers import (
    MaskWriteRegisterRequest,
    MaskWriteRegisterResponse,
    ReadFifoQueueRequest,
    ReadFifoQueueResponse,
    ReadHoldingRegistersRequest,
    ReadHoldingRegistersResponse,
    ReadInputRegistersRequest,
    ReadInputRegistersResponse,
    ReadWriteMultipleRegistersRequest,
    ReadWriteMultipleRegistersResponse,
    WriteMultipleRegistersRequest,
    WriteMultipleRegistersResponse,
    WriteSingleRegisterRequest,
    WriteSingleRegisterResponse,
)
from aiortu.core.pdu._serial_line import (
    DiagnosticsRequest,
    DiagnosticsResponse,
    GetCommEventCounterRequest,
    GetCommEventCounterResponse,
    GetCommEventLogRequest,
    GetCommEventLogResponse,
    ReadExceptionStatusRequest,
    ReadExceptionStatusResponse,
    ReportServerIdRequest,
    ReportServerIdResponse,
)

__all__ = ("PDU_CLASSES", "decode_request", "decode_response", "known_function_codes")

PDU_CLASSES: Final[Mapping[int, tuple[type[Request], type[Response]]]] = MappingProxyType(
    {
        FunctionCode.READ_COILS: (ReadCoilsRequest, ReadCoilsResponse),
        FunctionCode.READ_DISCRETE_INPUTS: (ReadDiscreteInputsRequest, ReadDiscreteInputsResponse),
        FunctionCode.READ_HOLDING_REGISTERS: (
            ReadHoldingRegistersRequest,
            ReadHoldingRegistersResponse,
        ),
        FunctionCode.READ_INPUT_REGISTERS: (ReadInputRegistersRequest, ReadInputRegistersResponse),
        FunctionCode.WRITE_SINGLE_COIL: (WriteSingleCoilRequest, WriteSingleCoilResponse),
        FunctionCode.WRITE_SINGLE_REGISTER: (
            WriteSingleRegisterRequest,
            WriteSingleRegisterResponse,
        ),
        FunctionCode.READ_EXCEPTION_STATUS: (
            ReadExceptionStatusRequest,
            ReadExceptionStatusResponse,
        ),
        FunctionCode.DIAGNOSTICS: (DiagnosticsRequest, DiagnosticsResponse),
        FunctionCode.GET_COMM_EVENT_COUNTER: (
            GetCommEventCounterRequest,
            GetCommEventCounterResponse,
        ),
        FunctionCode.GET_COMM_EVENT_LOG: (GetCommEventLogRequest, GetCommEventLogResponse),
        FunctionCode.WRITE_MULTIPLE_COILS: (WriteMultipleCoilsRequest, WriteMultipleCoilsResponse),
        FunctionCode.WRITE_MULTIPLE_REGISTERS: (
            WriteMultipleRegistersRequest,
            WriteMultipleRegistersResponse,
        ),
        FunctionCode.REPORT_SERVER_ID: (ReportServerIdRequest, ReportServerIdResponse),
        FunctionCode.READ_FILE_RECORD: (ReadFileRecordRequest, ReadFileRecordResponse),
        FunctionCode.WRITE_FILE_RECORD: (WriteFileRecordRequest, WriteFileRecordResponse),
        FunctionCode.MASK_WRITE_REGISTER: (MaskWriteRegisterRequest, MaskWriteRegisterResponse),
        FunctionCode.READ_WRITE_MULTIPLE_REGISTERS: (
            ReadWriteMultipleRegistersRequest,
            ReadWriteMultipleRegistersResponse,
        ),
        FunctionCode.READ_FIFO_QUEUE: (ReadFifoQueueRequest, ReadFifoQueueResponse),
    }
)
"""Function code -> (request class, response class), for every code with one class each.

Encapsulated interface transport (2B) is not here: it carries several classes told apart by
its MEI type byte, and decodes through its own two functions.
"""

_Decoders = tuple[Callable[[bytes], Request], Callable[[bytes], Response]]

# What decoding looks up: the table's classes, then 2B's decoders by MEI type.
_DECODERS: Final[dict[int, _Decoders]] = {
    code: (request_class.decode, response_class.decode)
    for code, (request_class, response_class) in PDU_CLASSES.items()
}
_DECODERS[FunctionCode.ENCAPSULATED_INTERFACE_TRANSPORT] = (decode_mei_request, decode_mei_response)


def _function_code(pdu: bytes) -> int:
    if not pdu:
        raise MalformedPDU(
            "empty PDU", field="length", value=0, allowed=range(1, MAX_PDU_LENGTH + 1)
        )
    if len(pdu) > MAX_PDU_LENGTH:
        raise MalformedPDU(
            "PDU too long", field="length", value=len(pdu), allowed=range(1, MAX_PDU_LENGTH + 1)
        )
    return pdu[0]


def decode_request(pdu: bytes) -> Request:
    """Decode a request PDU into its class, or into [`RawPDU`][aiortu.core.pdu.RawPDU] for an
    unknown code.

    Raises [`MalformedPDU`][aiortu.errors.MalformedPDU] for function code 0 or >= 0x80, and for a
    known function code whose data breaks the spec (its `exception_code` says which
    exception a slave should answer).
    """
    code = _function_code(pdu)
    if code == 0 or code & EXCEPTION_BIT:
        raise MalformedPDU(
            "invalid request function code",
            field="function_code",
            value=code,
            allowed=range(1, EXCEPTION_BIT),
            exception_code=ExceptionCode.ILLEGAL_FUNCTION,
        )
    decoders = _DECODERS.get(code)
    if decoders is not None:
        return decoders[0](pdu)
    return RawPDU.decode(pdu)


def decode_response(pdu: bytes) -> Response | ExceptionPDU:
    """Decode a reply PDU: an [`ExceptionPDU`][aiortu.core.pdu.ExceptionPDU], a known response, or
    [`RawPDU`][aiortu.core.pdu.RawPDU]."""
    code = _function_code(pdu)
    if code & EXCEPTION_BIT:
        return ExceptionPDU.decode(pdu)
    if code == 0:
        raise MalformedPDU(
            "invalid function code", field="function_code", value=0, allowed=range(1, EXCEPTION_BIT)
        )
    decoders = _DECODERS.get(code)
    if decoders is not None:
        return decoders[1](pdu)
    return RawPDU.decode(pdu)


def known_function_codes() -> frozenset[int]:
    """The function codes that decode into a class of their own."""
    return frozenset(_DECODERS)

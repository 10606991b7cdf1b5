"""Protocol data units: one immutable class per request and reply, and decoding by function code.

A PDU is the function code and its data, without the unit address and the CRC of the RTU frame
around it (see [`aiortu.core.rtu`][aiortu.core.rtu]). Every public function code has a request
class and a response class, listed in [`PDU_CLASSES`][aiortu.core.pdu.PDU_CLASSES]; each is an
immutable dataclass that checks the spec's limits when it is built and encodes itself to bytes:

    >>> ReadHoldingRegistersRequest(address=0x6B, count=3).encode().hex(" ")
    '03 00 6b 00 03'

Errors follow who caused them. Building an object with a field out of range raises
[`InvalidRequest`][aiortu.errors.InvalidRequest] (requests) or
[`InvalidValue`][aiortu.errors.InvalidValue] (responses), naming the field, the value and the
allowed range. Decoding bytes that break the spec raises
[`MalformedPDU`][aiortu.errors.MalformedPDU] and nothing else: never an `IndexError` or a
`struct.error` from inside.

An exception response is a value, [`ExceptionPDU`][aiortu.core.pdu.ExceptionPDU], that the caller
can inspect; the master turns it into [`ExceptionResponse`][aiortu.errors.ExceptionResponse] at its
boundary. Function codes without a class (the user-defined ones, vendor extensions) travel as
[`RawPDU`][aiortu.core.pdu.RawPDU].
"""

from __future__ import annotations

from aiortu._public import publish
from aiortu.core.pdu._base import (
    ADDRESS_RANGE,
    BYTE_RANGE,
    MAX_PDU_LENGTH,
    PDU,
    REGISTER_RANGE,
    ExceptionPDU,
    RawPDU,
    Request,
    Response,
    encode_exception,
    pack_bits,
    pack_registers,
    unpack_bits,
    unpack_registers,
)
from aiortu.core.pdu._bits import (
    MAX_READ_BITS,
    MAX_WRITE_BITS,
    ReadCoilsRequest,
    ReadCoilsResponse,
    ReadDiscreteInputsRequest,
    ReadDiscreteInputsResponse,
    WriteMultipleCoilsRequest,
    WriteMultipleCoilsResponse,
    WriteSingleCoilRequest,
    WriteSingleCoilResponse,
)
from aiortu.core.pdu._device_id import (
    CONFORMITY_LEVELS,
    ReadDeviceIdentificationRequest,
    ReadDeviceIdentificationResponse,
)
from aiortu.core.pdu._files import (
    FILE_NUMBER_RANGE,
    FILE_REFERENCE_TYPE,
    MAX_READ_SUB_REQUESTS,
    RECORD_NUMBER_RANGE,
    FileRecord,
    FileRecordRequest,
    ReadFileRecordRequest,
    ReadFileRecordResponse,
    WriteFileRecordRequest,
    WriteFileRecordResponse,
)
from aiortu.core.pdu._registers import (
    MAX_FIFO_COUNT,
    MAX_READ_REGISTERS,
    MAX_READ_WRITE_WRITE_REGISTERS,
    MAX_WRITE_REGISTERS,
    MaskWriteRegisterRequest,
    MaskWriteRegisterResponse,
    RawRegisterRead,
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
    COMM_EVENT_STATUS_BUSY,
    COMM_EVENT_STATUS_READY,
    MAX_COMM_EVENTS,
    MAX_DIAGNOSTIC_DATA,
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
from aiortu.core.pdu._table import (
    PDU_CLASSES,
    decode_request,
    decode_response,
    known_function_codes,
)
from aiortu.core.pdu._text import (
    HEX_LIMIT,
    describe_reply,
    describe_request,
    enum_name,
    function_name,
    hex_text,
    pdu_to_dict,
    table_access,
)

__all__ = (
    "ADDRESS_RANGE",
    "BYTE_RANGE",
    "COMM_EVENT_STATUS_BUSY",
    "COMM_EVENT_STATUS_READY",
    "CONFORMITY_LEVELS",
    "DiagnosticsRequest",
    "DiagnosticsResponse",
    "ExceptionPDU",
    "FILE_NUMBER_RANGE",
    "FILE_REFERENCE_TYPE",
    "FileRecord",
    "FileRecordRequest",
    "GetCommEventCounterRequest",
    "GetCommEventCounterResponse",
    "GetCommEventLogRequest",
    "GetCommEventLogResponse",
    "HEX_LIMIT",
    "MAX_COMM_EVENTS",
    "MAX_DIAGNOSTIC_DATA",
    "MAX_FIFO_COUNT",
    "MAX_PDU_LENGTH",
    "MAX_READ_BITS",
    "MAX_READ_REGISTERS",
    "MAX_READ_SUB_REQUESTS",
    "MAX_READ_WRITE_WRITE_REGISTERS",
    "MAX_WRITE_BITS",
    "MAX_WRITE_REGISTERS",
    "MaskWriteRegisterRequest",
    "MaskWriteRegisterResponse",
    "PDU",
    "PDU_CLASSES",
    "RECORD_NUMBER_RANGE",
    "REGISTER_RANGE",
    "RawPDU",
    "RawRegisterRead",
    "ReadCoilsRequest",
    "ReadCoilsResponse",
    "ReadDeviceIdentificationRequest",
    "ReadDeviceIdentificationResponse",
    "ReadDiscreteInputsRequest",
    "ReadDiscreteInputsResponse",
    "ReadExceptionStatusRequest",
    "ReadExceptionStatusResponse",
    "ReadFifoQueueRequest",
    "ReadFifoQueueResponse",
    "ReadFileRecordRequest",
    "ReadFileRecordResponse",
    "ReadHoldingRegistersRequest",
    "ReadHoldingRegistersResponse",
    "ReadInputRegistersRequest",
    "ReadInputRegistersResponse",
    "ReadWriteMultipleRegistersRequest",
    "ReadWriteMultipleRegistersResponse",
    "ReportServerIdRequest",
    "ReportServerIdResponse",
    "Request",
    "Response",
    "WriteFileRecordRequest",
    "WriteFileRecordResponse",
    "WriteMultipleCoilsRequest",
    "WriteMultipleCoilsResponse",
    "WriteMultipleRegistersRequest",
    "WriteMultipleRegistersResponse",
    "WriteSingleCoilRequest",
    "WriteSingleCoilResponse",
    "WriteSingleRegisterRequest",
    "WriteSingleRegisterResponse",
    "decode_request",
    "encode_exception",
    "decode_response",
    "describe_reply",
    "describe_request",
    "enum_name",
    "function_name",
    "hex_text",
    "known_function_codes",
    "pack_bits",
    "pack_registers",
    "pdu_to_dict",
    "table_access",
    "unpack_bits",
    "unpack_registers",
)

publish(__name__, __all__, globals())

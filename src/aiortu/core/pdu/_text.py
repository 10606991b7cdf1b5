"""Words for PDUs: one-line descriptions and JSON-able dicts of requests and replies.

Used by [`aiortu.core.rtu`][aiortu.core.rtu] and by traces. A request reads as what
it asks (`read holding registers 107..109 (3)`, `write coil 172 = ON`), a reply as what it says
(`reply [44609, 22098, 17216]`), and a reply given the request it answers names the addresses of its
values (`reply holding 107..109 = [44609, 22098, 17216]`). Addresses are protocol addresses (from
0), a span `a..b` is inclusive, and bits are written 1 and 0.
"""

from __future__ import annotations

import dataclasses
import enum
from collections.abc import Iterable
from typing import Any

from aiortu.core.codes import DeviceIdObject, ExceptionCode, FunctionCode
from aiortu.core.pdu._base import PDU, ExceptionPDU, RawPDU, Request, Response
from aiortu.core.pdu._bits import (
    ReadCoilsRequest,
    ReadCoilsResponse,
    WriteMultipleCoilsRequest,
    WriteMultipleCoilsResponse,
    WriteSingleCoilRequest,
    WriteSingleCoilResponse,
)
from aiortu.core.pdu._device_id import (
    ReadDeviceIdentificationRequest,
    ReadDeviceIdentificationResponse,
)
from aiortu.core.pdu._files import (
    FileRecord,
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
    ReadWriteMultipleRegistersRequest,
    WriteMultipleRegistersRequest,
    WriteMultipleRegistersResponse,
    WriteSingleRegisterRequest,
    WriteSingleRegisterResponse,
)
from aiortu.core.pdu._serial_line import (
    DiagnosticsRequest,
    DiagnosticsResponse,
    GetCommEventCounterResponse,
    GetCommEventLogResponse,
    ReadExceptionStatusResponse,
    ReportServerIdResponse,
)

__all__ = (
    "HEX_LIMIT",
    "describe_reply",
    "describe_request",
    "enum_name",
    "function_name",
    "hex_text",
    "pdu_to_dict",
    "table_access",
)

HEX_LIMIT = 32
"""Descriptions show at most this many bytes in hex; dicts always hold all of them."""

_TABLES = {
    FunctionCode.READ_COILS: ("coils", "coils"),
    FunctionCode.READ_DISCRETE_INPUTS: ("discrete inputs", "discrete_inputs"),
    FunctionCode.READ_HOLDING_REGISTERS: ("holding", "holding_registers"),
    FunctionCode.READ_INPUT_REGISTERS: ("input", "input_registers"),
    FunctionCode.READ_WRITE_MULTIPLE_REGISTERS: ("holding", "holding_registers"),
}
"""Per read function code: the table as descriptions name it, and as the dict does."""


def function_name(function_code: int) -> str:
    """The spec's name of `function_code` in lower case, or `function 0xNN`."""
    try:
        return FunctionCode(function_code).name.lower().replace("_", " ")
    except ValueError:
        return f"function 0x{function_code:02X}"


def hex_text(data: bytes, limit: int | None = HEX_LIMIT) -> str:
    """`data` as upper-case hex pairs; past `limit` bytes, cut short with the total length."""
    if limit is not None and len(data) > limit:
        return f"{data[:limit].hex(' ').upper()} ... ({len(data)} bytes)"
    return data.hex(" ").upper()


def _span(address: int, count: int) -> str:
    return str(address) if count == 1 else f"{address}..{address + count - 1}"


def _bits(values: Iterable[bool]) -> str:
    return "[" + ", ".join("1" if value else "0" for value in values) + "]"


def _words(values: Iterable[int]) -> str:
    return "[" + ", ".join(str(value) for value in values) + "]"


def _on_off(value: bool) -> str:
    return "ON" if value else "OFF"


def enum_name(value: int, width: int = 2) -> str:
    """The name of an enum member, or the number in hex (`width` digits) when it has none."""
    return value.name if isinstance(value, enum.Enum) else f"0x{value:0{width}X}"


def _text(value: bytes) -> str:
    """An identification value: quoted text when printable ASCII, else hex."""
    if value and all(0x20 <= byte < 0x7F for byte in value):
        return repr(value.decode("ascii"))
    return hex_text(value) if value else "''"


def describe_request(request: Request) -> str:
    """What a request asks, without the unit: `read holding registers 107..109 (3)`."""
    match request:
        case ReadCoilsRequest() | ReadHoldingRegistersRequest():
            span = _span(request.address, request.count)
            return f"{function_name(request.function_code)} {span} ({request.count})"
        case WriteSingleCoilRequest():
            return f"write coil {request.address} = {_on_off(request.value)}"
        case WriteSingleRegisterRequest():
            return f"write register {request.address} = {request.value}"
        case WriteMultipleCoilsRequest():
            return f"write coils {_span(request.address, request.count)} = {_bits(request.values)}"
        case WriteMultipleRegistersRequest():
            span = _span(request.address, request.count)
            return f"write registers {span} = {_words(request.values)}"
        case MaskWriteRegisterRequest():
            return _mask(request.address, request.and_mask, request.or_mask)
        case ReadWriteMultipleRegistersRequest():
            read = _span(request.read_address, request.read_count)
            write = _span(request.write_address, request.write_count)
            return (
                f"read/write registers read {read} ({request.read_count}),"
                f" write {write} = {_words(request.values)}"
            )
        case ReadFifoQueueRequest():
            return f"read FIFO queue {request.address}"
        case DiagnosticsRequest():
            return f"diagnostics {_diagnostic(request.sub_function, request.data, reply=False)}"
        case ReadFileRecordRequest():
            subs = ", ".join(
                f"file {sub.file_number} records"
                f" {_span(sub.record_number, sub.record_length)} ({sub.record_length})"
                for sub in request.sub_requests
            )
            return f"read file record {subs}"
        case WriteFileRecordRequest():
            return f"write file record {_records(request.records)}"
        case ReadDeviceIdentificationRequest():
            what = enum_name(request.read_code)
            return f"read device identification {what} from object {request.object_id}"
        case RawPDU():
            return _raw(request)
    return function_name(request.function_code)


def describe_reply(reply: Response, request: Request | None = None) -> str:
    """What a reply says, without the unit: `reply holding 107..109 = [1, 2, 3]`.

    With the `request` it answers, a read reply names the addresses of its values and
    drops the padding bits of a bit read.
    """
    match reply:
        case ReadCoilsResponse():
            if isinstance(request, ReadCoilsRequest) and request.count <= len(reply.values):
                table = _TABLES[FunctionCode(reply.function_code)][0]
                span = _span(request.address, request.count)
                return f"reply {table} {span} = {_bits(request.bits_of(reply))}"
            return f"reply {_bits(reply.values)}"
        case ReadHoldingRegistersResponse():
            read = _read_span(request, len(reply.values))
            if read is not None:
                table = _TABLES[FunctionCode(reply.function_code)][0]
                return f"reply {table} {_span(*read)} = {_words(reply.values)}"
            return f"reply {_words(reply.values)}"
        case WriteSingleCoilResponse():
            return f"reply write coil {reply.address} = {_on_off(reply.value)}"
        case WriteSingleRegisterResponse():
            return f"reply write register {reply.address} = {reply.value}"
        case WriteMultipleCoilsResponse():
            return f"reply write coils {_span(reply.address, reply.count)} ({reply.count})"
        case WriteMultipleRegistersResponse():
            return f"reply write registers {_span(reply.address, reply.count)} ({reply.count})"
        case MaskWriteRegisterResponse():
            return "reply " + _mask(reply.address, reply.and_mask, reply.or_mask)
        case ReadFifoQueueResponse():
            where = f" {request.address}" if isinstance(request, ReadFifoQueueRequest) else ""
            return f"reply FIFO queue{where} = {_words(reply.values)}"
        case ReadExceptionStatusResponse():
            return f"reply exception status 0x{reply.status:02X} = {_bits(reply.bits)}"
        case DiagnosticsResponse():
            return f"reply diagnostics {_diagnostic(reply.sub_function, reply.data, reply=True)}"
        case GetCommEventCounterResponse():
            state = "busy" if reply.busy else "ready"
            return f"reply comm event counter {reply.event_count}, {state}"
        case GetCommEventLogResponse():
            state = "busy" if reply.busy else "ready"
            return (
                f"reply comm event log {reply.event_count} events, {reply.message_count}"
                f" messages, {state}, log [{hex_text(reply.events)}]"
            )
        case ReportServerIdResponse():
            text = (
                f"reply server id {hex_text(reply.server_id)},"
                f" run indicator {_on_off(reply.run_indicator)}"
            )
            if reply.additional_data:
                text += f", data {hex_text(reply.additional_data)}"
            return text
        case ReadFileRecordResponse():
            if isinstance(request, ReadFileRecordRequest) and len(request.sub_requests) == len(
                reply.records
            ):
                parts = ", ".join(
                    f"file {sub.file_number} records"
                    f" {_span(sub.record_number, len(values))} = {_words(values)}"
                    for sub, values in zip(request.sub_requests, reply.records, strict=True)
                )
                return f"reply file record {parts}"
            return "reply file record " + ", ".join(_words(values) for values in reply.records)
        case WriteFileRecordResponse():
            return f"reply write file record {_records(reply.records)}"
        case ReadDeviceIdentificationResponse():
            return _device_id(reply)
        case RawPDU():
            return "reply " + _raw(reply)
    return "reply " + function_name(reply.function_code)


def _read_span(request: Request | None, count: int) -> tuple[int, int] | None:
    """(first address, count) of the registers a paired read reply carries."""
    if isinstance(request, ReadHoldingRegistersRequest) and request.count == count:
        return request.address, count
    if isinstance(request, ReadWriteMultipleRegistersRequest) and request.read_count == count:
        return request.read_address, count
    return None


def _mask(address: int, and_mask: int, or_mask: int) -> str:
    return f"mask write register {address} and 0x{and_mask:04X} or 0x{or_mask:04X}"


def _diagnostic(sub_function: int, data: bytes, *, reply: bool) -> str:
    if not isinstance(sub_function, enum.Enum):
        return f"sub-function 0x{sub_function:04X} data [{hex_text(data)}]"
    name = sub_function.name
    if reply and len(data) == 2 and name.startswith("RETURN_") and sub_function:
        return f"{name} = {int.from_bytes(data, 'big')}"
    if data == b"\x00\x00" and sub_function:
        return name
    return f"{name} data [{hex_text(data)}]"


def _records(records: tuple[FileRecord, ...]) -> str:
    return ", ".join(
        f"file {record.file_number} records"
        f" {_span(record.record_number, record.record_length)} = {_words(record.values)}"
        for record in records
    )


def _device_id(reply: ReadDeviceIdentificationResponse) -> str:
    objects = ", ".join(
        f"{enum_name(_object_id(object_id))}={_text(value)}" for object_id, value in reply.objects
    )
    text = (
        f"reply device identification {enum_name(reply.read_code)}"
        f" conformity 0x{reply.conformity_level:02X}: {objects or 'no objects'}"
    )
    if reply.more_follows:
        text += f", more follows from object {reply.next_object_id}"
    return text


def _object_id(object_id: int) -> int:
    try:
        return DeviceIdObject(object_id)
    except ValueError:
        return object_id


def _raw(pdu: RawPDU) -> str:
    name = function_name(pdu.function_code)
    return f"{name} data [{hex_text(pdu.data)}]" if pdu.data else name


# -- JSON ----------------------------------------------------------------------------------


def _json(value: Any) -> Any:
    if isinstance(value, bool | None | str):
        return value
    if isinstance(value, int):
        return int(value)
    if isinstance(value, bytes):
        return value.hex(" ").upper()
    if isinstance(value, tuple | list):
        return [_json(item) for item in value]
    if dataclasses.is_dataclass(value) and not isinstance(value, type):
        return {f.name: _json(getattr(value, f.name)) for f in dataclasses.fields(value)}
    return str(value)


def pdu_to_dict(pdu: PDU) -> dict[str, Any]:
    """The PDU as JSON types: its class name under `type`, then its fields."""
    out: dict[str, Any] = {"type": type(pdu).__name__}
    if isinstance(pdu, ExceptionPDU):
        code = pdu.exception_code
        out["exception"] = code.name if isinstance(code, ExceptionCode) else None
    # Every PDU class is a dataclass; the data of one is its fields.
    for field in dataclasses.fields(pdu):  # type: ignore[arg-type]
        out[field.name] = _json(getattr(pdu, field.name))
    return out


def table_access(pdu: PDU, request: Request | None) -> dict[str, Any]:
    """Which table `pdu` reads or writes: `table`, `address`, `count`, and `values`
    when it carries them (a read reply only when paired with its `request`); else `{}`.
    """
    code = pdu.function_code
    match pdu:
        case ReadCoilsRequest() | ReadHoldingRegistersRequest():
            return _table(code, pdu.address, pdu.count, None)
        case WriteSingleCoilRequest() | WriteSingleCoilResponse():
            return _table(FunctionCode.READ_COILS, pdu.address, 1, [pdu.value])
        case WriteSingleRegisterRequest() | WriteSingleRegisterResponse():
            return _table(FunctionCode.READ_HOLDING_REGISTERS, pdu.address, 1, [pdu.value])
        case WriteMultipleCoilsRequest():
            return _table(FunctionCode.READ_COILS, pdu.address, pdu.count, list(pdu.values))
        case WriteMultipleRegistersRequest():
            registers = FunctionCode.READ_HOLDING_REGISTERS
            return _table(registers, pdu.address, pdu.count, list(pdu.values))
        case WriteMultipleCoilsResponse():
            return _table(FunctionCode.READ_COILS, pdu.address, pdu.count, None)
        case WriteMultipleRegistersResponse() | MaskWriteRegisterRequest():
            count = pdu.count if isinstance(pdu, WriteMultipleRegistersResponse) else 1
            return _table(FunctionCode.READ_HOLDING_REGISTERS, pdu.address, count, None)
        case ReadCoilsResponse() if isinstance(request, ReadCoilsRequest):
            if request.count <= len(pdu.values):
                return _table(code, request.address, request.count, request.bits_of(pdu))
        case ReadHoldingRegistersResponse():
            read = _read_span(request, len(pdu.values))
            if read is not None:
                return _table(code, read[0], read[1], list(pdu.values))
    return {}


def _table(code: int, address: int, count: int, values: list[Any] | None) -> dict[str, Any]:
    out: dict[str, Any] = {
        "table": _TABLES[FunctionCode(code)][1],
        "address": address,
        "count": count,
    }
    if values is not None:
        out["values"] = values
    return out

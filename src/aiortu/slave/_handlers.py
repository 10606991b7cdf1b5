"""The slave's built-in request handlers: one function per public function code it serves.

A handler takes the decoded request and a [`RequestContext`][aiortu.slave.RequestContext] (the unit,
its data store, whether the request was broadcast, the line's state machine) and returns the
response PDU, a [`Reply`][aiortu.slave.Reply] (to answer late, as another unit, or not at all), or
`None` to send nothing. It raises [`ExceptionResponse`][aiortu.errors.ExceptionResponse] for an
exception reply; the store raises it too (02 for unmapped addresses). User handlers have the same
shape and may be coroutine functions. `BUILTIN_HANDLERS` maps each function code served here to its
handler.

A store's methods may return awaitables (an async store): the built-in handlers then
return an awaitable themselves, which the slave awaits; with a sync store they stay
plain calls.

The commonest requests may instead be answered at once, straight from the bytes of the
request to the bytes of the reply, while these handlers serve their function codes:
see [`aiortu.slave`][aiortu.slave].
"""

from __future__ import annotations

import inspect
from collections.abc import Awaitable, Callable, Mapping, Sequence
from dataclasses import dataclass
from typing import Any, Final, TypeVar

from aiortu.core.codes import DiagnosticSubFunction, ExceptionCode, FunctionCode
from aiortu.core.machines import SlaveMachine
from aiortu.core.model import (
    AsyncDataStore,
    DataStore,
    ServerId,
    Table,
    answer_device_identification,
)
from aiortu.core.pdu import (
    COMM_EVENT_STATUS_READY,
    MAX_FIFO_COUNT,
    DiagnosticsRequest,
    DiagnosticsResponse,
    ExceptionPDU,
    GetCommEventCounterRequest,
    GetCommEventCounterResponse,
    GetCommEventLogRequest,
    GetCommEventLogResponse,
    MaskWriteRegisterRequest,
    MaskWriteRegisterResponse,
    ReadCoilsRequest,
    ReadCoilsResponse,
    ReadDeviceIdentificationRequest,
    ReadDiscreteInputsRequest,
    ReadDiscreteInputsResponse,
    ReadExceptionStatusRequest,
    ReadExceptionStatusResponse,
    ReadFifoQueueRequest,
    ReadFifoQueueResponse,
    ReadFileRecordRequest,
    ReadFileRecordResponse,
    ReadHoldingRegistersRequest,
    ReadHoldingRegistersResponse,
    ReadInputRegistersRequest,
    ReadInputRegistersResponse,
    ReadWriteMultipleRegistersRequest,
    ReadWriteMultipleRegistersResponse,
    ReportServerIdRequest,
    ReportServerIdResponse,
    Response,
    WriteFileRecordRequest,
    WriteFileRecordResponse,
    WriteMultipleCoilsRequest,
    WriteMultipleCoilsResponse,
    WriteMultipleRegistersRequest,
    WriteMultipleRegistersResponse,
    WriteSingleCoilRequest,
    WriteSingleCoilResponse,
    WriteSingleRegisterRequest,
    WriteSingleRegisterResponse,
)
from aiortu.errors import ExceptionResponse

__all__ = (
    "BUILTIN_HANDLERS",
    "Answer",
    "Handler",
    "HandlerResult",
    "Reply",
    "RequestContext",
    "diagnostics",
    "get_comm_event_counter",
    "get_comm_event_log",
    "mask_write_register",
    "read_coils",
    "read_device_identification",
    "read_discrete_inputs",
    "read_exception_status",
    "read_fifo_queue",
    "read_file_record",
    "read_holding_registers",
    "read_input_registers",
    "read_write_multiple_registers",
    "report_server_id",
    "write_file_record",
    "write_multiple_coils",
    "write_multiple_registers",
    "write_single_coil",
    "write_single_register",
)

_V = TypeVar("_V")


@dataclass(frozen=True, slots=True)
class RequestContext:
    """What a handler knows besides the request: the `unit` asked, its `store`, whether
    the request was a `broadcast` (then the reply is never sent), and the line's
    `machine` (its counters, event log and listen-only mode; `None` outside a slave)."""

    unit: int
    store: DataStore | AsyncDataStore
    broadcast: bool = False
    machine: SlaveMachine | None = None


@dataclass(frozen=True, slots=True)
class Reply:
    """A handler's answer with a twist, to test masters against odd devices.

    `response` is the PDU to send (`None`: send nothing, a silent device); `delay`
    seconds pass before it is sent (a slow device); `unit`, when given, is the address
    the reply goes out with instead of the unit asked (a confused device).
    """

    response: Response | None
    delay: float = 0.0
    unit: int | None = None


HandlerResult = Response | ExceptionPDU | Reply | None
"""A handler's answer: the response PDU, an exception PDU, a [`Reply`][aiortu.slave.Reply], or
`None` to send nothing. Anything else is answered with exception 04 (and logged)."""

Answer = HandlerResult | Awaitable[HandlerResult]
"""What a handler returns: its answer, or an awaitable of it."""

Handler = Callable[[Any, RequestContext], Answer]
"""A request handler, sync or async. Its first argument is the decoded request (a
[`RawPDU`][aiortu.core.pdu.RawPDU] for codes without a class of their own)."""


def _then(value: _V | Awaitable[_V], build: Callable[[_V], Answer]) -> Answer:
    """`build(value)`, awaiting `value` first when a store returned an awaitable."""
    if inspect.isawaitable(value):
        return _await_then(value, build)
    return build(value)


async def _await_then(value: Awaitable[_V], build: Callable[[_V], Answer]) -> HandlerResult:
    result = build(await value)
    if inspect.isawaitable(result):
        return await result
    return result


def _all(values: list[Any], build: Callable[[list[Any]], Answer]) -> Answer:
    """`build(values)`, awaiting those of `values` that are awaitables, in order."""
    if any(inspect.isawaitable(value) for value in values):
        return _await_all(values, build)
    return build(values)


async def _await_all(values: list[Any], build: Callable[[list[Any]], Answer]) -> HandlerResult:
    resolved = [await value if inspect.isawaitable(value) else value for value in values]
    result = build(resolved)
    if inspect.isawaitable(result):
        return await result
    return result


def _capability(store: object, name: str) -> Callable[..., Any]:
    """The store's method `name`; exception 01 when the store lacks it."""
    method: Callable[..., Any] | None = getattr(store, name, None)
    if method is None:
        raise ExceptionResponse(ExceptionCode.ILLEGAL_FUNCTION)
    return method


def _machine(context: RequestContext) -> SlaveMachine:
    if context.machine is None:
        raise ExceptionResponse(ExceptionCode.ILLEGAL_FUNCTION)
    return context.machine


def read_coils(request: ReadCoilsRequest, context: RequestContext) -> Answer:
    """01: the coils asked for."""
    values = context.store.read(Table.COILS, request.address, request.count)
    return _then(values, lambda read: ReadCoilsResponse(tuple(map(bool, read))))


def read_discrete_inputs(request: ReadDiscreteInputsRequest, context: RequestContext) -> Answer:
    """02: the discrete inputs asked for."""
    values = context.store.read(Table.DISCRETE_INPUTS, request.address, request.count)
    return _then(values, lambda read: ReadDiscreteInputsResponse(tuple(map(bool, read))))


def read_holding_registers(request: ReadHoldingRegistersRequest, context: RequestContext) -> Answer:
    """03: the holding registers asked for."""
    values = context.store.read(Table.HOLDING_REGISTERS, request.address, request.count)
    return _then(values, lambda read: ReadHoldingRegistersResponse(tuple(read)))


def read_input_registers(request: ReadInputRegistersRequest, context: RequestContext) -> Answer:
    """04: the input registers asked for."""
    values = context.store.read(Table.INPUT_REGISTERS, request.address, request.count)
    return _then(values, lambda read: ReadInputRegistersResponse(tuple(read)))


def write_single_coil(request: WriteSingleCoilRequest, context: RequestContext) -> Answer:
    """05: set one coil; the reply echoes the request."""
    done = context.store.write(Table.COILS, request.address, (request.value,))
    return _then(done, lambda _: WriteSingleCoilResponse(request.address, request.value))


def write_single_register(request: WriteSingleRegisterRequest, context: RequestContext) -> Answer:
    """06: set one holding register; the reply echoes the request."""
    done = context.store.write(Table.HOLDING_REGISTERS, request.address, (request.value,))
    return _then(done, lambda _: WriteSingleRegisterResponse(request.address, request.value))


def read_exception_status(request: ReadExceptionStatusRequest, context: RequestContext) -> Answer:
    """07: the store's exception status byte, or 0 for a store without one."""
    reader = getattr(context.store, "read_exception_status", None)
    if reader is None:
        return ReadExceptionStatusResponse(0)
    return _then(reader(), lambda status: ReadExceptionStatusResponse(int(status)))


def write_multiple_coils(request: WriteMultipleCoilsRequest, context: RequestContext) -> Answer:
    """0F: set consecutive coils."""
    done = context.store.write(Table.COILS, request.address, request.values)
    return _then(done, lambda _: WriteMultipleCoilsResponse(request.address, request.count))


def write_multiple_registers(
    request: WriteMultipleRegistersRequest, context: RequestContext
) -> Answer:
    """10: set consecutive holding registers."""
    done = context.store.write(Table.HOLDING_REGISTERS, request.address, request.values)
    return _then(done, lambda _: WriteMultipleRegistersResponse(request.address, request.count))


def mask_write_register(request: MaskWriteRegisterRequest, context: RequestContext) -> Answer:
    """16: change bits of one holding register; the reply echoes the request."""
    store = context.store
    table = Table.HOLDING_REGISTERS

    def write(current: Sequence[int]) -> Answer:
        done = store.write(table, request.address, (request.apply(current[0]),))
        return _then(
            done,
            lambda _: MaskWriteRegisterResponse(request.address, request.and_mask, request.or_mask),
        )

    return _then(store.read(table, request.address, 1), write)


def read_write_multiple_registers(
    request: ReadWriteMultipleRegistersRequest, context: RequestContext
) -> Answer:
    """17: write, then read, holding registers.

    The read range is checked before anything is written, so a request whose read part
    is unmapped gets 02 and changes nothing.
    """
    store = context.store
    table = Table.HOLDING_REGISTERS

    def read_back(_: object) -> Answer:
        values = store.read(table, request.read_address, request.read_count)
        return _then(values, lambda read: ReadWriteMultipleRegistersResponse(tuple(read)))

    def write(_: object) -> Answer:
        return _then(store.write(table, request.write_address, request.values), read_back)

    return _then(store.read(table, request.read_address, request.read_count), write)


def read_fifo_queue(request: ReadFifoQueueRequest, context: RequestContext) -> Answer:
    """18: the values of a FIFO queue; more than 31 queued gets exception 03, as the spec says."""
    reader = getattr(context.store, "read_fifo_queue", None)
    if reader is None:
        raise ExceptionResponse(ExceptionCode.ILLEGAL_DATA_ADDRESS)

    def build(values: Sequence[int]) -> Answer:
        if len(values) > MAX_FIFO_COUNT:
            raise ExceptionResponse(ExceptionCode.ILLEGAL_DATA_VALUE)
        return ReadFifoQueueResponse(tuple(values))

    return _then(reader(request.address), build)


def read_file_record(request: ReadFileRecordRequest, context: RequestContext) -> Answer:
    """14: the records of each sub-request, in order; 02 for a missing file or record."""
    reader = _capability(context.store, "read_file_record")
    reads = [
        reader(sub.file_number, sub.record_number, sub.record_length)
        for sub in request.sub_requests
    ]
    return _all(reads, lambda records: ReadFileRecordResponse(tuple(map(tuple, records))))


def write_file_record(request: WriteFileRecordRequest, context: RequestContext) -> Answer:
    """15: write each sub-record, then echo the request.

    Every sub-record is checked (read) before any is written, so a request with one
    missing file or record gets 02 and changes nothing.
    """
    store = context.store
    reader = _capability(store, "read_file_record")
    writer = _capability(store, "write_file_record")
    records = request.records
    checks = [reader(r.file_number, r.record_number, r.record_length) for r in records]

    def write(_: object) -> Answer:
        writes = [writer(r.file_number, r.record_number, r.values) for r in records]
        return _all(writes, lambda _: WriteFileRecordResponse(records))

    return _all(checks, write)


def diagnostics(request: DiagnosticsRequest, context: RequestContext) -> Answer:
    """08: the serial line diagnostics, every sub-function of the spec.

    An unknown sub-function gets 01, as an unsupported function does. Force listen-only
    mode (04) never replies; restart communications (01) replies (unless the slave was
    in listen-only mode) and then restarts.
    """
    machine = _machine(context)
    sub = request.sub_function
    data = request.data
    counter = _COUNTER_OF.get(sub)
    if counter is not None:
        return DiagnosticsResponse(sub, machine.counters.word(counter).to_bytes(2, "big"))
    if sub in (_SUB.RETURN_QUERY_DATA, _SUB.CHANGE_ASCII_INPUT_DELIMITER):
        if sub == _SUB.CHANGE_ASCII_INPUT_DELIMITER:
            machine.ascii_delimiter = data[0]
        return DiagnosticsResponse(sub, data)
    if sub == _SUB.RESTART_COMMUNICATIONS:
        machine.restart_communications(clear_log=data == _CLEAR_LOG)
        return DiagnosticsResponse(sub, data)
    if sub == _SUB.RETURN_DIAGNOSTIC_REGISTER:
        return DiagnosticsResponse(sub, (machine.diagnostic_register & 0xFFFF).to_bytes(2, "big"))
    if sub == _SUB.FORCE_LISTEN_ONLY_MODE:
        machine.enter_listen_only()
        return None
    if sub == _SUB.CLEAR_COUNTERS_AND_DIAGNOSTIC_REGISTER:
        machine.clear_counters()
        return DiagnosticsResponse(sub, data)
    if sub == _SUB.CLEAR_OVERRUN_COUNTER_AND_FLAG:
        machine.counters.bus_character_overrun_count = 0
        return DiagnosticsResponse(sub, data)
    raise ExceptionResponse(ExceptionCode.ILLEGAL_FUNCTION)


_SUB = DiagnosticSubFunction
_CLEAR_LOG = b"\xff\x00"
_COUNTER_OF: Final[Mapping[int, str]] = {
    _SUB.RETURN_BUS_MESSAGE_COUNT: "bus_message_count",
    _SUB.RETURN_BUS_COMMUNICATION_ERROR_COUNT: "bus_communication_error_count",
    _SUB.RETURN_BUS_EXCEPTION_ERROR_COUNT: "bus_exception_error_count",
    _SUB.RETURN_SERVER_MESSAGE_COUNT: "server_message_count",
    _SUB.RETURN_SERVER_NO_RESPONSE_COUNT: "server_no_response_count",
    _SUB.RETURN_SERVER_NAK_COUNT: "server_nak_count",
    _SUB.RETURN_SERVER_BUSY_COUNT: "server_busy_count",
    _SUB.RETURN_BUS_CHARACTER_OVERRUN_COUNT: "bus_character_overrun_count",
}


def get_comm_event_counter(request: GetCommEventCounterRequest, context: RequestContext) -> Answer:
    """0B: the status word (always ready) and the comm event counter."""
    machine = _machine(context)
    return GetCommEventCounterResponse(COMM_EVENT_STATUS_READY, machine.event_log.event_count)


def get_comm_event_log(request: GetCommEventLogRequest, context: RequestContext) -> Answer:
    """0C: status, event counter, bus message count and the event bytes, newest first."""
    machine = _machine(context)
    log = machine.event_log
    return GetCommEventLogResponse(
        COMM_EVENT_STATUS_READY,
        log.event_count,
        machine.counters.word("bus_message_count"),
        log.events(),
    )


def report_server_id(request: ReportServerIdRequest, context: RequestContext) -> Answer:
    """11: the store's server id, run indicator and data; by default the unit address, running."""
    reporter = getattr(context.store, "report_server_id", None)

    def build(found: ServerId | None) -> Answer:
        if found is None:
            found = ServerId(bytes((context.unit,)))
        return ReportServerIdResponse(found.server_id, found.run_indicator, found.additional_data)

    return build(None) if reporter is None else _then(reporter(), build)


def read_device_identification(request: object, context: RequestContext) -> Answer:
    """2B/0E: the store's identification objects (streamed, or one); 01 for other MEI types."""
    if not isinstance(request, ReadDeviceIdentificationRequest):
        raise ExceptionResponse(ExceptionCode.ILLEGAL_FUNCTION)
    getter = _capability(context.store, "device_identification")

    def build(objects: Mapping[int, bytes]) -> Answer:
        reply = answer_device_identification(objects, request.read_code, request.object_id)
        if reply is None:
            raise ExceptionResponse(ExceptionCode.ILLEGAL_DATA_ADDRESS)
        return reply

    return _then(getter(), build)


def _as_handler(function: Callable[[Any, RequestContext], Answer]) -> Handler:
    return function


BUILTIN_HANDLERS: Final[Mapping[int, Handler]] = {
    FunctionCode.READ_COILS: _as_handler(read_coils),
    FunctionCode.READ_DISCRETE_INPUTS: _as_handler(read_discrete_inputs),
    FunctionCode.READ_HOLDING_REGISTERS: _as_handler(read_holding_registers),
    FunctionCode.READ_INPUT_REGISTERS: _as_handler(read_input_registers),
    FunctionCode.WRITE_SINGLE_COIL: _as_handler(write_single_coil),
    FunctionCode.WRITE_SINGLE_REGISTER: _as_handler(write_single_register),
    FunctionCode.READ_EXCEPTION_STATUS: _as_handler(read_exception_status),
    FunctionCode.WRITE_MULTIPLE_COILS: _as_handler(write_multiple_coils),
    FunctionCode.WRITE_MULTIPLE_REGISTERS: _as_handler(write_multiple_registers),
    FunctionCode.MASK_WRITE_REGISTER: _as_handler(mask_write_register),
    FunctionCode.READ_WRITE_MULTIPLE_REGISTERS: _as_handler(read_write_multiple_registers),
    FunctionCode.READ_FIFO_QUEUE: _as_handler(read_fifo_queue),
    FunctionCode.DIAGNOSTICS: _as_handler(diagnostics),
    FunctionCode.GET_COMM_EVENT_COUNTER: _as_handler(get_comm_event_counter),
    FunctionCode.GET_COMM_EVENT_LOG: _as_handler(get_comm_event_log),
    FunctionCode.REPORT_SERVER_ID: _as_handler(report_server_id),
    FunctionCode.READ_FILE_RECORD: _as_handler(read_file_record),
    FunctionCode.WRITE_FILE_RECORD: _as_handler(write_file_record),
    FunctionCode.ENCAPSULATED_INTERFACE_TRANSPORT: _as_handler(read_device_identification),
}
"""The handlers served without registration, by function code."""

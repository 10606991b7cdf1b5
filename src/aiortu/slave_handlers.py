"""The slave's built-in request handlers: one function per public function code it serves.

A handler takes the decoded request and a :class:`RequestContext` (the unit, its data
store, whether the request was broadcast) and returns the response PDU, or ``None`` to
send nothing. It raises :class:`~aiortu.errors.ExceptionResponse` for an exception reply;
the store raises it too (02 for unmapped addresses). User handlers have the same shape
and may be coroutine functions. :data:`BUILTIN_HANDLERS` maps each function code served
here to its handler.
"""

from __future__ import annotations

from collections.abc import Awaitable, Callable, Mapping
from dataclasses import dataclass
from typing import Any, Final

from aiortu.core.codes import ExceptionCode, FunctionCode
from aiortu.core.data_model import DataStore, Table
from aiortu.core.pdu import Response
from aiortu.core.pdu_bits import (
    ReadCoilsRequest,
    ReadCoilsResponse,
    ReadDiscreteInputsRequest,
    ReadDiscreteInputsResponse,
    WriteMultipleCoilsRequest,
    WriteMultipleCoilsResponse,
    WriteSingleCoilRequest,
    WriteSingleCoilResponse,
)
from aiortu.core.pdu_registers import (
    MAX_FIFO_COUNT,
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
from aiortu.core.pdu_serial_line import ReadExceptionStatusRequest, ReadExceptionStatusResponse
from aiortu.errors import ExceptionResponse

__all__ = (
    "BUILTIN_HANDLERS",
    "Handler",
    "HandlerResult",
    "RequestContext",
    "mask_write_register",
    "read_coils",
    "read_discrete_inputs",
    "read_exception_status",
    "read_fifo_queue",
    "read_holding_registers",
    "read_input_registers",
    "read_write_multiple_registers",
    "write_multiple_coils",
    "write_multiple_registers",
    "write_single_coil",
    "write_single_register",
)


@dataclass(frozen=True, slots=True)
class RequestContext:
    """What a handler knows besides the request: the *unit* asked, its *store*, and
    whether the request was a *broadcast* (then the reply is never sent)."""

    unit: int
    store: DataStore
    broadcast: bool = False


HandlerResult = Response | None
"""A handler's answer: the response PDU, or ``None`` to send nothing."""

Handler = Callable[[Any, RequestContext], HandlerResult | Awaitable[HandlerResult]]
"""A request handler, sync or async. Its first argument is the decoded request (a
:class:`~aiortu.core.pdu.RawPDU` for codes without a class of their own)."""


def read_coils(request: ReadCoilsRequest, context: RequestContext) -> ReadCoilsResponse:
    """01: the coils asked for."""
    values = context.store.read(Table.COILS, request.address, request.count)
    return ReadCoilsResponse(tuple(map(bool, values)))


def read_discrete_inputs(
    request: ReadDiscreteInputsRequest, context: RequestContext
) -> ReadDiscreteInputsResponse:
    """02: the discrete inputs asked for."""
    values = context.store.read(Table.DISCRETE_INPUTS, request.address, request.count)
    return ReadDiscreteInputsResponse(tuple(map(bool, values)))


def read_holding_registers(
    request: ReadHoldingRegistersRequest, context: RequestContext
) -> ReadHoldingRegistersResponse:
    """03: the holding registers asked for."""
    values = context.store.read(Table.HOLDING_REGISTERS, request.address, request.count)
    return ReadHoldingRegistersResponse(tuple(values))


def read_input_registers(
    request: ReadInputRegistersRequest, context: RequestContext
) -> ReadInputRegistersResponse:
    """04: the input registers asked for."""
    values = context.store.read(Table.INPUT_REGISTERS, request.address, request.count)
    return ReadInputRegistersResponse(tuple(values))


def write_single_coil(
    request: WriteSingleCoilRequest, context: RequestContext
) -> WriteSingleCoilResponse:
    """05: set one coil; the reply echoes the request."""
    context.store.write(Table.COILS, request.address, (request.value,))
    return WriteSingleCoilResponse(request.address, request.value)


def write_single_register(
    request: WriteSingleRegisterRequest, context: RequestContext
) -> WriteSingleRegisterResponse:
    """06: set one holding register; the reply echoes the request."""
    context.store.write(Table.HOLDING_REGISTERS, request.address, (request.value,))
    return WriteSingleRegisterResponse(request.address, request.value)


def read_exception_status(
    request: ReadExceptionStatusRequest, context: RequestContext
) -> ReadExceptionStatusResponse:
    """07: the store's exception status byte, or 0 for a store without one."""
    reader = getattr(context.store, "read_exception_status", None)
    return ReadExceptionStatusResponse(int(reader()) if reader is not None else 0)


def write_multiple_coils(
    request: WriteMultipleCoilsRequest, context: RequestContext
) -> WriteMultipleCoilsResponse:
    """0F: set consecutive coils."""
    context.store.write(Table.COILS, request.address, request.values)
    return WriteMultipleCoilsResponse(request.address, request.count)


def write_multiple_registers(
    request: WriteMultipleRegistersRequest, context: RequestContext
) -> WriteMultipleRegistersResponse:
    """10: set consecutive holding registers."""
    context.store.write(Table.HOLDING_REGISTERS, request.address, request.values)
    return WriteMultipleRegistersResponse(request.address, request.count)


def mask_write_register(
    request: MaskWriteRegisterRequest, context: RequestContext
) -> MaskWriteRegisterResponse:
    """16: change bits of one holding register; the reply echoes the request."""
    store = context.store
    (current,) = store.read(Table.HOLDING_REGISTERS, request.address, 1)
    store.write(Table.HOLDING_REGISTERS, request.address, (request.apply(current),))
    return MaskWriteRegisterResponse(request.address, request.and_mask, request.or_mask)


def read_write_multiple_registers(
    request: ReadWriteMultipleRegistersRequest, context: RequestContext
) -> ReadWriteMultipleRegistersResponse:
    """17: write, then read, holding registers.

    The read range is checked before anything is written, so a request whose read part
    is unmapped gets 02 and changes nothing.
    """
    store = context.store
    table = Table.HOLDING_REGISTERS
    store.read(table, request.read_address, request.read_count)
    store.write(table, request.write_address, request.values)
    values = store.read(table, request.read_address, request.read_count)
    return ReadWriteMultipleRegistersResponse(tuple(values))


def read_fifo_queue(
    request: ReadFifoQueueRequest, context: RequestContext
) -> ReadFifoQueueResponse:
    """18: the values of a FIFO queue; more than 31 queued gets exception 03, as the spec says."""
    reader = getattr(context.store, "read_fifo_queue", None)
    if reader is None:
        raise ExceptionResponse(ExceptionCode.ILLEGAL_DATA_ADDRESS)
    values = reader(request.address)
    if len(values) > MAX_FIFO_COUNT:
        raise ExceptionResponse(ExceptionCode.ILLEGAL_DATA_VALUE)
    return ReadFifoQueueResponse(tuple(values))


def _as_handler(function: Callable[[Any, RequestContext], Response]) -> Handler:
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
}
"""The handlers served without registration, by function code."""

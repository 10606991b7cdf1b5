# ruff: noqa: ASYNC109
# ``timeout=`` here is the Modbus response timeout, counted from the end of transmission
# by the master; a cancel scope around the call cannot express that.
"""The master's operations, each written once.

[`Operations`][aiortu.master.Master] holds every Modbus function a master offers, as a method
that takes the unit first; [`Master`][aiortu.master.Master] inherits them as they are (its
register read is the method below, with no layer around it). The unit handles, the broadcast
handle and the blocking API are made from these definitions, one line per operation, by the
wrappers in `aiortu.master._handles` and `aiortu.blocking`: their signatures (the unit taken
out) and docstrings come from here.

The operations stand on four methods of the master, declared here and implemented by
[`Master`][aiortu.master.Master]: `request`, `execute`, `send_without_reply`, and `_submit`,
the awaitable of one request with no coroutine of its own, which the register reads use so
that a read is one coroutine (the caller's) waiting on the engine.
"""

from __future__ import annotations

import functools
from abc import abstractmethod
from collections.abc import Awaitable, Iterable, Sequence
from typing import TypeVar

from aiortu.core import pdu
from aiortu.core.codes import DeviceIdReadCode, DiagnosticSubFunction
from aiortu.core.errors import ExceptionResponse, InvalidRequest, MalformedPDU
from aiortu.core.pdu import (
    ExceptionPDU,
    MaskWriteRegisterRequest,
    ReadCoilsRequest,
    ReadCoilsResponse,
    ReadDiscreteInputsRequest,
    ReadFifoQueueRequest,
    ReadFifoQueueResponse,
    ReadHoldingRegistersRequest,
    ReadHoldingRegistersResponse,
    ReadInputRegistersRequest,
    ReadWriteMultipleRegistersRequest,
    Request,
    Response,
    WriteMultipleCoilsRequest,
    WriteMultipleRegistersRequest,
    WriteSingleCoilRequest,
    WriteSingleRegisterRequest,
)
from aiortu.master._arguments import check_coil, check_coils, check_registers
from aiortu.master._records import FileRecordLike, RecordRequestLike, file_records, record_requests

__all__ = (
    "Operations",
    "answer",
    "mask_write_register_request",
    "write_coil_request",
    "write_coils_request",
    "write_file_record_request",
    "write_register_request",
    "write_registers_request",
)

_ResponseT = TypeVar("_ResponseT", bound=Response)
_READ_CACHE_SIZE = 256
"""Read requests of each kind kept made: a poll loop reads the same blocks again and again,
and a request (immutable) is encoded once. A hit in the cache (functools' C code) makes no
Python call; a miss, or arguments of another type (`typed`: `1.0` and `True` are not `1`),
runs the constructor, which checks them. Unhashable arguments miss the cache by a TypeError
and meet the constructor's check too (see the reads)."""

_coils_reads = functools.lru_cache(_READ_CACHE_SIZE, typed=True)(ReadCoilsRequest)
_inputs_reads = functools.lru_cache(_READ_CACHE_SIZE, typed=True)(ReadDiscreteInputsRequest)
_holding_reads = functools.lru_cache(_READ_CACHE_SIZE, typed=True)(ReadHoldingRegistersRequest)
_input_register_reads = functools.lru_cache(_READ_CACHE_SIZE, typed=True)(ReadInputRegistersRequest)

_MAX_DEVICE_ID_READS = 256
"""A device cannot stream more objects than there are ids; stop a looping one there."""


def answer(
    response: Response | ExceptionPDU | None, pdu: Request, unit: int, expected: type[_ResponseT]
) -> _ResponseT:
    """`response` as the reply to `pdu`; raise ExceptionResponse for an exception reply
    and MalformedPDU for a reply of another kind."""
    if isinstance(response, ExceptionPDU):
        raise ExceptionResponse(response.exception_code, pdu.function_code, unit)
    if not isinstance(response, expected):
        raise MalformedPDU(f"{type(response).__name__} does not answer {type(pdu).__name__}")
    return response


# -- the requests of the writes a broadcast may carry, checked ---------------------------


def write_coil_request(address: int, value: bool) -> WriteSingleCoilRequest:
    """The request of write single coil (05), its arguments checked."""
    return WriteSingleCoilRequest(address, check_coil(value))


def write_coils_request(address: int, values: Sequence[bool]) -> WriteMultipleCoilsRequest:
    """The request of write multiple coils (0F), its arguments checked."""
    return WriteMultipleCoilsRequest(address, check_coils(values))


def write_register_request(address: int, value: int) -> WriteSingleRegisterRequest:
    """The request of write single register (06), its arguments checked."""
    return WriteSingleRegisterRequest(address, value)  # checks the value's type


def write_registers_request(address: int, values: Sequence[int]) -> WriteMultipleRegistersRequest:
    """The request of write multiple registers (10), its arguments checked."""
    return WriteMultipleRegistersRequest(address, check_registers("values", values))


def mask_write_register_request(
    address: int, and_mask: int, or_mask: int
) -> MaskWriteRegisterRequest:
    """The request of mask write register (16), its arguments checked."""
    return MaskWriteRegisterRequest(address, and_mask, or_mask)


def write_file_record_request(
    records: Iterable[FileRecordLike],
) -> pdu.WriteFileRecordRequest:
    """The request of write file record (15), its arguments checked."""
    return pdu.WriteFileRecordRequest(file_records(records))


class Operations:
    """The Modbus functions of a master (see the module): every method takes the unit first,
    and `timeout=` (this call's response timeout) and `priority=` (lower goes first)."""

    # -- what the operations stand on (implemented by Master) ------------------------

    @abstractmethod
    async def request(
        self,
        unit: int,
        pdu: Request,
        expected: type[_ResponseT],
        *,
        timeout: float | None = None,
        priority: int = 0,
        retries: int | None = None,
    ) -> _ResponseT:
        """Send `pdu`, raise ExceptionResponse for an exception reply, return the reply."""

    @abstractmethod
    async def execute(
        self, unit: int, pdu: Request, *, timeout: float | None = None, priority: int = 0
    ) -> Response | ExceptionPDU:
        """Send any request PDU and return the reply as it came, an exception reply included."""

    @abstractmethod
    async def send_without_reply(self, unit: int, pdu: Request, *, priority: int = 0) -> None:
        """Send `pdu` to `unit` (0 broadcasts it), then wait the turnaround delay."""

    @abstractmethod
    def _submit(
        self, unit: int, request: Request, timeout: float | None, priority: int
    ) -> Awaitable[Response | ExceptionPDU | None]:
        """The engine's awaitable of `request`, the unit and the timeout checked."""

    # -- bits ------------------------------------------------------------------------

    async def read_coils(
        self,
        unit: int,
        address: int,
        count: int,
        *,
        timeout: float | None = None,
        priority: int = 0,
    ) -> list[bool]:
        """Read `count` (1..2000) coils from `address` (01)."""
        try:
            request = _coils_reads(address, count)
        except TypeError:  # unhashable: the constructor says what is wrong
            request = ReadCoilsRequest(address, count)
        response = await self._submit(unit, request, timeout, priority)
        return request.bits_of(answer(response, request, unit, ReadCoilsResponse))

    async def read_discrete_inputs(
        self,
        unit: int,
        address: int,
        count: int,
        *,
        timeout: float | None = None,
        priority: int = 0,
    ) -> list[bool]:
        """Read `count` (1..2000) discrete inputs from `address` (02)."""
        try:
            request = _inputs_reads(address, count)
        except TypeError:  # unhashable: the constructor says what is wrong
            request = ReadDiscreteInputsRequest(address, count)
        response = await self._submit(unit, request, timeout, priority)
        return request.bits_of(answer(response, request, unit, ReadCoilsResponse))

    async def write_coil(
        self,
        unit: int,
        address: int,
        value: bool,
        *,
        timeout: float | None = None,
        priority: int = 0,
    ) -> None:
        """Set the coil at `address` on or off (05); the echo is verified.

        `value` is a bool, 1 or 0, or the spec's encoding 0xFF00 or 0x0000; anything
        else (`"off"` is true to Python) raises InvalidRequest.
        """
        request = write_coil_request(address, value)
        await self.request(unit, request, Response, timeout=timeout, priority=priority)

    async def write_coils(
        self,
        unit: int,
        address: int,
        values: Sequence[bool],
        *,
        timeout: float | None = None,
        priority: int = 0,
    ) -> None:
        """Set 1..1968 coils from `address` (0F), each a bool, 1 or 0; the reply's address
        and count are verified."""
        request = write_coils_request(address, values)
        await self.request(unit, request, Response, timeout=timeout, priority=priority)

    # -- registers -------------------------------------------------------------------

    async def read_holding_registers(
        self,
        unit: int,
        address: int,
        count: int,
        *,
        timeout: float | None = None,
        priority: int = 0,
    ) -> list[int]:
        """Read `count` (1..125) holding registers from `address` (03)."""
        try:
            request = _holding_reads(address, count)
        except TypeError:  # unhashable: the constructor says what is wrong
            request = ReadHoldingRegistersRequest(address, count)
        response = await self._submit(unit, request, timeout, priority)
        return list(answer(response, request, unit, ReadHoldingRegistersResponse).values)

    async def read_input_registers(
        self,
        unit: int,
        address: int,
        count: int,
        *,
        timeout: float | None = None,
        priority: int = 0,
    ) -> list[int]:
        """Read `count` (1..125) input registers from `address` (04)."""
        try:
            request = _input_register_reads(address, count)
        except TypeError:  # unhashable: the constructor says what is wrong
            request = ReadInputRegistersRequest(address, count)
        response = await self._submit(unit, request, timeout, priority)
        return list(answer(response, request, unit, ReadHoldingRegistersResponse).values)

    async def write_register(
        self,
        unit: int,
        address: int,
        value: int,
        *,
        timeout: float | None = None,
        priority: int = 0,
    ) -> None:
        """Write `value` (0..65535) to the holding register at `address` (06); echo verified."""
        request = write_register_request(address, value)
        await self.request(unit, request, Response, timeout=timeout, priority=priority)

    async def write_registers(
        self,
        unit: int,
        address: int,
        values: Sequence[int],
        *,
        timeout: float | None = None,
        priority: int = 0,
    ) -> None:
        """Write 1..123 registers from `address` (10); the echoed address and count are checked."""
        request = write_registers_request(address, values)
        await self.request(unit, request, Response, timeout=timeout, priority=priority)

    async def mask_write_register(
        self,
        unit: int,
        address: int,
        and_mask: int,
        or_mask: int,
        *,
        timeout: float | None = None,
        priority: int = 0,
    ) -> None:
        """Mask write the register at `address` (16): it becomes
        `(current & and_mask) | (or_mask & ~and_mask)`; the echo is verified."""
        request = mask_write_register_request(address, and_mask, or_mask)
        await self.request(unit, request, Response, timeout=timeout, priority=priority)

    async def read_write_registers(
        self,
        unit: int,
        read_address: int,
        read_count: int,
        write_address: int,
        values: Sequence[int],
        *,
        timeout: float | None = None,
        priority: int = 0,
    ) -> list[int]:
        """Write `values` from `write_address`, then read `read_count` registers (17)."""
        request = ReadWriteMultipleRegistersRequest(
            read_address, read_count, write_address, check_registers("values", values)
        )
        reply = await self.request(
            unit, request, ReadHoldingRegistersResponse, timeout=timeout, priority=priority
        )
        return list(reply.values)

    async def read_fifo_queue(
        self, unit: int, address: int, *, timeout: float | None = None, priority: int = 0
    ) -> list[int]:
        """Read the 0..31 values queued in the FIFO whose pointer is at `address` (18)."""
        request = ReadFifoQueueRequest(address)
        reply = await self.request(
            unit, request, ReadFifoQueueResponse, timeout=timeout, priority=priority
        )
        return list(reply.values)

    # -- file records ----------------------------------------------------------------

    async def read_file_record(
        self,
        unit: int,
        sub_requests: Iterable[RecordRequestLike],
        *,
        timeout: float | None = None,
        priority: int = 0,
    ) -> list[list[int]]:
        """Read file records (14): one list of values per sub-request, in order.

        Each sub-request is a [`FileRecordRequest`][aiortu.core.pdu.FileRecordRequest] or a
        `(file_number, record_number, record_length)` tuple.
        """
        request = pdu.ReadFileRecordRequest(record_requests(sub_requests))
        reply = await self.request(
            unit, request, pdu.ReadFileRecordResponse, timeout=timeout, priority=priority
        )
        return [list(values) for values in reply.records]

    async def write_file_record(
        self,
        unit: int,
        records: Iterable[FileRecordLike],
        *,
        timeout: float | None = None,
        priority: int = 0,
    ) -> None:
        """Write file records (15); the echo is verified.

        Each record is a [`FileRecord`][aiortu.core.pdu.FileRecord] or a
        `(file_number, record_number, values)` tuple.
        """
        request = write_file_record_request(records)
        await self.request(unit, request, Response, timeout=timeout, priority=priority)

    # -- serial line functions -------------------------------------------------------

    async def read_exception_status(
        self, unit: int, *, timeout: float | None = None, priority: int = 0
    ) -> int:
        """Read the eight exception status bits of the device as one byte (07)."""
        reply = await self.request(
            unit,
            pdu.ReadExceptionStatusRequest(),
            pdu.ReadExceptionStatusResponse,
            timeout=timeout,
            priority=priority,
        )
        return reply.status

    async def diagnostics(
        self,
        unit: int,
        sub_function: int,
        data: bytes = b"\x00\x00",
        *,
        timeout: float | None = None,
        priority: int = 0,
    ) -> pdu.DiagnosticsResponse | None:
        """Run diagnostics `sub_function` with `data` (08); return the reply.

        Force listen-only mode (04) gets no reply: it is sent, followed by the turnaround
        delay, and `None` is returned.
        """
        if not isinstance(data, bytes | bytearray | memoryview):
            raise InvalidRequest("data", data, "bytes")
        request = pdu.DiagnosticsRequest(sub_function, data)
        if request.sub_function == DiagnosticSubFunction.FORCE_LISTEN_ONLY_MODE:
            await self.send_without_reply(unit, request, priority=priority)
            return None
        return await self.request(
            unit,
            request,
            pdu.DiagnosticsResponse,
            timeout=timeout,
            priority=priority,
        )

    async def get_comm_event_counter(
        self, unit: int, *, timeout: float | None = None, priority: int = 0
    ) -> pdu.GetCommEventCounterResponse:
        """Read the status word and the event counter of the device (0B)."""
        return await self.request(
            unit,
            pdu.GetCommEventCounterRequest(),
            pdu.GetCommEventCounterResponse,
            timeout=timeout,
            priority=priority,
        )

    async def get_comm_event_log(
        self, unit: int, *, timeout: float | None = None, priority: int = 0
    ) -> pdu.GetCommEventLogResponse:
        """Read the status, the counters and the event log of the device (0C)."""
        return await self.request(
            unit,
            pdu.GetCommEventLogRequest(),
            pdu.GetCommEventLogResponse,
            timeout=timeout,
            priority=priority,
        )

    async def report_server_id(
        self, unit: int, *, timeout: float | None = None, priority: int = 0
    ) -> pdu.ReportServerIdResponse:
        """Read the device's server id, run indicator and additional data (11)."""
        return await self.request(
            unit,
            pdu.ReportServerIdRequest(),
            pdu.ReportServerIdResponse,
            timeout=timeout,
            priority=priority,
        )

    async def read_device_identification(
        self,
        unit: int,
        read_code: int = DeviceIdReadCode.BASIC,
        object_id: int = 0,
        *,
        timeout: float | None = None,
        priority: int = 0,
    ) -> dict[int, bytes]:
        """Read the device identification objects (2B/0E) as `{object id: value}`.

        Stream reads (basic, regular, extended) follow "more follows" until the device
        has sent everything; an individual read (4) returns the one object.
        """
        objects: dict[int, bytes] = {}
        next_id = object_id
        for _ in range(_MAX_DEVICE_ID_READS):
            request = pdu.ReadDeviceIdentificationRequest(read_code, next_id)
            reply = await self.request(
                unit,
                request,
                pdu.ReadDeviceIdentificationResponse,
                timeout=timeout,
                priority=priority,
            )
            objects.update(reply.objects)
            if not reply.more_follows or request.read_code == DeviceIdReadCode.INDIVIDUAL:
                return objects
            if reply.next_object_id in objects or not reply.objects:
                raise MalformedPDU(
                    "device identification does not advance",
                    field="next_object_id",
                    value=reply.next_object_id,
                    allowed="an object id not read yet",
                )
            next_id = reply.next_object_id
        raise MalformedPDU("device identification never ends")

# ruff: noqa: ASYNC109
# ``timeout=`` here is the Modbus response timeout, counted from the end of transmission
# by the master; a cancel scope around the call cannot express that.
"""The master's file record, serial-line and device identification functions.

`SerialLineFunctions` is a base class of [`Master`][aiortu.master.Master]; it holds
the function codes beyond the four tables (14, 15, 07, 08, 0B, 0C, 11, 2B/0E), written
on top of the master's [`request`][aiortu.master.Master.request], so that `master.py` stays
about the tables, the lifetime and the core of every call. Its methods need of `self`
only what `Requester` names, so this module never imports the
class built on it.
"""

from __future__ import annotations

from collections.abc import Iterable
from typing import TypeVar

from aiortu.core import pdu as pdu_device_id
from aiortu.core import pdu as pdu_files
from aiortu.core import pdu as pdu_serial_line
from aiortu.core.codes import DeviceIdReadCode, DiagnosticSubFunction
from aiortu.core.pdu import Response
from aiortu.errors import InvalidRequest, MalformedPDU
from aiortu.master._calls import FileRecordLike, RecordRequestLike, Requester
from aiortu.master._handles import file_records, record_requests

__all__ = ("SerialLineFunctions",)

_ResponseT = TypeVar("_ResponseT", bound=Response)

_MAX_DEVICE_ID_READS = 256
"""A device cannot stream more objects than there are ids; stop a looping one there."""


class SerialLineFunctions:
    """File records, serial-line functions and device identification (see the module).

    Every method takes the unit first, and `timeout=` and `priority=` as the
    master's other methods do.
    """

    # -- file records ----------------------------------------------------------------

    async def read_file_record(
        self: Requester,
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
        request = pdu_files.ReadFileRecordRequest(record_requests(sub_requests))
        reply = await self.request(
            unit,
            request,
            pdu_files.ReadFileRecordResponse,
            timeout=timeout,
            priority=priority,
        )
        return [list(values) for values in reply.records]

    async def write_file_record(
        self: Requester,
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
        request = pdu_files.WriteFileRecordRequest(file_records(records))
        await self.request(unit, request, Response, timeout=timeout, priority=priority)

    # -- serial line functions -------------------------------------------------------

    async def read_exception_status(
        self: Requester, unit: int, *, timeout: float | None = None, priority: int = 0
    ) -> int:
        """Read the eight exception status bits of the device as one byte (07)."""
        reply = await self.request(
            unit,
            pdu_serial_line.ReadExceptionStatusRequest(),
            pdu_serial_line.ReadExceptionStatusResponse,
            timeout=timeout,
            priority=priority,
        )
        return reply.status

    async def diagnostics(
        self: Requester,
        unit: int,
        sub_function: int,
        data: bytes = b"\x00\x00",
        *,
        timeout: float | None = None,
        priority: int = 0,
    ) -> pdu_serial_line.DiagnosticsResponse | None:
        """Run diagnostics `sub_function` with `data` (08); return the reply.

        Force listen-only mode (04) gets no reply: it is sent, followed by the turnaround
        delay, and `None` is returned.
        """
        if not isinstance(data, bytes | bytearray | memoryview):
            raise InvalidRequest("data", data, "bytes")
        request = pdu_serial_line.DiagnosticsRequest(sub_function, data)
        if request.sub_function == DiagnosticSubFunction.FORCE_LISTEN_ONLY_MODE:
            await self.send_without_reply(unit, request, priority=priority)
            return None
        return await self.request(
            unit,
            request,
            pdu_serial_line.DiagnosticsResponse,
            timeout=timeout,
            priority=priority,
        )

    async def get_comm_event_counter(
        self: Requester, unit: int, *, timeout: float | None = None, priority: int = 0
    ) -> pdu_serial_line.GetCommEventCounterResponse:
        """Read the status word and the event counter of the device (0B)."""
        return await self.request(
            unit,
            pdu_serial_line.GetCommEventCounterRequest(),
            pdu_serial_line.GetCommEventCounterResponse,
            timeout=timeout,
            priority=priority,
        )

    async def get_comm_event_log(
        self: Requester, unit: int, *, timeout: float | None = None, priority: int = 0
    ) -> pdu_serial_line.GetCommEventLogResponse:
        """Read the status, the counters and the event log of the device (0C)."""
        return await self.request(
            unit,
            pdu_serial_line.GetCommEventLogRequest(),
            pdu_serial_line.GetCommEventLogResponse,
            timeout=timeout,
            priority=priority,
        )

    async def report_server_id(
        self: Requester, unit: int, *, timeout: float | None = None, priority: int = 0
    ) -> pdu_serial_line.ReportServerIdResponse:
        """Read the device's server id, run indicator and additional data (11)."""
        return await self.request(
            unit,
            pdu_serial_line.ReportServerIdRequest(),
            pdu_serial_line.ReportServerIdResponse,
            timeout=timeout,
            priority=priority,
        )

    async def read_device_identification(
        self: Requester,
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
            request = pdu_device_id.ReadDeviceIdentificationRequest(read_code, next_id)
            reply = await self.request(
                unit,
                request,
                pdu_device_id.ReadDeviceIdentificationResponse,
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

# ruff: noqa: ASYNC109
# ``timeout=`` here is the Modbus response timeout, counted from the end of transmission
# by the master; a cancel scope around the call cannot express that.
"""What the master's helpers need of a master, as protocols: the serial-line functions
(`SerialLineFunctions`, a base class of
[`Master`][aiortu.master.Master]) build on `Requester`; the unit handles
([`UnitHandle`][aiortu.master.UnitHandle]) on `MasterCalls`.

They live below the client so that the helpers never import the class built on them:
the master's modules form no import cycle, type-checking imports included.
"""

from __future__ import annotations

from collections.abc import Iterable, Sequence
from typing import Protocol, TypeVar

from aiortu.core import pdu as pdu_files
from aiortu.core.codes import DeviceIdReadCode
from aiortu.core.pdu import (
    DiagnosticsResponse,
    ExceptionPDU,
    GetCommEventCounterResponse,
    GetCommEventLogResponse,
    ReportServerIdResponse,
    Request,
    Response,
)

__all__ = ("FileRecordLike", "MasterCalls", "RecordRequestLike", "Requester")

_ResponseT = TypeVar("_ResponseT", bound=Response)

RecordRequestLike = pdu_files.FileRecordRequest | tuple[int, int, int]
"""A read file record sub-request: the class, or `(file, record, length)`."""

FileRecordLike = pdu_files.FileRecord | tuple[int, int, Sequence[int]]
"""A write file record sub-record: the class, or `(file, record, values)`."""


class Requester(Protocol):
    """A master's core: send a request and return its reply, or send one without reply."""

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
        """See [`aiortu.master.Master.request`][aiortu.master.Master.request]."""
        ...

    async def send_without_reply(self, unit: int, pdu: Request, *, priority: int = 0) -> None:
        """See
        [`aiortu.master.Master.send_without_reply`][aiortu.master.Master.send_without_reply]."""
        ...


class MasterCalls(Requester, Protocol):
    """The master's methods a unit handle binds to one unit (see
    [`Master`][aiortu.master.Master] for each)."""

    async def read_coils(
        self,
        unit: int,
        address: int,
        count: int,
        *,
        timeout: float | None = None,
        priority: int = 0,
    ) -> list[bool]: ...

    async def read_discrete_inputs(
        self,
        unit: int,
        address: int,
        count: int,
        *,
        timeout: float | None = None,
        priority: int = 0,
    ) -> list[bool]: ...

    async def read_holding_registers(
        self,
        unit: int,
        address: int,
        count: int,
        *,
        timeout: float | None = None,
        priority: int = 0,
    ) -> list[int]: ...

    async def read_input_registers(
        self,
        unit: int,
        address: int,
        count: int,
        *,
        timeout: float | None = None,
        priority: int = 0,
    ) -> list[int]: ...

    async def write_coil(
        self,
        unit: int,
        address: int,
        value: bool,
        *,
        timeout: float | None = None,
        priority: int = 0,
    ) -> None: ...

    async def write_coils(
        self,
        unit: int,
        address: int,
        values: Sequence[bool],
        *,
        timeout: float | None = None,
        priority: int = 0,
    ) -> None: ...

    async def write_register(
        self,
        unit: int,
        address: int,
        value: int,
        *,
        timeout: float | None = None,
        priority: int = 0,
    ) -> None: ...

    async def write_registers(
        self,
        unit: int,
        address: int,
        values: Sequence[int],
        *,
        timeout: float | None = None,
        priority: int = 0,
    ) -> None: ...

    async def mask_write_register(
        self,
        unit: int,
        address: int,
        and_mask: int,
        or_mask: int,
        *,
        timeout: float | None = None,
        priority: int = 0,
    ) -> None: ...

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
    ) -> list[int]: ...

    async def read_fifo_queue(
        self, unit: int, address: int, *, timeout: float | None = None, priority: int = 0
    ) -> list[int]: ...

    async def read_file_record(
        self,
        unit: int,
        sub_requests: Iterable[RecordRequestLike],
        *,
        timeout: float | None = None,
        priority: int = 0,
    ) -> list[list[int]]: ...

    async def write_file_record(
        self,
        unit: int,
        records: Iterable[FileRecordLike],
        *,
        timeout: float | None = None,
        priority: int = 0,
    ) -> None: ...

    async def read_exception_status(
        self, unit: int, *, timeout: float | None = None, priority: int = 0
    ) -> int: ...

    async def diagnostics(
        self,
        unit: int,
        sub_function: int,
        data: bytes = b"\x00\x00",
        *,
        timeout: float | None = None,
        priority: int = 0,
    ) -> DiagnosticsResponse | None: ...

    async def get_comm_event_counter(
        self, unit: int, *, timeout: float | None = None, priority: int = 0
    ) -> GetCommEventCounterResponse: ...

    async def get_comm_event_log(
        self, unit: int, *, timeout: float | None = None, priority: int = 0
    ) -> GetCommEventLogResponse: ...

    async def report_server_id(
        self, unit: int, *, timeout: float | None = None, priority: int = 0
    ) -> ReportServerIdResponse: ...

    async def read_device_identification(
        self,
        unit: int,
        read_code: int = DeviceIdReadCode.BASIC,
        object_id: int = 0,
        *,
        timeout: float | None = None,
        priority: int = 0,
    ) -> dict[int, bytes]: ...

    async def execute(
        self, unit: int, pdu: Request, *, timeout: float | None = None, priority: int = 0
    ) -> Response | ExceptionPDU: ...

# ruff: noqa: ASYNC109
# ``timeout=`` here is the Modbus response timeout, counted from the end of transmission
# by the master; a cancel scope around the call cannot express that.
"""Handles on a [`Master`][aiortu.master.Master]: one unit, or every unit at once (broadcast).

[`UnitHandle`][aiortu.master.UnitHandle] (`master.slave(17)`) has the master's methods without the
unit, and typed values on top: 32-bit integers, floats and strings in holding or input registers, in
any word layout ([`aiortu.core.model`][aiortu.core.model]), and reads by reference (`"40108"`,
[`aiortu.core.model`][aiortu.core.model]).

[`BroadcastHandle`][aiortu.master.BroadcastHandle] (`master.broadcast`) has the writes the spec lets
be broadcast: each goes to unit 0, no reply is awaited, and the line waits the turnaround delay so
that the slaves can execute it.
"""

from __future__ import annotations

from collections.abc import Iterable, Sequence

from aiortu.core import pdu as pdu_files
from aiortu.core.codes import BROADCAST_UNIT, DeviceIdReadCode
from aiortu.core.errors import InvalidRequest
from aiortu.core.model import (
    Layout,
    Table,
    ValueType,
    as_layout,
    as_value_type,
    check_encoding,
    decode_value,
    encode_value,
    parse_reference,
    registers_to_string,
    string_to_registers,
)
from aiortu.core.pdu import (
    DiagnosticsResponse,
    ExceptionPDU,
    GetCommEventCounterResponse,
    GetCommEventLogResponse,
    MaskWriteRegisterRequest,
    ReportServerIdResponse,
    Request,
    Response,
    WriteMultipleCoilsRequest,
    WriteMultipleRegistersRequest,
    WriteSingleCoilRequest,
    WriteSingleRegisterRequest,
)
from aiortu.master._arguments import (
    check_coil,
    check_coils,
    check_int,
    check_items,
    check_registers,
)
from aiortu.master._calls import FileRecordLike, MasterCalls, RecordRequestLike, Requester

__all__ = (
    "BroadcastHandle",
    "FileRecordLike",
    "RecordRequestLike",
    "UnitHandle",
    "as_file_record",
    "as_record_request",
    "file_records",
    "record_requests",
)

_REGISTER_TABLES = {
    "holding": Table.HOLDING_REGISTERS,
    "input": Table.INPUT_REGISTERS,
    Table.HOLDING_REGISTERS: Table.HOLDING_REGISTERS,
    Table.INPUT_REGISTERS: Table.INPUT_REGISTERS,
}


def _fields(name: str, item: object, kind: type, names: tuple[str, str, str]) -> tuple[object, ...]:
    """The three fields of `item`, an instance of `kind` or a tuple of three."""
    if isinstance(item, kind):
        return tuple(getattr(item, field) for field in names)
    if not isinstance(item, tuple | list) or len(item) != 3:
        raise InvalidRequest(name, item, f"a {kind.__name__} or ({', '.join(names)})")
    return tuple(item)


def as_record_request(sub: RecordRequestLike) -> pdu_files.FileRecordRequest:
    """A read file record sub-request from the class or a `(file, record, length)` tuple."""
    names = ("file_number", "record_number", "record_length")
    fields = _fields("sub_request", sub, pdu_files.FileRecordRequest, names)
    for name, value in zip(names, fields, strict=True):
        check_int(name, value, range(0x10000), InvalidRequest)
    if isinstance(sub, pdu_files.FileRecordRequest):
        return sub
    return pdu_files.FileRecordRequest(*sub)


def as_file_record(record: FileRecordLike) -> pdu_files.FileRecord:
    """A write file record sub-record from the class or a `(file, record, values)` tuple."""
    names = ("file_number", "record_number", "values")
    file_number, record_number, values = _fields("record", record, pdu_files.FileRecord, names)
    check_int("file_number", file_number, range(0x10000), InvalidRequest)
    check_int("record_number", record_number, range(0x10000), InvalidRequest)
    return pdu_files.FileRecord(
        file_number,  # type: ignore[arg-type]  # checked above
        record_number,  # type: ignore[arg-type]
        check_registers("values", values),
    )


def record_requests(sub_requests: object) -> tuple[pdu_files.FileRecordRequest, ...]:
    """The sub-requests of a read file record (14), each checked."""
    items = check_items("sub_requests", sub_requests, "an iterable of sub-requests")
    return tuple(as_record_request(sub) for sub in items)  # type: ignore[arg-type]


def file_records(records: object) -> tuple[pdu_files.FileRecord, ...]:
    """The sub-records of a write file record (15), each checked."""
    items = check_items("records", records, "an iterable of records")
    return tuple(as_file_record(record) for record in items)  # type: ignore[arg-type]


class BroadcastHandle:
    """The broadcast writes of a master (see the module docstring); each returns once the
    request is sent and the turnaround delay has passed."""

    def __init__(self, master: Requester) -> None:
        self._master = master

    async def write_coil(self, address: int, value: bool, *, priority: int = 0) -> None:
        """Set the coil at `address` on every unit (05)."""
        request = WriteSingleCoilRequest(address, check_coil(value))
        await self._master.send_without_reply(BROADCAST_UNIT, request, priority=priority)

    async def write_register(self, address: int, value: int, *, priority: int = 0) -> None:
        """Write the holding register at `address` on every unit (06)."""
        request = WriteSingleRegisterRequest(address, value)
        await self._master.send_without_reply(BROADCAST_UNIT, request, priority=priority)

    async def write_coils(self, address: int, values: Sequence[bool], *, priority: int = 0) -> None:
        """Set 1..1968 coils from `address` on every unit (0F)."""
        request = WriteMultipleCoilsRequest(address, check_coils(values))
        await self._master.send_without_reply(BROADCAST_UNIT, request, priority=priority)

    async def write_registers(
        self, address: int, values: Sequence[int], *, priority: int = 0
    ) -> None:
        """Write 1..123 registers from `address` on every unit (10)."""
        request = WriteMultipleRegistersRequest(address, check_registers("values", values))
        await self._master.send_without_reply(BROADCAST_UNIT, request, priority=priority)

    async def mask_write_register(
        self, address: int, and_mask: int, or_mask: int, *, priority: int = 0
    ) -> None:
        """Mask write the register at `address` on every unit (16)."""
        request = MaskWriteRegisterRequest(address, and_mask, or_mask)
        await self._master.send_without_reply(BROADCAST_UNIT, request, priority=priority)

    async def write_file_record(
        self, records: Iterable[FileRecordLike], *, priority: int = 0
    ) -> None:
        """Write file records on every unit (15)."""
        request = pdu_files.WriteFileRecordRequest(file_records(records))
        await self._master.send_without_reply(BROADCAST_UNIT, request, priority=priority)


class UnitHandle:
    """One unit of a master: `master.slave(unit)` (see the module docstring).

    Every method takes `timeout=` and `priority=` as the master's do.
    """

    def __init__(self, master: MasterCalls, unit: int) -> None:
        self.master = master
        self.unit = unit

    # -- the master's methods, bound to the unit -------------------------------------

    async def read_coils(
        self, address: int, count: int, *, timeout: float | None = None, priority: int = 0
    ) -> list[bool]:
        """See [Master.read_coils][aiortu.master.Master.read_coils]."""
        return await self.master.read_coils(
            self.unit, address, count, timeout=timeout, priority=priority
        )

    async def read_discrete_inputs(
        self, address: int, count: int, *, timeout: float | None = None, priority: int = 0
    ) -> list[bool]:
        """See
        [`aiortu.master.Master.read_discrete_inputs`][aiortu.master.Master.read_discrete_inputs]."""
        return await self.master.read_discrete_inputs(
            self.unit, address, count, timeout=timeout, priority=priority
        )

    async def read_holding_registers(
        self, address: int, count: int, *, timeout: float | None = None, priority: int = 0
    ) -> list[int]:
        """See
        [`aiortu.master.Master.read_holding_registers`][aiortu.master.Master.read_holding_registers]."""
        return await self.master.read_holding_registers(
            self.unit, address, count, timeout=timeout, priority=priority
        )

    async def read_input_registers(
        self, address: int, count: int, *, timeout: float | None = None, priority: int = 0
    ) -> list[int]:
        """See
        [`aiortu.master.Master.read_input_registers`][aiortu.master.Master.read_input_registers]."""
        return await self.master.read_input_registers(
            self.unit, address, count, timeout=timeout, priority=priority
        )

    async def write_coil(
        self, address: int, value: bool, *, timeout: float | None = None, priority: int = 0
    ) -> None:
        """See [`aiortu.master.Master.write_coil`][aiortu.master.Master.write_coil]."""
        await self.master.write_coil(self.unit, address, value, timeout=timeout, priority=priority)

    async def write_coils(
        self,
        address: int,
        values: Sequence[bool],
        *,
        timeout: float | None = None,
        priority: int = 0,
    ) -> None:
        """See [`aiortu.master.Master.write_coils`][aiortu.master.Master.write_coils]."""
        await self.master.write_coils(
            self.unit, address, values, timeout=timeout, priority=priority
        )

    async def write_register(
        self, address: int, value: int, *, timeout: float | None = None, priority: int = 0
    ) -> None:
        """See [`aiortu.master.Master.write_register`][aiortu.master.Master.write_register]."""
        await self.master.write_register(
            self.unit, address, value, timeout=timeout, priority=priority
        )

    async def write_registers(
        self,
        address: int,
        values: Sequence[int],
        *,
        timeout: float | None = None,
        priority: int = 0,
    ) -> None:
        """See [`aiortu.master.Master.write_registers`][aiortu.master.Master.write_registers]."""
        await self.master.write_registers(
            self.unit, address, values, timeout=timeout, priority=priority
        )

    async def mask_write_register(
        self,
        address: int,
        and_mask: int,
        or_mask: int,
        *,
        timeout: float | None = None,
        priority: int = 0,
    ) -> None:
        """See
        [`aiortu.master.Master.mask_write_register`][aiortu.master.Master.mask_write_register]."""
        await self.master.mask_write_register(
            self.unit, address, and_mask, or_mask, timeout=timeout, priority=priority
        )

    async def read_write_registers(
        self,
        read_address: int,
        read_count: int,
        write_address: int,
        values: Sequence[int],
        *,
        timeout: float | None = None,
        priority: int = 0,
    ) -> list[int]:
        """See
        [`aiortu.master.Master.read_write_registers`][aiortu.master.Master.read_write_registers]."""
        return await self.master.read_write_registers(
            self.unit,
            read_address,
            read_count,
            write_address,
            values,
            timeout=timeout,
            priority=priority,
        )

    async def read_fifo_queue(
        self, address: int, *, timeout: float | None = None, priority: int = 0
    ) -> list[int]:
        """See [`aiortu.master.Master.read_fifo_queue`][aiortu.master.Master.read_fifo_queue]."""
        return await self.master.read_fifo_queue(
            self.unit, address, timeout=timeout, priority=priority
        )

    async def read_file_record(
        self,
        sub_requests: Iterable[RecordRequestLike],
        *,
        timeout: float | None = None,
        priority: int = 0,
    ) -> list[list[int]]:
        """See [`aiortu.master.Master.read_file_record`][aiortu.master.Master.read_file_record]."""
        return await self.master.read_file_record(
            self.unit, sub_requests, timeout=timeout, priority=priority
        )

    async def write_file_record(
        self,
        records: Iterable[FileRecordLike],
        *,
        timeout: float | None = None,
        priority: int = 0,
    ) -> None:
        """See
        [`aiortu.master.Master.write_file_record`][aiortu.master.Master.write_file_record]."""
        await self.master.write_file_record(self.unit, records, timeout=timeout, priority=priority)

    async def read_exception_status(
        self, *, timeout: float | None = None, priority: int = 0
    ) -> int:
        """See
        [`aiortu.master.Master.read_exception_status`][aiortu.master.Master.read_exception_status]."""
        return await self.master.read_exception_status(
            self.unit, timeout=timeout, priority=priority
        )

    async def diagnostics(
        self,
        sub_function: int,
        data: bytes = b"\x00\x00",
        *,
        timeout: float | None = None,
        priority: int = 0,
    ) -> DiagnosticsResponse | None:
        """See [`aiortu.master.Master.diagnostics`][aiortu.master.Master.diagnostics]."""
        return await self.master.diagnostics(
            self.unit, sub_function, data, timeout=timeout, priority=priority
        )

    async def get_comm_event_counter(
        self, *, timeout: float | None = None, priority: int = 0
    ) -> GetCommEventCounterResponse:
        """See
        [`aiortu.master.Master.get_comm_event_counter`][aiortu.master.Master.get_comm_event_counter]."""
        return await self.master.get_comm_event_counter(
            self.unit, timeout=timeout, priority=priority
        )

    async def get_comm_event_log(
        self, *, timeout: float | None = None, priority: int = 0
    ) -> GetCommEventLogResponse:
        """See
        [`aiortu.master.Master.get_comm_event_log`][aiortu.master.Master.get_comm_event_log]."""
        return await self.master.get_comm_event_log(self.unit, timeout=timeout, priority=priority)

    async def report_server_id(
        self, *, timeout: float | None = None, priority: int = 0
    ) -> ReportServerIdResponse:
        """See [`aiortu.master.Master.report_server_id`][aiortu.master.Master.report_server_id]."""
        return await self.master.report_server_id(self.unit, timeout=timeout, priority=priority)

    async def read_device_identification(
        self,
        read_code: int = DeviceIdReadCode.BASIC,
        object_id: int = 0,
        *,
        timeout: float | None = None,
        priority: int = 0,
    ) -> dict[int, bytes]:
        """See
        [`aiortu.master.Master.read_device_identification`][aiortu.master.Master.read_device_identification]."""
        return await self.master.read_device_identification(
            self.unit, read_code, object_id, timeout=timeout, priority=priority
        )

    async def execute(
        self, pdu: Request, *, timeout: float | None = None, priority: int = 0
    ) -> Response | ExceptionPDU:
        """See [`aiortu.master.Master.execute`][aiortu.master.Master.execute]."""
        return await self.master.execute(self.unit, pdu, timeout=timeout, priority=priority)

    # -- typed values ----------------------------------------------------------------

    async def read_value(
        self,
        address: int,
        kind: ValueType | str,
        layout: Layout | str = Layout.ABCD,
        *,
        table: Table | str = "holding",
        timeout: float | None = None,
        priority: int = 0,
    ) -> int | float:
        """Read one `kind` (`"float32"`, `"int32"`, ...) from `address` in `layout`.

        `table` is `"holding"` (the default) or `"input"`.
        """
        # Checked before the request goes out: a bad layout must not cost a read.
        kind = as_value_type(kind)
        layout = as_layout(layout)
        registers = await self._read_registers(
            table, address, kind.register_count, timeout, priority
        )
        return decode_value(registers, kind, layout)

    async def write_value(
        self,
        address: int,
        value: float,
        kind: ValueType | str,
        layout: Layout | str = Layout.ABCD,
        *,
        timeout: float | None = None,
        priority: int = 0,
    ) -> None:
        """Write `value` as one `kind` to the holding registers from `address` in `layout`."""
        registers = encode_value(value, kind, layout)
        await self.write_registers(address, registers, timeout=timeout, priority=priority)

    async def read_float32(
        self,
        address: int,
        layout: Layout | str = Layout.ABCD,
        *,
        table: Table | str = "holding",
        timeout: float | None = None,
    ) -> float:
        """Read a float32 from two registers at `address` in `layout`."""
        value = await self.read_value(
            address, ValueType.FLOAT32, layout, table=table, timeout=timeout
        )
        return float(value)

    async def read_int32(
        self,
        address: int,
        layout: Layout | str = Layout.ABCD,
        *,
        table: Table | str = "holding",
        timeout: float | None = None,
    ) -> int:
        """Read a signed 32-bit integer from two registers at `address` in `layout`."""
        return int(
            await self.read_value(address, ValueType.INT32, layout, table=table, timeout=timeout)
        )

    async def read_uint32(
        self,
        address: int,
        layout: Layout | str = Layout.ABCD,
        *,
        table: Table | str = "holding",
        timeout: float | None = None,
    ) -> int:
        """Read an unsigned 32-bit integer from two registers at `address` in `layout`."""
        return int(
            await self.read_value(address, ValueType.UINT32, layout, table=table, timeout=timeout)
        )

    async def write_float32(
        self,
        address: int,
        value: float,
        layout: Layout | str = Layout.ABCD,
        *,
        timeout: float | None = None,
    ) -> None:
        """Write `value` as a float32 to two holding registers at `address`."""
        await self.write_value(address, value, ValueType.FLOAT32, layout, timeout=timeout)

    async def write_int32(
        self,
        address: int,
        value: int,
        layout: Layout | str = Layout.ABCD,
        *,
        timeout: float | None = None,
    ) -> None:
        """Write `value` as a signed 32-bit integer to two holding registers at `address`."""
        await self.write_value(address, value, ValueType.INT32, layout, timeout=timeout)

    async def write_uint32(
        self,
        address: int,
        value: int,
        layout: Layout | str = Layout.ABCD,
        *,
        timeout: float | None = None,
    ) -> None:
        """Write `value` as an unsigned 32-bit integer to two holding registers at `address`."""
        await self.write_value(address, value, ValueType.UINT32, layout, timeout=timeout)

    async def read_string(
        self,
        address: int,
        register_count: int,
        *,
        encoding: str = "ascii",
        byte_swap: bool = False,
        table: Table | str = "holding",
        timeout: float | None = None,
    ) -> str:
        """Read text from `register_count` registers, two bytes each, padding stripped."""
        check_encoding(encoding)
        registers = await self._read_registers(table, address, register_count, timeout, 0)
        return registers_to_string(registers, encoding, byte_swap)

    async def write_string(
        self,
        address: int,
        text: str,
        register_count: int | None = None,
        *,
        encoding: str = "ascii",
        byte_swap: bool = False,
        timeout: float | None = None,
    ) -> None:
        """Write `text` to holding registers from `address`, NUL-padded to `register_count`."""
        registers = string_to_registers(text, register_count, encoding, byte_swap)  # checks all
        await self.write_registers(address, registers, timeout=timeout)

    async def read_reference(
        self, reference: str, count: int = 1, *, timeout: float | None = None
    ) -> list[bool] | list[int]:
        """Read `count` elements from a reference such as `"40108"` (holding register
        address 107) or `"100001"` (discrete input address 0)."""
        parsed = parse_reference(reference)
        table = parsed.table
        if table is Table.COILS:
            return await self.read_coils(parsed.address, count, timeout=timeout)
        if table is Table.DISCRETE_INPUTS:
            return await self.read_discrete_inputs(parsed.address, count, timeout=timeout)
        return await self._read_registers(table, parsed.address, count, timeout, 0)

    async def _read_registers(
        self,
        table: Table | str,
        address: int,
        count: int,
        timeout: float | None,
        priority: int,
    ) -> list[int]:
        resolved = _REGISTER_TABLES.get(table) if isinstance(table, str) else None
        if resolved is Table.INPUT_REGISTERS:
            return await self.read_input_registers(
                address, count, timeout=timeout, priority=priority
            )
        if resolved is Table.HOLDING_REGISTERS:
            return await self.read_holding_registers(
                address, count, timeout=timeout, priority=priority
            )
        raise InvalidRequest("table", table, "'holding' or 'input'")

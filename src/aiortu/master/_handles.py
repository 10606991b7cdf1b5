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

import inspect
from collections.abc import Callable, Coroutine
from typing import Any, Concatenate, ParamSpec, Protocol, TypeVar, TypeVarTuple, Unpack

from aiortu._derived import derive
from aiortu.core.codes import BROADCAST_UNIT
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
from aiortu.core.pdu import Request
from aiortu.master._operations import (
    Operations,
    mask_write_register_request,
    write_coil_request,
    write_coils_request,
    write_file_record_request,
    write_register_request,
    write_registers_request,
)

__all__ = ("BroadcastHandle", "BroadcastMethod", "UnitHandle", "on_unit")

_P = ParamSpec("_P")
_R = TypeVar("_R")
_Ts = TypeVarTuple("_Ts")

_REGISTER_TABLES = {
    "holding": Table.HOLDING_REGISTERS,
    "input": Table.INPUT_REGISTERS,
    Table.HOLDING_REGISTERS: Table.HOLDING_REGISTERS,
    Table.INPUT_REGISTERS: Table.INPUT_REGISTERS,
}


def on_unit(
    operation: Callable[Concatenate[Operations, int, _P], Coroutine[Any, Any, _R]],
) -> Callable[Concatenate[UnitHandle, _P], Coroutine[Any, Any, _R]]:
    """The method of [`UnitHandle`][aiortu.master.UnitHandle] made from a master's `operation`:
    the same call with the handle's unit first (the master's own method is called, so that
    what it overrides counts)."""
    name = operation.__name__

    async def bound(self: UnitHandle, /, *args: _P.args, **kwargs: _P.kwargs) -> _R:
        method = getattr(self.master, name)
        result: _R = await method(self.unit, *args, **kwargs)
        return result

    derive(bound, operation, "UnitHandle", drop=1)
    return bound


class BroadcastMethod(Protocol[*_Ts]):
    """A method of [`BroadcastHandle`][aiortu.master.BroadcastHandle]: a write's arguments
    without the unit, and `priority=`."""

    def __call__(self, *args: *_Ts, priority: int = 0) -> Coroutine[Any, Any, None]: ...


def _broadcast(
    operation: Callable[..., Coroutine[Any, Any, None]], build: Callable[[Unpack[_Ts]], Request]
) -> BroadcastMethod[*_Ts]:
    """The broadcast form of the master's write `operation`, whose request `build` makes."""
    name = operation.__name__

    # The write's arguments by keyword too, as its signature shows (the protocol's type
    # cannot say so: a TypeVarTuple has no names).
    async def send(self: BroadcastHandle, /, *args: *_Ts, priority: int = 0, **named: Any) -> None:
        request = build(*args, **named)
        await self._master.send_without_reply(BROADCAST_UNIT, request, priority=priority)

    code = inspect.signature(build, eval_str=True).return_annotation.function_code
    doc = (
        f"[`Master.{name}`][aiortu.master.Master.{name}] on every unit at once (unit 0, function"
        f" code {code:02X}): no reply is awaited; returns once the request is sent and the"
        " turnaround delay has passed."
    )
    parameters = list(inspect.signature(build).parameters.values())
    derive(send, operation, "BroadcastHandle", doc=doc)
    send.__signature__ = inspect.Signature(  # type: ignore[attr-defined]
        [
            inspect.Parameter("self", inspect.Parameter.POSITIONAL_OR_KEYWORD),
            *parameters,
            inspect.Parameter(
                "priority", inspect.Parameter.KEYWORD_ONLY, default=0, annotation="int"
            ),
        ],
        return_annotation="None",
    )
    return send  # type: ignore[return-value]  # its call is BroadcastMethod's


class BroadcastHandle:
    """The broadcast writes of a master (see the module docstring); each returns once the
    request is sent and the turnaround delay has passed."""

    def __init__(self, master: Operations) -> None:
        self._master = master

    write_coil = _broadcast(Operations.write_coil, write_coil_request)
    write_register = _broadcast(Operations.write_register, write_register_request)
    write_coils = _broadcast(Operations.write_coils, write_coils_request)
    write_registers = _broadcast(Operations.write_registers, write_registers_request)
    mask_write_register = _broadcast(Operations.mask_write_register, mask_write_register_request)
    write_file_record = _broadcast(Operations.write_file_record, write_file_record_request)


class UnitHandle:
    """One unit of a master: `master.slave(unit)` (see the module docstring).

    Every method takes `timeout=` and `priority=` as the master's do.
    """

    def __init__(self, master: Operations, unit: int) -> None:
        self.master = master
        self.unit = unit

    # -- the master's operations, bound to the unit ----------------------------------

    read_coils = on_unit(Operations.read_coils)
    read_discrete_inputs = on_unit(Operations.read_discrete_inputs)
    read_holding_registers = on_unit(Operations.read_holding_registers)
    read_input_registers = on_unit(Operations.read_input_registers)
    write_coil = on_unit(Operations.write_coil)
    write_coils = on_unit(Operations.write_coils)
    write_register = on_unit(Operations.write_register)
    write_registers = on_unit(Operations.write_registers)
    mask_write_register = on_unit(Operations.mask_write_register)
    read_write_registers = on_unit(Operations.read_write_registers)
    read_fifo_queue = on_unit(Operations.read_fifo_queue)
    read_file_record = on_unit(Operations.read_file_record)
    write_file_record = on_unit(Operations.write_file_record)
    read_exception_status = on_unit(Operations.read_exception_status)
    diagnostics = on_unit(Operations.diagnostics)
    get_comm_event_counter = on_unit(Operations.get_comm_event_counter)
    get_comm_event_log = on_unit(Operations.get_comm_event_log)
    report_server_id = on_unit(Operations.report_server_id)
    read_device_identification = on_unit(Operations.read_device_identification)
    execute = on_unit(Operations.execute)

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

"""Each operation is written once, in `aiortu.master._operations`: the master inherits it as it
is, and the unit and broadcast handles are made from it with the same names, docstrings and
signatures (the unit taken out)."""

from __future__ import annotations

import inspect

import anyio
import pytest

from aiortu.errors import InvalidRequest
from aiortu.master import BroadcastHandle, Master, UnitHandle
from aiortu.master._operations import Operations
from aiortu.testing import VirtualBus

from .fakes import line, register_value

OPERATIONS = sorted(
    name
    for name, member in vars(Operations).items()
    if not name.startswith("_") and inspect.iscoroutinefunction(member)
)


def _parameters(function: object) -> list[inspect.Parameter]:
    return list(inspect.signature(function).parameters.values())  # type: ignore[arg-type]


def test_the_table_lists_every_operation() -> None:
    assert len(OPERATIONS) == 22
    assert {"read_holding_registers", "read_device_identification", "execute"} <= set(OPERATIONS)


SEAM = ("request", "execute", "send_without_reply")
"""What the operations stand on, which the master implements."""


@pytest.mark.parametrize("name", OPERATIONS)
def test_the_master_runs_the_one_definition_with_no_layer(name: str) -> None:
    if name in SEAM:
        assert getattr(Master, name) is not getattr(Operations, name)
    else:
        assert getattr(Master, name) is getattr(Operations, name)


@pytest.mark.parametrize(
    "name", [n for n in OPERATIONS if n not in ("request", "send_without_reply")]
)
def test_a_unit_handle_method_is_the_operation_without_the_unit(name: str) -> None:
    operation = getattr(Operations, name)
    method = getattr(UnitHandle, name)
    assert inspect.iscoroutinefunction(method)
    assert method.__doc__ == operation.__doc__
    assert method.__qualname__ == f"UnitHandle.{name}"
    assert _parameters(operation)[1].name == "unit"
    assert [p.name for p in _parameters(method)] == [
        "self",
        *(p.name for p in _parameters(operation)[2:]),
    ]
    assert _parameters(method)[1:] == _parameters(operation)[2:]
    assert (
        inspect.signature(method).return_annotation
        == inspect.signature(operation).return_annotation
    )


BROADCASTS = [
    "mask_write_register",
    "write_coil",
    "write_coils",
    "write_file_record",
    "write_register",
    "write_registers",
]


def test_the_broadcast_handle_has_the_broadcastable_writes() -> None:
    found = sorted(
        name
        for name, member in vars(BroadcastHandle).items()
        if not name.startswith("_") and inspect.iscoroutinefunction(member)
    )
    assert found == BROADCASTS


@pytest.mark.parametrize("name", BROADCASTS)
def test_a_broadcast_takes_the_writes_arguments_and_a_priority(name: str) -> None:
    operation = getattr(Operations, name)
    method = getattr(BroadcastHandle, name)
    names = [p.name for p in _parameters(method)]
    assert names == ["self", *(p.name for p in _parameters(operation)[2:-2]), "priority"]
    assert f"[`Master.{name}`][aiortu.master.Master.{name}]" in (method.__doc__ or "")


async def test_a_broadcast_takes_its_arguments_by_keyword_too() -> None:
    async with line(turnaround_delay=0.001) as (master, slave, _):
        await master.broadcast.write_register(address=0x10, value=7, priority=1)
        await master.broadcast.mask_write_register(1, and_mask=0xFF, or_mask=0)
        assert [(seen.unit, seen.request.function_code) for seen in slave.seen] == [
            (0, 6),
            (0, 0x16),
        ]
        with pytest.raises(TypeError):
            await master.broadcast.write_register(0x10, 7, timeout=1)  # type: ignore[call-arg]


async def test_a_handle_calls_the_masters_method_with_its_unit() -> None:
    async with line() as (master, slave, _):
        handle = master.slave(17)
        assert await handle.read_holding_registers(0x6B, 2) == [
            register_value(17, 0x6B),
            register_value(17, 0x6C),
        ]
        assert await handle.read_holding_registers(address=0x6B, count=1, timeout=0.5) == [
            register_value(17, 0x6B)
        ]
        assert [seen.unit for seen in slave.seen] == [17, 17]
        with pytest.raises(TypeError):
            await handle.read_holding_registers(17, 0x6B, 2)  # type: ignore[call-arg]


async def test_a_master_left_in_another_task_says_so_and_stays_open() -> None:
    bus = VirtualBus(2)
    other = Master(bus[0], frame_gap=0)
    leave = anyio.Event()
    left = anyio.Event()

    async def enter_and_wait() -> None:
        await other.__aenter__()
        await leave.wait()
        await other.__aexit__(None, None, None)
        left.set()

    async with anyio.create_task_group() as tasks:
        tasks.start_soon(enter_and_wait)
        await anyio.sleep(0.01)
        with pytest.raises(RuntimeError, match=r"^a master must be left in the task that entered"):
            await other.__aexit__(None, None, None)
        assert other.connected
        leave.set()
        await left.wait()
    assert not other.connected


@pytest.mark.parametrize("bad", [1.0, True, [1], None])
async def test_a_read_made_before_does_not_let_a_bad_address_through(bad: object) -> None:
    async with line() as (master, slave, _):
        reads = (
            master.read_coils,
            master.read_discrete_inputs,
            master.read_holding_registers,
            master.read_input_registers,
        )
        for read in reads:
            await read(1, 1, 1)  # the request for address 1 is made and kept
            with pytest.raises(InvalidRequest, match=r"^address "):
                await read(1, bad, 1)  # type: ignore[arg-type]
            with pytest.raises(InvalidRequest, match=r"^count "):
                await read(1, 1, bad)  # type: ignore[arg-type]
        assert len(slave.seen) == len(reads)

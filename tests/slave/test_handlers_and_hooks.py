"""Range handlers, hooks, odd devices (silent, slow, another unit) and async stores."""

from __future__ import annotations

from collections.abc import AsyncIterator, Sequence
from contextlib import asynccontextmanager

import anyio
import anyio.lowlevel
import pytest

import aiortu
from aiortu.core.codes import ExceptionCode
from aiortu.core.pdu import ReadHoldingRegistersResponse
from aiortu.errors import ExceptionResponse, ResponseTimeout
from aiortu.slave import (
    AsyncDataStore,
    MemoryStore,
    RangeAccess,
    Reply,
    RequestContext,
    Slave,
    Table,
)
from aiortu.testing import virtual_pair

from .helpers import UNIT, example_store, slave_line


@asynccontextmanager
async def master_and_slave(
    units: dict[int, object] | None = None,
) -> AsyncIterator[tuple[aiortu.Master, Slave]]:
    master_end, slave_end = virtual_pair()
    slave = Slave(
        slave_end,
        units if units is not None else {UNIT: example_store()},  # type: ignore[arg-type]
        frame_gap=0.0,
        frame_silence=0.005,
    )
    async with slave, aiortu.Master(master_end, timeout=0.3, retries=0, frame_gap=0.0) as master:
        await anyio.sleep(0.02)
        yield master, slave


async def test_range_handler_serves_reads_and_writes() -> None:
    written: list[RangeAccess] = []

    def sensor(access: RangeAccess) -> list[int] | None:
        if access.is_write:
            written.append(access)
            return None
        return [access.address * 2 + index for index in range(access.count)]

    async with master_and_slave() as (master, slave):
        slave.route(Table.HOLDING_REGISTERS, range(1000, 1010), sensor)
        assert await master.read_holding_registers(UNIT, 1002, 2) == [2004, 2005]
        await master.write_registers(UNIT, 1000, [7, 8])
        # Outside the route the store still answers.
        assert await master.read_holding_registers(UNIT, 0x6B, 1) == [0xAE41]
        with pytest.raises(ExceptionResponse) as straddling:
            await master.read_holding_registers(UNIT, 1008, 4)
    assert straddling.value.code == ExceptionCode.ILLEGAL_DATA_ADDRESS
    assert written == [RangeAccess(UNIT, Table.HOLDING_REGISTERS, 1000, 2, (7, 8))]


async def test_async_range_handler_and_mask_write() -> None:
    cell = [0x12]

    async def register(access: RangeAccess) -> Sequence[int] | None:
        await anyio.sleep(0.001)
        if access.values is not None:
            cell[0] = access.values[0]
            return None
        return list(cell)

    async with master_and_slave() as (master, slave):
        slave.route("holding_registers", range(500, 501), register)
        await master.mask_write_register(UNIT, 500, 0xF2, 0x25)
        assert await master.read_holding_registers(UNIT, 500, 1) == [0x17]


async def test_before_hook_answers_or_refuses_and_after_hook_replaces() -> None:
    seen: list[int] = []

    def before(request: object, context: RequestContext) -> ReadHoldingRegistersResponse | None:
        seen.append(context.unit)
        address = getattr(request, "address", None)
        if address == 1:
            raise ExceptionResponse(ExceptionCode.SERVER_DEVICE_BUSY)
        if address == 2:
            return ReadHoldingRegistersResponse((42,))
        return None

    async def after(request: object, context: RequestContext, result: object) -> object:
        if getattr(request, "address", None) == 3:
            return ReadHoldingRegistersResponse((99,))
        return None

    async with master_and_slave() as (master, slave):
        remove = slave.before_request(before)
        remove_after = slave.after_request(after)  # type: ignore[arg-type]
        with pytest.raises(ExceptionResponse) as refused:
            await master.read_holding_registers(UNIT, 1, 1)
        assert await master.read_holding_registers(UNIT, 2, 1) == [42]
        assert await master.read_holding_registers(UNIT, 3, 1) == [99]
        assert await master.read_holding_registers(UNIT, 0, 1) == [0]
        remove()
        assert await master.read_holding_registers(UNIT, 1, 1) == [0]
        remove_after()
        remove_after()  # a second removal is harmless
        stored = example_store().read(Table.HOLDING_REGISTERS, 3, 1)
        assert await master.read_holding_registers(UNIT, 3, 1) == stored != [99]
    assert refused.value.code == ExceptionCode.SERVER_DEVICE_BUSY
    assert slave.counters.server_busy_count == 1
    assert seen == [UNIT] * 4


async def test_silent_slow_and_other_unit_devices() -> None:
    mode = {"value": "silent"}

    def odd(request: object, context: RequestContext) -> Reply:
        response = ReadHoldingRegistersResponse((1,))
        if mode["value"] == "silent":
            return Reply(None)
        if mode["value"] == "slow":
            return Reply(response, delay=0.15)
        return Reply(response, unit=UNIT + 1)

    async with master_and_slave() as (master, slave):
        slave.set_handler(0x03, odd)
        with pytest.raises(ResponseTimeout):
            await master.read_holding_registers(UNIT, 0, 1)
        mode["value"] = "slow"
        started = anyio.current_time()
        assert await master.read_holding_registers(UNIT, 0, 1, timeout=1.0) == [1]
        assert anyio.current_time() - started >= 0.15
        with pytest.raises(ResponseTimeout):
            await master.read_holding_registers(UNIT, 0, 1, timeout=0.05)
        await anyio.sleep(0.2)
        mode["value"] = "other"
        with pytest.raises(ResponseTimeout):
            await master.read_holding_registers(UNIT, 0, 1)
    assert slave.counters.server_no_response_count == 1


class ProxyStore:
    """An async store in front of a MemoryStore, as a proxy to another device would be."""

    def __init__(self, backing: MemoryStore) -> None:
        self.backing = backing
        self.calls = 0

    async def read(self, table: Table, address: int, count: int) -> list[int]:
        self.calls += 1
        await anyio.lowlevel.checkpoint()
        return self.backing.read(table, address, count)

    async def write(self, table: Table, address: int, values: Sequence[int]) -> None:
        self.calls += 1
        await anyio.lowlevel.checkpoint()
        self.backing.write(table, address, values)

    async def read_file_record(self, file_number: int, record: int, count: int) -> list[int]:
        await anyio.lowlevel.checkpoint()
        return self.backing.read_file_record(file_number, record, count)

    async def write_file_record(self, file_number: int, record: int, values: Sequence[int]) -> None:
        await anyio.lowlevel.checkpoint()
        self.backing.write_file_record(file_number, record, values)


async def test_async_store_serves_every_table_function() -> None:
    backing = MemoryStore(coils={0: 16}, holding_registers={0: 16}, files={1: 10})
    proxy = ProxyStore(backing)
    assert isinstance(proxy, AsyncDataStore)
    async with master_and_slave({UNIT: proxy}) as (master, _):
        await master.write_coils(UNIT, 0, [True, False, True])
        assert await master.read_coils(UNIT, 0, 3) == [True, False, True]
        await master.write_registers(UNIT, 0, [1, 2, 3])
        await master.write_register(UNIT, 3, 4)
        assert await master.read_write_registers(UNIT, 0, 4, 4, [5]) == [1, 2, 3, 4]
        await master.mask_write_register(UNIT, 0, 0x00, 0x10)
        assert await master.read_holding_registers(UNIT, 0, 5) == [0x10, 2, 3, 4, 5]
        await master.write_file_record(UNIT, [(1, 2, [9, 8])])
        assert await master.read_file_record(UNIT, [(1, 2, 2)]) == [[9, 8]]
        with pytest.raises(ExceptionResponse):
            await master.read_holding_registers(UNIT, 15, 2)
    assert proxy.calls >= 8


async def test_range_handler_failure_answers_04_and_serving_goes_on() -> None:
    def broken(access: RangeAccess) -> list[int]:
        raise RuntimeError("sensor unplugged")

    async with slave_line() as (master, slave):
        slave.route(Table.INPUT_REGISTERS, range(8, 9), broken)
        assert await master.request(UNIT, "04 00 08 00 01") == "84 04"
        assert await master.request(UNIT, "03 00 6B 00 01") == "03 02 AE 41"


async def test_a_broadcast_reaches_each_store_flagged_as_broadcast() -> None:
    seen: list[tuple[int, bool]] = []

    def record(request: object, context: RequestContext) -> None:
        seen.append((context.unit, context.broadcast))

    stores = {unit: MemoryStore(holding_registers={1: [0]}) for unit in (3, 4)}
    async with slave_line(stores) as (master, slave):
        slave.set_handler(0x06, record)
        await master.send_request(0, "06 00 01 00 07")
        # A read answered after it: the broadcast has run by then.
        assert await master.request(3, "03 00 01 00 01") == "03 02 00 00"
        assert seen == [(3, True), (4, True)]


async def test_a_frame_for_another_unit_while_busy_is_only_counted() -> None:
    release = anyio.Event()

    async def held(request: object, context: RequestContext) -> ReadHoldingRegistersResponse:
        await release.wait()
        return ReadHoldingRegistersResponse((5,))

    async with slave_line({3: MemoryStore(holding_registers={0: [1]})}) as (master, slave):
        slave.set_handler(0x03, held)
        await master.send_request(3, "03 00 00 00 01")
        await anyio.sleep(0.03)
        # The serve loop is busy: the frame for unit 5 is queued, then taken by it.
        await master.send_request(5, "03 00 00 00 01")
        await anyio.sleep(0.03)
        release.set()
        frame = await master.receive_frame()
        assert frame is not None
        assert frame[0] == 3, frame
        assert await master.receive_frame(0.1) is None  # nothing for unit 5
        assert await master.request(3, "03 00 00 00 01") == "03 02 00 05"
    assert slave.counters.other_unit_count == 1

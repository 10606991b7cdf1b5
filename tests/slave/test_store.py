"""MemoryStore: blocks, unmapped addresses, aliasing, read-only ranges, FIFOs, observers."""

from __future__ import annotations

import anyio
import pytest

from aiortu.core.codes import ExceptionCode
from aiortu.errors import ExceptionResponse, InvalidValue
from aiortu.slave import Block, Change, DataStore, MemoryStore, Table

HR = Table.HOLDING_REGISTERS


def exception_code(call: object) -> int:
    assert callable(call)
    with pytest.raises(ExceptionResponse) as caught:
        call()
    return caught.value.code


def test_blocks_from_mappings_and_objects() -> None:
    store = MemoryStore(holding_registers={0x160: 32, 0x200: [1, 2]}, coils=Block(0x130, 37, [1]))
    assert store.read(HR, 0x160, 32) == [0] * 32
    assert store.read(HR, 0x200, 2) == [1, 2]
    assert store.read(Table.COILS, 0x130, 2) == [True, False]
    assert [block.start for block in store.blocks(HR)] == [0x160, 0x200]
    assert isinstance(store, DataStore)


@pytest.mark.parametrize(
    ("address", "count"),
    [(0x15F, 1), (0x15F, 2), (0x17F, 2), (0x180, 1), (0x1FF, 3), (0x201, 2), (0, 1), (0xFFFF, 1)],
)
def test_unmapped_or_straddling_ranges_give_02(address: int, count: int) -> None:
    store = MemoryStore(holding_registers={0x160: 32, 0x200: [1, 2]})
    assert exception_code(lambda: store.read(HR, address, count)) == 0x02
    assert exception_code(lambda: store.write(HR, address, [0] * count)) == 0x02


def test_empty_tables_give_02() -> None:
    store = MemoryStore()
    for table in Table:
        assert exception_code(lambda table=table: store.read(table, 0, 1)) == 0x02


def test_read_is_a_copy() -> None:
    store = MemoryStore(holding_registers={0: 10})
    values = store.read(HR, 2, 3)
    values[0] = 99
    assert store.read(HR, 2, 1) == [0]


def test_aliasing_by_shared_block_and_by_name() -> None:
    shared = Block(0, 4)
    store = MemoryStore(holding_registers=[shared], input_registers=[shared])
    store.write(HR, 1, [7])
    assert store.read(Table.INPUT_REGISTERS, 1, 1) == [7]
    bits = MemoryStore(coils={0: 8}, discrete_inputs=Table.COILS)
    bits.write(Table.COILS, 3, [True])
    assert bits.read(Table.DISCRETE_INPUTS, 3, 1) == [True]


@pytest.mark.parametrize(
    "options",
    [
        {"holding_registers": {0: 4, 2: 4}},
        {"coils": {0: [2]}},
        {"holding_registers": {0: [0x10000]}},
        {"coils": {0: 4}, "input_registers": Table.COILS},
        {"coils": Table.DISCRETE_INPUTS, "discrete_inputs": Table.COILS},
        {"holding_registers": {0xFFFF: 2}},
        {"holding_registers": {0: 0}},
        {"exception_status": 256},
    ],
)
def test_bad_layouts_are_refused(options: dict[str, object]) -> None:
    with pytest.raises(InvalidValue):
        MemoryStore(**options)  # type: ignore[arg-type]


def test_read_only_ranges() -> None:
    store = MemoryStore(holding_registers={0: 8}, read_only={"holding_registers": [range(2, 4)]})
    assert exception_code(lambda: store.write(HR, 3, [1])) == 0x02
    assert exception_code(lambda: store.write(HR, 0, [1, 1, 1])) == 0x02
    store.write(HR, 4, [1, 1])
    store.set(HR, 2, [5, 6])  # the device itself may change them
    assert store.read(HR, 0, 6) == [0, 0, 5, 6, 1, 1]
    other = MemoryStore(
        holding_registers={0: 8},
        read_only={HR: [range(8)]},
        read_only_exception=ExceptionCode.SERVER_DEVICE_FAILURE,
    )
    assert exception_code(lambda: other.write(HR, 0, [1])) == 0x04


def test_set_and_get_check_values() -> None:
    store = MemoryStore(holding_registers={0: 2}, coils={0: 2})
    store.set("holding_registers", 0, 0xFFFF)
    store.set(Table.COILS, 0, [1, 0])
    assert store.get(HR, 0) == [0xFFFF]
    assert store.get(Table.COILS, 0, 2) == [True, False]
    with pytest.raises(InvalidValue):
        store.set(HR, 0, 0x10000)
    with pytest.raises(InvalidValue):
        store.set(Table.COILS, 0, 2)


def test_fifo_queues() -> None:
    store = MemoryStore(fifo_queues={0x04DE: [1, 2]})
    assert store.read_fifo_queue(0x04DE) == [1, 2]
    assert store.read_fifo_queue(0x04DE) == [1, 2]  # reading leaves them queued
    store.fifo_queues[0x04DE].append(3)
    assert store.read_fifo_queue(0x04DE) == [1, 2, 3]
    assert exception_code(lambda: store.read_fifo_queue(0)) == 0x02


def test_observers_and_a_failing_observer(caplog: pytest.LogCaptureFixture) -> None:
    store = MemoryStore(holding_registers={0: 4})
    seen: list[Change] = []

    def failing(change: Change) -> None:
        raise RuntimeError("observer bug")

    store.observe(failing)
    remove = store.observe(seen.append)
    store.write(HR, 1, [5, 6])
    remove()
    store.write(HR, 1, [7])
    assert seen == [Change(HR, 1, (5, 6), (0, 0))]
    assert seen[0].count == 2
    assert "observer bug" in caplog.text
    assert store.read(HR, 1, 1) == [7]


async def test_change_feed_bounded_and_closable() -> None:
    store = MemoryStore(holding_registers={0: 4})
    feed = store.changes(max_pending=2)
    for value in range(3):
        store.write(HR, 0, [value])
    assert feed.dropped == 1
    assert (await anext(feed)).values == (1,)

    async def write_later() -> None:
        await anyio.sleep(0.01)
        store.write(HR, 3, [9])
        feed.close()

    async with anyio.create_task_group() as group:
        group.start_soon(write_later)
        received = [change.values async for change in feed]
    assert received == [(2,), (9,)]
    store.write(HR, 0, [1])
    assert feed.dropped == 1

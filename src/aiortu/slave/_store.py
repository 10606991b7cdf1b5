"""Data stores: what a slave reads and writes when a master asks, and the in-memory default.

A slave unit serves the four tables of the Modbus data model (coils, discrete inputs, input
registers, holding registers) from a [`DataStore`][aiortu.core.model.DataStore]: a small
synchronous protocol, [`read`][aiortu.core.model.DataStore.read] and
[`write`][aiortu.core.model.DataStore.write] on a [`Table`][aiortu.core.model.Table],
raising [`ExceptionResponse`][aiortu.errors.ExceptionResponse] with the code the master should get
(02 for an address outside the map), plus the optional capabilities
([`SupportsFifoQueues`][aiortu.core.model.SupportsFifoQueues],
[`SupportsExceptionStatus`][aiortu.core.model.SupportsExceptionStatus],
[`SupportsFileRecords`][aiortu.core.model.SupportsFileRecords],
[`SupportsDeviceIdentification`][aiortu.core.model.SupportsDeviceIdentification],
[`SupportsServerId`][aiortu.core.model.SupportsServerId]). They are defined in
[`aiortu.core.model`][aiortu.core.model] and re-exported here. Any store method may be a
coroutine ([`AsyncDataStore`][aiortu.core.model.AsyncDataStore], e.g. a store that proxies
another device, see `examples/proxy_store.py`); a sync store keeps costing nothing extra.

[`MemoryStore`][aiortu.slave.MemoryStore] is the default store:

    store = MemoryStore(
        coils={0x130: 37},                                   # start: count
        holding_registers=[Block(0x160, 32, [0x022B, 1])],   # or blocks with values
        input_registers=Table.HOLDING_REGISTERS,             # alias another table
        read_only={Table.HOLDING_REGISTERS: [range(0x160, 0x162)]},
        fifo_queues={0x04DE: [440, 25]},
        files={1: 100, 2: [1, 2, 3]},                        # file: record count or values
        device_identification={0: "aiortu", 1: "SIM-1", 2: "1.0"},
        server_id=ServerId(b"\x11", True, b"sim"),
    )

Each table is a set of [`Block`][aiortu.slave.Block]s with explicit extents; a read or write whose
range is not entirely inside one block gets exception 02, as a device without those addresses
answers. Tables alias each other by sharing blocks (pass the same [`Block`][aiortu.slave.Block] to
both, or name the other table). Writes from the master to a read-only range get exception 02 (or the
code given as `read_only_exception`). Observers
([`MemoryStore.observe`][aiortu.slave.MemoryStore.observe] callbacks and
[`MemoryStore.changes`][aiortu.slave.MemoryStore.changes] async iterators) see every write a master
makes, so an application can react to it. Reading registers is one list slice.
"""

from __future__ import annotations

import itertools
from bisect import bisect_right
from collections import deque
from collections.abc import Callable, Iterable, Mapping, Sequence
from dataclasses import dataclass
from types import TracebackType
from typing import Final, Self

import anyio

from aiortu._log import get_logger
from aiortu.core.codes import ExceptionCode
from aiortu.core.model import (
    AsyncDataStore,
    DataStore,
    ServerId,
    SupportsDeviceIdentification,
    SupportsExceptionStatus,
    SupportsFifoQueues,
    SupportsFileRecords,
    SupportsServerId,
    Table,
)
from aiortu.errors import ExceptionResponse, InvalidValue

__all__ = (
    "AsyncDataStore",
    "Block",
    "Change",
    "ChangeFeed",
    "DataStore",
    "MemoryStore",
    "ServerId",
    "SupportsDeviceIdentification",
    "SupportsExceptionStatus",
    "SupportsFifoQueues",
    "SupportsFileRecords",
    "SupportsServerId",
    "Table",
)

_log = get_logger(__name__)

_ADDRESS_SPACE: Final = 0x10000
_EXCEPTION_CODES: Final = tuple(sorted(int(code) for code in ExceptionCode))
_REGISTER_VALUES = range(0x10000)
_BIT_VALUES = range(2)
_FILE_NUMBERS = range(1, 0x10000)
_FILE_LENGTHS = range(1, 10001)
_OBJECT_IDS = range(0x100)
_MAX_OBJECT_LENGTH = 244


@dataclass(frozen=True, slots=True)
class Change:
    """A write a master made: the `table`, the first `address`, and the values before and after.

    Bits are `bool`, registers `int`.
    """

    table: Table
    address: int
    values: tuple[int, ...]
    previous: tuple[int, ...]

    @property
    def count(self) -> int:
        """The number of elements written."""
        return len(self.values)


class Block:
    """A run of `count` consecutive addresses from `start`, with its values.

    `values` are the initial values from `start` (the rest are 0); `count` defaults to
    `len(values)`. One block may be placed in two tables of the same kind (holding and
    input registers, or coils and discrete inputs) to alias them.
    """

    __slots__ = ("count", "start", "values")

    def __init__(self, start: int, count: int | None = None, values: Iterable[int] = ()) -> None:
        initial = list(values)
        if count is None:
            count = len(initial)
        if start not in range(_ADDRESS_SPACE):
            raise InvalidValue("start", start, range(_ADDRESS_SPACE))
        if count not in range(1, _ADDRESS_SPACE - start + 1):
            raise InvalidValue("count", count, range(1, _ADDRESS_SPACE - start + 1))
        if len(initial) > count:
            raise InvalidValue("len(values)", len(initial), range(count + 1))
        self.start = start
        """The first protocol address of the block."""
        self.count = count
        """How many addresses the block covers."""
        self.values: list[int] = initial + [0] * (count - len(initial))
        """The values, index 0 at [`start`][aiortu.slave.Block.start] (bits are `bool` once placed
        in a bit table)."""

    @property
    def stop(self) -> int:
        """One past the last address of the block."""
        return self.start + self.count

    def __repr__(self) -> str:
        return f"Block(start=0x{self.start:04X}, count={self.count})"


BlockSpec = Block | Iterable[Block] | Mapping[int, int | Sequence[int]] | Table
"""How a table is given to [`MemoryStore`][aiortu.slave.MemoryStore]: a block, blocks, `{start:
count or values}`, or another table to alias."""


class _TableMap:
    """The blocks of one table, sorted by start, for a bisect lookup."""

    __slots__ = ("blocks", "starts")

    def __init__(self, blocks: list[Block]) -> None:
        self.blocks = sorted(blocks, key=lambda block: block.start)
        self.starts = [block.start for block in self.blocks]


class MemoryStore:
    """A data store in memory (see the module docstring for the arguments).

    A table given as `None` serves no address: every access gets exception 02.
    """

    def __init__(
        self,
        *,
        coils: BlockSpec | None = None,
        discrete_inputs: BlockSpec | None = None,
        input_registers: BlockSpec | None = None,
        holding_registers: BlockSpec | None = None,
        read_only: Mapping[Table | str, Iterable[range]] | None = None,
        read_only_exception: ExceptionCode = ExceptionCode.ILLEGAL_DATA_ADDRESS,
        fifo_queues: Mapping[int, Iterable[int]] | None = None,
        exception_status: int = 0,
        files: Mapping[int, int | Sequence[int]] | None = None,
        device_identification: Mapping[int, str | bytes] | None = None,
        server_id: ServerId | bytes | None = None,
    ) -> None:
        given = {
            Table.COILS: coils,
            Table.DISCRETE_INPUTS: discrete_inputs,
            Table.INPUT_REGISTERS: input_registers,
            Table.HOLDING_REGISTERS: holding_registers,
        }
        blocks: dict[Table, list[Block]] = {}
        for table, spec in given.items():
            if not isinstance(spec, Table):
                blocks[table] = _blocks_of(table, spec)
        for table, spec in given.items():
            if isinstance(spec, Table):
                blocks[table] = _alias(table, spec, given, blocks)
        self._maps = {table: _TableMap(found) for table, found in blocks.items()}
        self._read_only: dict[Table, tuple[range, ...]] = dict.fromkeys(Table, ())
        for name, ranges in (read_only or {}).items():
            self._read_only[Table(name)] = tuple(ranges)
        if read_only_exception not in _EXCEPTION_CODES:
            raise InvalidValue("read_only_exception", read_only_exception, _EXCEPTION_CODES)
        self.read_only_exception = read_only_exception
        """The exception a master's write into a read-only range gets."""
        self.fifo_queues: dict[int, deque[int]] = {
            address: deque(values) for address, values in (fifo_queues or {}).items()
        }
        """FIFO queues by pointer address; the application appends and pops."""
        if exception_status not in range(0x100):
            raise InvalidValue("exception_status", exception_status, range(0x100))
        self.exception_status = exception_status
        """The byte Read Exception Status (07) answers."""
        self.files: dict[int, list[int]] = {
            number: _file_of(number, spec) for number, spec in (files or {}).items()
        }
        """File records by file number: each file a list of records (registers)."""
        self.device_objects: dict[int, bytes] | None = (
            None if device_identification is None else _device_objects(device_identification)
        )
        """Device identification objects by id; `None` answers 2B/0E with 01."""
        self.server_id: ServerId | None = (
            ServerId(server_id) if isinstance(server_id, bytes) else server_id
        )
        """What Report Server ID (11) answers; `None` answers with the unit address."""
        self._observers: list[Callable[[Change], object]] = []

    # -- the DataStore protocol -----------------------------------------------------

    def read(self, table: Table, address: int, count: int) -> list[int]:
        """Return `count` values of `table` from `address`; exception 02 outside one block."""
        block, offset = self._locate(table, address, count)
        return block.values[offset : offset + count]

    def write(self, table: Table, address: int, values: Sequence[int]) -> None:
        """Store `values` from `address` on behalf of a master; notify the observers.

        Exception 02 outside one block; a read-only range gets
        [`read_only_exception`][aiortu.slave.MemoryStore.read_only_exception].
        """
        count = len(values)
        block, offset = self._locate(table, address, count)
        end = address + count
        for protected in self._read_only[table]:
            if address < protected.stop and protected.start < end:
                raise ExceptionResponse(self.read_only_exception)
        stored = block.values
        if not self._observers:
            stored[offset : offset + count] = values
            return
        previous = tuple(stored[offset : offset + count])
        stored[offset : offset + count] = values
        self._notify(Change(table, address, tuple(stored[offset : offset + count]), previous))

    def read_fifo_queue(self, address: int) -> list[int]:
        """The values of the FIFO queue at `address`, oldest first (left queued)."""
        queue = self.fifo_queues.get(address)
        if queue is None:
            raise ExceptionResponse(ExceptionCode.ILLEGAL_DATA_ADDRESS)
        return list(queue)

    def read_exception_status(self) -> int:
        """The byte Read Exception Status (07) answers."""
        return self.exception_status

    def read_file_record(self, file_number: int, record_number: int, count: int) -> list[int]:
        """`count` records of file `file_number` from `record_number`; 02 if not there."""
        records = self._file(file_number, record_number, count)
        return records[record_number : record_number + count]

    def write_file_record(
        self, file_number: int, record_number: int, values: Sequence[int]
    ) -> None:
        """Store `values` into file `file_number` from `record_number`; 02 if not there."""
        records = self._file(file_number, record_number, len(values))
        records[record_number : record_number + len(values)] = values

    def device_identification(self) -> Mapping[int, bytes]:
        """The device identification objects; exception 01 when the store has none."""
        if self.device_objects is None:
            raise ExceptionResponse(ExceptionCode.ILLEGAL_FUNCTION)
        return self.device_objects

    def report_server_id(self) -> ServerId | None:
        """What Report Server ID (11) answers; `None` for the default (the unit, running)."""
        return self.server_id

    # -- the application's side --------------------------------------------------------

    def get(self, table: Table | str, address: int, count: int = 1) -> list[int]:
        """Return `count` values of `table` from `address`; ExceptionResponse 02 if unmapped."""
        return self.read(Table(table), address, count)

    def set(self, table: Table | str, address: int, values: int | Iterable[int]) -> None:
        """Set values as the device itself: read-only ranges do not apply, observers are not told.

        Raises [`InvalidValue`][aiortu.errors.InvalidValue] for a value outside the table's range
        and [`ExceptionResponse`][aiortu.errors.ExceptionResponse] (02) for an unmapped address.
        """
        table = Table(table)
        items = [values] if isinstance(values, int) else list(values)
        allowed = _BIT_VALUES if table.is_bit else _REGISTER_VALUES
        for index, value in enumerate(items):
            if value not in allowed:
                raise InvalidValue(f"values[{index}]", value, allowed)
        if table.is_bit:
            items = [bool(value) for value in items]
        block, offset = self._locate(table, address, len(items))
        block.values[offset : offset + len(items)] = items

    def blocks(self, table: Table | str) -> tuple[Block, ...]:
        """The blocks of `table`, by start address."""
        return tuple(self._maps[Table(table)].blocks)

    def observe(self, callback: Callable[[Change], object]) -> Callable[[], None]:
        """Call `callback` with a [`Change`][aiortu.slave.Change] after every write a master makes.

        Returns a function that removes the callback. A callback that raises is logged
        and detached; the write and the reply go on as if it were not there.
        """
        self._observers.append(callback)

        def remove() -> None:
            if callback in self._observers:
                self._observers.remove(callback)

        return remove

    def changes(self, max_pending: int = 1024) -> ChangeFeed:
        """An async iterator of the writes masters make from now on (see
        [`ChangeFeed`][aiortu.slave.ChangeFeed])."""
        feed = ChangeFeed(max_pending)
        feed._remove = self.observe(feed._push)
        return feed

    # -- internals -------------------------------------------------------------------

    def _locate(self, table: Table, address: int, count: int) -> tuple[Block, int]:
        table_map = self._maps[table]
        index = bisect_right(table_map.starts, address) - 1
        if index >= 0:
            block = table_map.blocks[index]
            offset = address - block.start
            if count > 0 and offset + count <= block.count:
                return block, offset
        raise ExceptionResponse(ExceptionCode.ILLEGAL_DATA_ADDRESS)

    def _file(self, file_number: int, record_number: int, count: int) -> list[int]:
        records = self.files.get(file_number)
        if records is None or count < 1 or record_number + count > len(records):
            raise ExceptionResponse(ExceptionCode.ILLEGAL_DATA_ADDRESS)
        return records

    def _notify(self, change: Change) -> None:
        for callback in tuple(self._observers):
            try:
                callback(change)
            except Exception:
                # Logged once, not on every later write: a broken observer is dropped.
                _log.exception("a store observer failed on %r; it is detached", change)
                if callback in self._observers:
                    self._observers.remove(callback)


class ChangeFeed:
    """An async iterator of [`Change`][aiortu.slave.Change] records, from
    [`MemoryStore.changes`][aiortu.slave.MemoryStore.changes].

    Changes wait in a queue of at most `max_pending`; when a reader falls behind, the oldest are
    dropped and counted in [`dropped`][aiortu.slave.ChangeFeed.dropped], so a slow reader never
    stalls the slave. Use it in a `with` block, or call [`close`][aiortu.slave.ChangeFeed.close], to
    stop receiving changes.
    """

    def __init__(self, max_pending: int = 1024) -> None:
        if max_pending < 1:
            raise InvalidValue("max_pending", max_pending, "an integer >= 1")
        self._pending: deque[Change] = deque(maxlen=max_pending)
        self._wakeup: anyio.Event | None = None
        self._remove: Callable[[], None] | None = None
        self._closed = False
        self.dropped = 0
        """Changes lost because the queue was full."""

    def _push(self, change: Change) -> None:
        if self._closed:
            return
        if len(self._pending) == self._pending.maxlen:
            self.dropped += 1
        self._pending.append(change)
        if self._wakeup is not None:
            self._wakeup.set()

    def close(self) -> None:
        """Stop receiving changes; iteration ends once the queued ones are read."""
        self._closed = True
        if self._remove is not None:
            self._remove()
            self._remove = None
        if self._wakeup is not None:
            self._wakeup.set()

    def __enter__(self) -> Self:
        return self

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        traceback: TracebackType | None,
    ) -> None:
        self.close()

    def __aiter__(self) -> Self:
        return self

    async def __anext__(self) -> Change:
        while not self._pending:
            if self._closed:
                raise StopAsyncIteration
            self._wakeup = anyio.Event()
            await self._wakeup.wait()
        return self._pending.popleft()


def _blocks_of(table: Table, spec: BlockSpec | None) -> list[Block]:
    """The blocks a table argument describes, checked for overlaps."""
    if spec is None:
        found: list[Block] = []
    elif isinstance(spec, Block):
        found = [spec]
    elif isinstance(spec, Mapping):
        found = [
            Block(start, extent) if isinstance(extent, int) else Block(start, values=extent)
            for start, extent in spec.items()
        ]
    else:
        found = list(spec)  # type: ignore[arg-type]  # a Table was handled by the caller
    for block in found:
        if not isinstance(block, Block):
            raise InvalidValue(table.value, block, "Block objects or a {start: count} mapping")
        _prepare(table, block)
    ordered = sorted(found, key=lambda block: block.start)
    for before, after in itertools.pairwise(ordered):
        if after.start < before.stop:
            raise InvalidValue(
                table.value,
                after,
                "blocks that do not overlap",
                message=f"{table.value}: the block at {after.start}..{after.stop - 1} "
                f"overlaps the block at {before.start}..{before.stop - 1}",
            )
    return found


def _prepare(table: Table, block: Block) -> None:
    """Check (and for bits normalise) a block's values for `table`."""
    allowed = _BIT_VALUES if table.is_bit else _REGISTER_VALUES
    values = block.values
    if values and (min(values) < allowed.start or max(values) >= allowed.stop):
        bad = next(value for value in values if value not in allowed)
        raise InvalidValue(f"{table.value} values", bad, allowed)
    if table.is_bit:
        values[:] = [bool(value) for value in values]


def _alias(
    table: Table,
    target: Table,
    given: Mapping[Table, BlockSpec | None],
    blocks: Mapping[Table, list[Block]],
) -> list[Block]:
    """The blocks of `target`, shared by `table`."""
    if isinstance(given[target], Table):
        raise InvalidValue(table.value, target.value, "a table that is not itself an alias")
    if target.is_bit != table.is_bit:
        raise InvalidValue(table.value, target.value, "a table of the same kind, bits or registers")
    return blocks[target]


def _file_of(number: int, spec: int | Sequence[int]) -> list[int]:
    """The records of file `number`: `spec` records of 0, or the values given."""
    if number not in _FILE_NUMBERS:
        raise InvalidValue("files key", number, _FILE_NUMBERS)
    records = [0] * spec if isinstance(spec, int) else list(spec)
    if len(records) not in _FILE_LENGTHS:
        raise InvalidValue(f"files[{number}] length", len(records), _FILE_LENGTHS)
    for index, value in enumerate(records):
        if value not in _REGISTER_VALUES:
            raise InvalidValue(f"files[{number}][{index}]", value, _REGISTER_VALUES)
    return records


def _device_objects(objects: Mapping[int, str | bytes]) -> dict[int, bytes]:
    """The objects as bytes by id, checked; sorted by id, as streams send them."""
    found: dict[int, bytes] = {}
    for object_id in sorted(objects):
        if object_id not in _OBJECT_IDS:
            raise InvalidValue("device_identification key", object_id, _OBJECT_IDS)
        value = objects[object_id]
        data = value.encode() if isinstance(value, str) else bytes(value)
        if len(data) > _MAX_OBJECT_LENGTH:
            raise InvalidValue(
                f"device_identification[{object_id}] length",
                len(data),
                range(_MAX_OBJECT_LENGTH + 1),
                "an object must fit one reply",
            )
        found[object_id] = data
    return found

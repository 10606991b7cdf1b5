"""Range handlers: one function serves an address range of one table for a slave unit.

A range handler stands in for the data store on its addresses, for every function code
that touches them (01-06, 0F, 10, 16, 17):

    def temperature(access: RangeAccess) -> list[int] | None:
        if access.values is None:                      # a read
            return [read_sensor()] * access.count
        raise ExceptionResponse(ExceptionCode.ILLEGAL_DATA_ADDRESS)

    slave.route(Table.INPUT_REGISTERS, range(100, 110), temperature)

It may be a coroutine function. A request that covers part of a routed range and part of something
else gets exception 02, as a device whose map has a hole there would answer.
[`RoutedStore`][aiortu.slave.RoutedStore] is the data store wrapper the slave puts around a unit's
store to do this; everything else (FIFOs, files, ...) goes to the wrapped store.
"""

from __future__ import annotations

from collections.abc import Awaitable, Callable, Sequence
from dataclasses import dataclass
from typing import Any

from aiortu.core.codes import ExceptionCode
from aiortu.core.model import AsyncDataStore, DataStore, Table
from aiortu.errors import ExceptionResponse

__all__ = ("RangeAccess", "RangeHandler", "RoutedStore")


@dataclass(frozen=True, slots=True)
class RangeAccess:
    """One access a master makes to a routed range: `unit`, `table`, the first `address`
    and `count`; `values` are what a write stores, `None` for a read."""

    unit: int
    table: Table
    address: int
    count: int
    values: tuple[int, ...] | None = None

    @property
    def is_write(self) -> bool:
        """Whether the master writes (else it reads)."""
        return self.values is not None


RangeHandler = Callable[[RangeAccess], Sequence[int] | Awaitable[Sequence[int] | None] | None]
"""A range handler: for a read it returns `count` values; for a write its result is
ignored. It may raise [`ExceptionResponse`][aiortu.errors.ExceptionResponse], and be async."""


class RoutedStore:
    """`store` with some ranges served by range handlers instead (see the module docstring)."""

    def __init__(self, store: DataStore | AsyncDataStore, unit: int) -> None:
        self.store = store
        """The wrapped store, which serves everything not routed."""
        self.unit = unit
        """The unit the store serves (passed on to the handlers)."""
        self._routes: dict[Table, list[tuple[range, RangeHandler]]] = {}

    def add(self, table: Table, addresses: range, handler: RangeHandler) -> None:
        """Serve `addresses` of `table` with `handler`; a later route wins where they overlap."""
        self._routes.setdefault(table, []).insert(0, (addresses, handler))

    def _route(self, table: Table, address: int, count: int) -> RangeHandler | None:
        routes = self._routes.get(table)
        if not routes:
            return None
        end = address + count
        for addresses, handler in routes:
            if address < addresses.stop and addresses.start < end:
                if address < addresses.start or end > addresses.stop:
                    raise ExceptionResponse(ExceptionCode.ILLEGAL_DATA_ADDRESS)
                return handler
        return None

    def read(self, table: Table, address: int, count: int) -> Any:
        """The values from the range handler, or from the wrapped store."""
        handler = self._route(table, address, count)
        if handler is None:
            return self.store.read(table, address, count)
        return handler(RangeAccess(self.unit, table, address, count))

    def write(self, table: Table, address: int, values: Sequence[int]) -> Any:
        """Hand the write to the range handler, or to the wrapped store."""
        handler = self._route(table, address, len(values))
        if handler is None:
            return self.store.write(table, address, values)
        return handler(RangeAccess(self.unit, table, address, len(values), tuple(values)))

    def __getattr__(self, name: str) -> Any:
        # The optional capabilities (FIFOs, files, ...) are the wrapped store's.
        return getattr(self.store, name)

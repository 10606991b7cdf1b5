"""The Modbus data model: the four tables, and the protocols a slave's data store follows.

The tables are coils (one bit, read/write), discrete inputs (one bit, read-only), input registers
(16 bits, read-only) and holding registers (16 bits, read/write), each with protocol addresses
0..65535; [`Table`][aiortu.core.model.Table] is
[`aiortu.core.model.Table`][aiortu.core.model.Table], re-exported here. A slave unit
serves them from a [`DataStore`][aiortu.core.model.DataStore]:
[`read`][aiortu.core.model.DataStore.read] and
[`write`][aiortu.core.model.DataStore.write] on a [`Table`][aiortu.core.model.Table],
raising [`ExceptionResponse`][aiortu.errors.ExceptionResponse] with the code the master should get
(02 for an address outside the map). Optional capabilities are separate protocols:

- [`SupportsFifoQueues`][aiortu.core.model.SupportsFifoQueues]: Read FIFO Queue (18);
- [`SupportsExceptionStatus`][aiortu.core.model.SupportsExceptionStatus]: Read Exception Status
  (07);
- [`SupportsFileRecords`][aiortu.core.model.SupportsFileRecords]: Read and Write File Record
  (14, 15);
- [`SupportsDeviceIdentification`][aiortu.core.model.SupportsDeviceIdentification]: Read Device
  Identification (2B/0E);
- [`SupportsServerId`][aiortu.core.model.SupportsServerId]: Report Server ID (11).

Any of these methods may instead return an awaitable (be `async def`): that is an async store, for
example one that proxies another device through a master
([`AsyncDataStore`][aiortu.core.model.AsyncDataStore] spells the protocol out). The slave
awaits such results; a sync store pays nothing for that possibility.

These definitions live in the core because both the slave and the stores
([`aiortu.slave`][aiortu.slave], where users import them from) depend on them.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Protocol, runtime_checkable

from aiortu.core.errors import InvalidValue
from aiortu.core.model._addressing import Table

__all__ = (
    "AsyncDataStore",
    "DataStore",
    "ServerId",
    "SupportsDeviceIdentification",
    "SupportsExceptionStatus",
    "SupportsFifoQueues",
    "SupportsFileRecords",
    "SupportsServerId",
    "Table",
)


@runtime_checkable
class DataStore(Protocol):
    """What a slave unit serves its tables from (see the module docstring).

    Both methods raise [`ExceptionResponse`][aiortu.errors.ExceptionResponse] with the code to
    answer: 02 (`ILLEGAL_DATA_ADDRESS`) when any address of the range is not served, and whatever
    else the store decides (04 when a backing device failed, ...). Any other error makes the slave
    answer 04 and log it.
    """

    def read(self, table: Table, address: int, count: int) -> Sequence[int]:
        """Return `count` values of `table` from `address` (bits as bool or 0/1)."""
        ...

    def write(self, table: Table, address: int, values: Sequence[int]) -> object:
        """Store `values` into `table` from `address`, on behalf of a master.

        Returns `None` (anything else but an awaitable is ignored).
        """
        ...


@runtime_checkable
class AsyncDataStore(Protocol):
    """A [`DataStore`][aiortu.core.model.DataStore] whose methods are coroutines (a proxy to
    another device, ...).

    The slave accepts it wherever it accepts a [`DataStore`][aiortu.core.model.DataStore].
    """

    async def read(self, table: Table, address: int, count: int) -> Sequence[int]:
        """Return `count` values of `table` from `address`."""
        ...

    async def write(self, table: Table, address: int, values: Sequence[int]) -> None:
        """Store `values` into `table` from `address`, on behalf of a master."""
        ...


@runtime_checkable
class SupportsFifoQueues(Protocol):
    """A store that serves Read FIFO Queue (18)."""

    def read_fifo_queue(self, address: int) -> Sequence[int]:
        """The values queued behind the FIFO pointer `address`, oldest first; 02 if none."""
        ...


@runtime_checkable
class SupportsExceptionStatus(Protocol):
    """A store that serves Read Exception Status (07)."""

    def read_exception_status(self) -> int:
        """The eight exception status bits of the device, as one byte."""
        ...


@runtime_checkable
class SupportsFileRecords(Protocol):
    """A store that serves Read File Record (14) and Write File Record (15).

    A file (1..65535) is a run of records (registers) numbered from 0. Both methods
    raise [`ExceptionResponse`][aiortu.errors.ExceptionResponse] 02 for a file the device does not
    have or records past its end.
    """

    def read_file_record(self, file_number: int, record_number: int, count: int) -> Sequence[int]:
        """`count` records of file `file_number` from `record_number`."""
        ...

    def write_file_record(
        self, file_number: int, record_number: int, values: Sequence[int]
    ) -> None:
        """Store `values` into file `file_number` from `record_number`."""
        ...


@runtime_checkable
class SupportsDeviceIdentification(Protocol):
    """A store that serves Read Device Identification (2B/0E)."""

    def device_identification(self) -> Mapping[int, bytes]:
        """The identification objects, by object id (0..255); values of at most 244 bytes."""
        ...


_MAX_SERVER_ID_BYTES = 250


@dataclass(frozen=True, slots=True)
class ServerId:
    """What Report Server ID (11) answers: the `server_id` bytes (at least one), the
    `run_indicator` (running or not), and `additional_data` of the device's own."""

    server_id: bytes
    run_indicator: bool = True
    additional_data: bytes = b""

    def __post_init__(self) -> None:
        object.__setattr__(self, "server_id", bytes(self.server_id))
        object.__setattr__(self, "additional_data", bytes(self.additional_data))
        if not self.server_id:
            raise InvalidValue("server_id", self.server_id, "at least one byte")
        # The reply's byte count covers the id, the run indicator and the data: 250 at most.
        total = len(self.server_id) + 1 + len(self.additional_data)
        if total > _MAX_SERVER_ID_BYTES:
            raise InvalidValue(
                "len(server_id) + 1 + len(additional_data)",
                total,
                range(2, _MAX_SERVER_ID_BYTES + 1),
            )


@runtime_checkable
class SupportsServerId(Protocol):
    """A store that serves Report Server ID (11)."""

    def report_server_id(self) -> ServerId | None:
        """The server id, run indicator and additional data; `None` for the slave's
        default (the unit address as the id, running, no data)."""
        ...

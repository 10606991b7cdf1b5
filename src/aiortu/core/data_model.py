"""The Modbus data model: the four tables, and the protocol a slave's data store follows.

The tables are coils (one bit, read/write), discrete inputs (one bit, read-only), input
registers (16 bits, read-only) and holding registers (16 bits, read/write), each with
protocol addresses 0..65535. A slave unit serves them from a :class:`DataStore`. The
protocol is small and synchronous: :meth:`~DataStore.read` and :meth:`~DataStore.write`
on a :class:`Table`, raising :class:`~aiortu.errors.ExceptionResponse` with the code the
master should get (02 for an address outside the map). Optional capabilities are
separate protocols: :class:`SupportsFifoQueues` for Read FIFO Queue (18) and
:class:`SupportsExceptionStatus` for Read Exception Status (07).

An async variant of the protocol (a store that proxies another device) is allowed by
the design and may be added later; a sync store then keeps costing nothing extra.

These definitions live in the core because both the slave and the stores
(:mod:`aiortu.store`, where users import them from) depend on them.
"""

from __future__ import annotations

import enum
from collections.abc import Sequence
from typing import Protocol, runtime_checkable

__all__ = (
    "DataStore",
    "SupportsExceptionStatus",
    "SupportsFifoQueues",
    "Table",
)


class Table(enum.StrEnum):
    """The four tables of the Modbus data model."""

    COILS = "coils"
    DISCRETE_INPUTS = "discrete_inputs"
    INPUT_REGISTERS = "input_registers"
    HOLDING_REGISTERS = "holding_registers"

    @property
    def holds_bits(self) -> bool:
        """True for the one-bit tables (coils, discrete inputs)."""
        return self in (Table.COILS, Table.DISCRETE_INPUTS)


@runtime_checkable
class DataStore(Protocol):
    """What a slave unit serves its tables from (see the module docstring).

    Both methods raise :class:`~aiortu.errors.ExceptionResponse` with the code to answer:
    02 (``ILLEGAL_DATA_ADDRESS``) when any address of the range is not served, and
    whatever else the store decides (04 when a backing device failed, ...). Any other
    error makes the slave answer 04 and log it.
    """

    def read(self, table: Table, address: int, count: int) -> Sequence[int]:
        """Return *count* values of *table* from *address* (bits as bool or 0/1)."""
        ...

    def write(self, table: Table, address: int, values: Sequence[int]) -> None:
        """Store *values* into *table* from *address*, on behalf of a master."""
        ...


@runtime_checkable
class SupportsFifoQueues(Protocol):
    """A store that serves Read FIFO Queue (18)."""

    def read_fifo_queue(self, address: int) -> Sequence[int]:
        """The values queued behind the FIFO pointer *address*, oldest first; 02 if none."""
        ...


@runtime_checkable
class SupportsExceptionStatus(Protocol):
    """A store that serves Read Exception Status (07)."""

    def read_exception_status(self) -> int:
        """The eight exception status bits of the device, as one byte."""
        ...

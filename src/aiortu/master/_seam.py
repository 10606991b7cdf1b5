"""What a master hands its transactions to: the one request seam.

A [`Master`][aiortu.master.Master] submits every request it makes, whatever method makes it,
as a [`Transaction`][aiortu.core.machines.Transaction] to one object's `submit`: its
line's engine, or a [`Seam`][aiortu.master.Seam] given in place of a byte stream, such as
[`aiortu.testing.MockLine`][aiortu.testing.MockLine], which answers requests without bytes or
timing.
"""

from __future__ import annotations

from collections.abc import Awaitable, Mapping
from typing import Protocol, runtime_checkable

from aiortu.core.machines import Transaction
from aiortu.core.pdu import ExceptionPDU, Response
from aiortu.master._stats import UnitStats

__all__ = ("Seam",)


@runtime_checkable
class Seam(Protocol):
    """Runs a master's transactions (see the module docstring)."""

    @property
    def stats(self) -> Mapping[int, UnitStats]:
        """[`UnitStats`][aiortu.master.UnitStats] by unit, for the units used so far."""
        ...

    def unit_stats(self, unit: int) -> UnitStats:
        """The statistics of `unit` (created empty on first use)."""
        ...

    def submit(self, transaction: Transaction) -> Awaitable[Response | ExceptionPDU | None]:
        """Run `transaction`; the awaitable gives its reply (`None` when it expects none)
        or raises its error ([`ResponseTimeout`][aiortu.errors.ResponseTimeout], ...)."""
        ...

    def clock(self) -> float:
        """The time, in seconds, on the clock the master's users (the poller) go by."""
        ...

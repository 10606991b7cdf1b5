"""A request-level fake of a serial line: a master's requests answered by a function.

    def device(unit: int, request: Request) -> Response | ExceptionPDU | None:
        ...

    async with aiortu.Master(aiortu.testing.MockLine(device)) as master:
        await master.read_holding_registers(1, 0, 2)

[`MockLine`][aiortu.testing.MockLine] stands where a master's line engine stands (the
[`Seam`][aiortu.master.Seam] every request goes through): no bytes, no framing, no timing,
no retries. What the handler returns is the reply; what it raises (a
[`ResponseTimeout`][aiortu.errors.ResponseTimeout], a
[`ConnectionLost`][aiortu.errors.ConnectionLost], ...) is what the call raises. The unit
statistics and health are kept as the engine keeps them.
"""

from __future__ import annotations

import inspect
from collections.abc import Awaitable, Callable, Mapping

import anyio
import anyio.lowlevel

from aiortu.core.errors import CRCError, FrameError, ResponseTimeout
from aiortu.core.machines import Transaction
from aiortu.core.pdu import ExceptionPDU, Request, Response
from aiortu.errors import InvalidValue
from aiortu.master import HealthPolicy, UnitStats

__all__ = ("MockHandler", "MockLine")

MockHandler = Callable[
    [int, Request],
    Response | ExceptionPDU | Awaitable[Response | ExceptionPDU | None] | None,
]
"""`handler(unit, request)`: the reply (an `ExceptionPDU` for an exception reply, `None` for
none), or an awaitable of it; or it raises the error the call raises."""


class MockLine:
    """A fake line that answers each request with `handler(unit, request)` (see the module
    docstring); give it to [`Master`][aiortu.master.Master] in place of a stream.

    `transactions` lists every transaction submitted, in order (a broadcast included: its
    handler's return is ignored). `health` decides when a unit counts as offline, as the
    master's does; `clock` is the time the statistics and the poller go by.
    """

    def __init__(
        self,
        handler: MockHandler,
        *,
        health: HealthPolicy | None = None,
        clock: Callable[[], float] = anyio.current_time,
    ) -> None:
        if not callable(handler):
            raise InvalidValue("handler", handler, "a function (unit, request) -> reply")
        self.handler = handler
        self.health = health if health is not None else HealthPolicy()
        self.transactions: list[Transaction] = []
        """Every transaction submitted, in order."""
        self._clock = clock
        self._stats: dict[int, UnitStats] = {}

    def __repr__(self) -> str:
        return f"MockLine({self.handler!r})"

    @property
    def stats(self) -> Mapping[int, UnitStats]:
        """[`UnitStats`][aiortu.master.UnitStats] by unit, for the units used so far."""
        return self._stats

    def unit_stats(self, unit: int) -> UnitStats:
        """The statistics of `unit` (created empty on first use)."""
        stats = self._stats.get(unit)
        if stats is None:
            stats = self._stats[unit] = UnitStats()
        return stats

    def clock(self) -> float:
        """The line's time, in seconds."""
        return self._clock()

    def submit(self, transaction: Transaction) -> Awaitable[Response | ExceptionPDU | None]:
        """Run `transaction` through the handler (see the module docstring)."""
        return self._run(transaction)

    async def _run(self, transaction: Transaction) -> Response | ExceptionPDU | None:
        await anyio.lowlevel.checkpoint()  # a call yields, as on a real line
        self.transactions.append(transaction)
        stats = self.unit_stats(transaction.unit)
        stats.requests += 1
        try:
            reply = self.handler(transaction.unit, transaction.request)
            if inspect.isawaitable(reply):
                reply = await reply
        except ResponseTimeout:
            stats.timeouts += 1
            stats.count_failure(self.health, self.clock())
            raise
        except FrameError as error:
            if isinstance(error, CRCError):
                stats.crc_errors += 1
            else:
                stats.frame_errors += 1
            stats.count_failure(self.health, self.clock())
            raise
        if not transaction.expects_reply:
            return None
        if not isinstance(reply, Response | ExceptionPDU):
            raise InvalidValue(
                "reply", reply, "a Response or ExceptionPDU", "the MockLine handler's return"
            )
        stats.count_success(0.0, exception=isinstance(reply, ExceptionPDU))
        return reply

"""What the parts of a master's engine share: the line, the machine, the queue, the attempts,
the statistics, and the hand-overs between them.

`LineEngine` is a `LineState`; its fast path
(`_fast_path.py`) and its line task (`_line_task.py`) are given it, and call the hand-overs
it implements (`release`, `take_over`, `adopt`, `exchange`).
"""

from __future__ import annotations

import anyio

from aiortu.core.errors import FrameError
from aiortu.core.machines import Failure, MasterMachine, Outcome, OutcomeKind
from aiortu.core.pdu import ExceptionPDU
from aiortu.errors import ConnectionLost, ResponseTimeout
from aiortu.line import Link, LinkEvent
from aiortu.master._attempt import Attempts
from aiortu.master._config import MasterConfig
from aiortu.master._queue import Job, JobResult, LineQueue
from aiortu.master._stats import UnitStats

__all__ = ("LineState",)


class LineState:
    """The state of a master's line (see the module docstring), under `config`."""

    def __init__(self, link: Link, config: MasterConfig) -> None:
        self.link = link
        self.config = config
        self.health = config.health
        self.machine = MasterMachine()
        self.stats: dict[int, UnitStats] = {}
        """Statistics by unit address."""
        self.min_turnaround = config.timings.min_turnaround
        self.unit_turnaround: dict[int, float] = {}
        """The minimum turnaround of single units."""
        self.queue = LineQueue()
        self.attempts = Attempts(
            link, self.machine, config.timings.late_reply_guard, self.on_time_up
        )
        self.open = False
        """The line task serves a live link."""
        self._connected = anyio.Event()
        self._connected.set()

    def unit_stats(self, unit: int) -> UnitStats:
        """The statistics of `unit` (created empty on first use)."""
        stats = self.stats.get(unit)
        if stats is None:
            stats = self.stats[unit] = UnitStats()
        return stats

    def reply_delay(self, unit: int) -> float | None:
        """The least delay from a request to `unit` leaving the wire to the arrival of its
        reply's first byte, where the link's wire times are real: the unit's minimum
        turnaround plus the byte's own wire time. None where they are not (see
        [`Transaction.reply_delay`][aiortu.core.machines.Transaction.reply_delay])."""
        link = self.link
        if not link.wire_timed:
            return None
        return self.unit_turnaround.get(unit, self.min_turnaround) + link.char_time

    def settle(self, job: Job, outcome: Outcome, stats: UnitStats) -> None:
        """Count `outcome`, the end of `job`'s transaction, and tell its future."""
        transaction = job.transaction
        if transaction.failures or outcome.kind is OutcomeKind.FAILED:
            # A failed attempt may still be answered late, even when a retry succeeded.
            self.attempts.start_guard()
        if outcome.kind is OutcomeKind.FAILED:
            stats.count_failed_attempt(transaction)
            error = outcome.error
            assert error is not None
            if isinstance(error, ResponseTimeout | FrameError):
                stats.count_failure(self.health, self.link.clock())
            job.finish(None, error)
            return
        response = outcome.response
        if response is not None:
            now = self.link.clock()
            latency = now - transaction.attempt_start
            exception = isinstance(response, ExceptionPDU)
            if Failure.TIMEOUT in transaction.failures:
                stats.count_late_success(latency, self.health, now, exception=exception)
            else:
                stats.count_success(latency, exception=exception)
        job.finish(response, None)

    def attach(self, link: Link) -> None:
        """The line task serves `link` (entered) from now on."""
        self.link = self.attempts.link = link
        self.attempts.events.clear()
        self.open = True
        link.listen(self._on_link_event)  # a closed link: `open` is false at once
        try:
            while link.receive_nowait() is not None:  # queued before we listened
                pass
        except ConnectionLost:
            pass
        self._connected.set()

    def detach(self) -> None:
        """The line task stops serving the link: the queue fails with its error."""
        link = self.link
        self.open = False
        link.listen(None)
        self._connected = anyio.Event()
        self.queue.fail_all(str(link.connection_lost_error()))

    # -- the hand-overs, which the engine implements -----------------------------------------

    def release(self) -> None:
        """The transaction that had the line is over: hand the line on."""
        raise NotImplementedError

    def take_over(self, job: Job, on_the_wire: bool) -> None:
        """The machine took `job` over from the fast path: the line task runs the rest (all
        of it unless `on_the_wire`)."""
        raise NotImplementedError

    def adopt(self, job: Job) -> None:
        """`job`'s caller is gone mid-attempt: the line task finishes the attempt."""
        raise NotImplementedError

    async def exchange(self, job: Job, on_the_wire: bool = False) -> JobResult:
        """Run `job`'s transaction through the machine; return its reply."""
        raise NotImplementedError

    def on_time_up(self) -> None:
        """The attempts' timer ran out with no attempt of the machine waiting."""
        raise NotImplementedError

    def _on_link_event(self, event: LinkEvent | None) -> None:
        """The link's listener."""
        raise NotImplementedError

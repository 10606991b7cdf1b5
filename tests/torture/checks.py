"""What every torture scenario checks, whatever it ran on: the report, the ledger of
writes, the wire's t3.5, and what a scenario must leave behind (no task, no timer, no
logged error)."""

from __future__ import annotations

import asyncio
import itertools
import logging
from collections import Counter
from collections.abc import Iterable, Iterator
from contextlib import contextmanager
from dataclasses import dataclass, field

from aiortu.testing import TraceEntry

from .scenarios import CONSTANT, CONSTANTS, MAX_CALLERS, OWN, constant

__all__ = ("Ledger", "Leftovers", "Report", "check_t3_5", "logged_errors")


@dataclass
class Report:
    """What one scenario (*kind* ``master`` or ``slave``) did: *operations* calls, their
    *outcomes* by kind (``ok``, ``cancelled``, or the aiortu error's class name), and
    every *violations* found."""

    seed: int
    kind: str
    description: str
    operations: int = 0
    outcomes: Counter[str] = field(default_factory=Counter)
    violations: list[str] = field(default_factory=list)

    def violation(self, text: str) -> None:
        """Record a broken invariant."""
        self.violations.append(text)

    def message(self) -> str:
        """The failure message: the seed, how to run it alone, and what broke."""
        shown = "\n  ".join(self.violations[:10])
        more = len(self.violations) - 10
        return (
            f"torture {self.kind} seed {self.seed} ({self.description}); rerun with "
            f"AIORTU_TORTURE_SEED={self.seed} pytest tests/torture\n  {shown}"
            + (f"\n  ... and {more} more" if more > 0 else "")
        )


@dataclass
class Ledger:
    """The sequence numbers each caller has begun to write, by caller (and so by own
    register): a write that was cancelled, failed or timed out may still have landed."""

    begun: dict[int, set[int]] = field(default_factory=dict)

    def begin(self, caller: int, sequence: int) -> None:
        """Caller *caller* starts writing its *sequence*-th value."""
        self.begun.setdefault(caller, set()).add(sequence)

    def check_read(self, unit: int, address: int, values: list[int]) -> str | None:
        """Why *values*, read from *address* of *unit*, cannot be right; None if they can."""
        for offset, value in enumerate(values):
            at = address + offset
            if CONSTANT <= at < CONSTANT + CONSTANTS:
                holds = constant(unit, at - CONSTANT)
                if value != holds:
                    return f"unit {unit} register {at} read {value}, holds {holds}"
            elif OWN <= at < OWN + MAX_CALLERS:
                owner, sequence = divmod(value, 256)
                if value != 0 and (owner != at - OWN or sequence not in self.begun.get(owner, ())):
                    return (
                        f"unit {unit} register {at} read {value} (caller {owner}, write "
                        f"{sequence}): caller {at - OWN} never wrote it"
                    )
            else:
                return f"unit {unit} register {at} is outside the map"
        return None


def check_t3_5(trace: Iterable[TraceEntry], t3_5: float) -> str | None:
    """Why the wire breaks t3.5 between frames of different senders; None if it does not."""
    for before, after in itertools.pairwise(trace):
        gap = after.start - before.end
        if before.sender != after.sender and gap < t3_5 - 1e-6:
            return (
                f"{gap * 1e3:.3f} ms between port {before.sender}'s {before.data.hex()} and "
                f"port {after.sender}'s {after.data.hex()} (t3.5 {t3_5 * 1e3:.3f} ms)"
            )
    return None


class _Collector(logging.Handler):
    def __init__(self) -> None:
        super().__init__(logging.ERROR)
        self.records: list[logging.LogRecord] = []

    def emit(self, record: logging.LogRecord) -> None:
        self.records.append(record)


@contextmanager
def logged_errors() -> Iterator[list[logging.LogRecord]]:
    """The records aiortu logs at ERROR or above inside the block (a handler that failed,
    a task that died)."""
    collector = _Collector()
    logger = logging.getLogger("aiortu")
    logger.addHandler(collector)
    try:
        yield collector.records
    finally:
        logger.removeHandler(collector)


class Leftovers:
    """The asyncio tasks and timers that exist when made; :meth:`new` tells what a
    scenario left behind. Timers are the armed handles in the event loop's timer heap
    (``loop._scheduled``, CPython's asyncio): a ``call_at`` nobody cancelled."""

    def __init__(self) -> None:
        self.tasks = asyncio.all_tasks()
        self.timers = set(self._timers())

    @staticmethod
    def _timers() -> list[asyncio.TimerHandle]:
        loop = asyncio.get_running_loop()
        scheduled: list[asyncio.TimerHandle] = getattr(loop, "_scheduled", [])
        return [handle for handle in scheduled if not handle.cancelled()]

    def new(self) -> list[str]:
        """What is left: tasks still running and timers still armed that were not there."""
        left = [
            f"task {task.get_name()}: {task.get_coro()!r}"
            for task in asyncio.all_tasks() - self.tasks
        ]
        left += [f"timer {handle!r}" for handle in self._timers() if handle not in self.timers]
        return left

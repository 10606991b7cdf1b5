"""Who holds a master's line and who waits for it: one job per transaction, one queue.

`LineEngine.submit` makes a `Job` for a transaction that cannot run at once and puts it in
the `LineQueue`, ordered by the transaction's `priority`, then its `order` (lower first),
then by arrival. Each job has one way to be woken: its `future`, completed once,
with `TURN` (the line is the caller's: it runs its transaction itself), with the result
(the engine ran the transaction for it), or with the error that ends it. On an event loop
the future is a future of that loop, and a job queued there gets its result only (the
engine runs it: `Job.caller_runs` is false); elsewhere (trio) an `EventFuture`.
"""

from __future__ import annotations

import enum
import heapq
import itertools
from collections.abc import Callable, Generator
from typing import TYPE_CHECKING, Any, Final, Protocol

import anyio
import anyio.abc

from aiortu.core.machines import Transaction
from aiortu.core.pdu import ExceptionPDU, Response
from aiortu.errors import ConnectionLost

if TYPE_CHECKING:
    import asyncio

__all__ = ("NO_FUTURE", "TURN", "EventFuture", "Job", "JobFuture", "JobResult", "LineQueue", "Turn")

JobResult = Response | ExceptionPDU | None
"""What a transaction returns: the response, the exception response, or nothing (a
request without reply)."""


class Turn(enum.Enum):
    """What a queued job's future is completed with when its caller is handed the line."""

    TURN = "turn"


TURN = Turn.TURN


class JobFuture(Protocol):
    """What a job's caller awaits: an asyncio future, or an `EventFuture`."""

    def done(self) -> bool: ...
    def set_result(self, result: JobResult | Turn, /) -> None: ...
    def set_exception(self, error: BaseException, /) -> None: ...
    def add_done_callback(self, callback: Callable[[Any], object], /) -> None: ...
    def __await__(self) -> Generator[Any, None, JobResult | Turn]: ...


_PENDING: Any = object()


class EventFuture:
    """A future for a backend without an asyncio loop (trio), over an anyio event. Its
    awaiter's cancellation is the engine's to notice (it awaits it in its own coroutine)."""

    __slots__ = ("_error", "_event", "_result")

    def __init__(self, event: anyio.Event) -> None:
        self._event = event
        self._result: JobResult | Turn = _PENDING
        self._error: BaseException | None = None

    def done(self) -> bool:
        return self._event.is_set()

    def set_result(self, result: JobResult | Turn, /) -> None:
        self._result = result
        self._event.set()

    def set_exception(self, error: BaseException, /) -> None:
        self._error = error
        self._event.set()

    def add_done_callback(self, callback: Callable[[EventFuture], object], /) -> None:
        """Nothing to do: the engine's coroutine that awaits this future notices its
        cancellation itself."""

    def __await__(self) -> Generator[Any, None, JobResult | Turn]:
        return self._wait().__await__()

    async def _wait(self) -> JobResult | Turn:
        await self._event.wait()
        if self._error is not None:
            raise self._error
        return self._result


class _Told:
    """The future of a job whose caller runs it and gets its result itself: nobody to tell."""

    __slots__ = ()

    def done(self) -> bool:
        return True

    def set_result(self, result: JobResult | Turn, /) -> None:
        raise AssertionError("a job run by its caller is never woken")

    def set_exception(self, error: BaseException, /) -> None:
        raise AssertionError("a job run by its caller is never woken")

    def add_done_callback(self, callback: Callable[[Any], object], /) -> None:
        raise AssertionError("a job run by its caller is never taken over")

    def __await__(self) -> Generator[Any, None, JobResult | Turn]:
        raise AssertionError("a job run by its caller is never awaited")


NO_FUTURE: Final[JobFuture] = _Told()
"""The future of a job its caller runs at once, on an idle line."""


class Job:
    """A transaction waiting for the line or on it, and the future its caller awaits."""

    __slots__ = ("caller_runs", "future", "granted", "transaction", "woken")

    def __init__(
        self, transaction: Transaction, future: JobFuture, caller_runs: bool = True
    ) -> None:
        self.transaction = transaction
        self.future = future
        """Completed once: `TURN`, the result, or the error (see the module docstring)."""
        self.caller_runs = caller_runs
        """Whether its caller runs the transaction once handed the line (`TURN`); else the
        engine runs it and completes the future with the result."""
        self.granted = False
        """Whether the job was handed the line."""
        self.woken = False
        """Whether its caller was handed the line to run the transaction itself (`TURN`)."""

    def finish(self, response: JobResult, error: BaseException | None) -> None:
        """End the job with `response` or `error`: its caller, if it still waits, is told."""
        future = self.future
        if future.done():
            return  # cancelled: nobody to tell
        if error is None:
            future.set_result(response)
        else:
            future.set_exception(error)

    def abandon_if_cancelled(self, future: asyncio.Future[Any]) -> None:
        """The done callback of an event loop's future whose caller awaits it directly: a
        cancelled caller is gone, and its transaction is finished without retries. (An
        `EventFuture` calls no done callback: the engine notices its caller's cancellation.)"""
        if future.cancelled():
            self.transaction.abandoned = True

    def wake(self) -> None:
        """Hand the line to the job's caller: it runs its transaction itself."""
        if not self.future.done():
            self.woken = True
            self.future.set_result(TURN)


class LineQueue:
    """Whether the line is held (`busy`), and the jobs that wait for it: lower priority
    first, then lower order, then in order of arrival."""

    __slots__ = ("_sequence", "busy", "waiting")

    def __init__(self) -> None:
        self.waiting: list[tuple[int, int, int, Job]] = []
        """A heap of sort keys `(priority, order, sequence, job)` (ints compare in C: a queue of
        10,000 callers costs no more per job than one of ten). Read it; change it through
        the methods."""
        self._sequence = itertools.count()
        self.busy = False
        """The line belongs to a transaction (running, handed over, or left to the line
        task)."""

    def push(self, transaction: Transaction, future: JobFuture, caller_runs: bool = True) -> Job:
        """Queue `transaction`, whose caller awaits `future`; return its job."""
        job = Job(transaction, future, caller_runs)
        key = (transaction.priority, transaction.order, next(self._sequence), job)
        heapq.heappush(self.waiting, key)
        return job

    def next_job(self) -> Job | None:
        """Take the first job whose caller still waits and mark the line as its; None
        (the line marked free) if there is none."""
        heap = self.waiting
        while heap:
            job = heapq.heappop(heap)[3]
            if job.transaction.abandoned or job.future.done():
                continue  # its caller was cancelled while queued
            self.busy = True
            job.granted = True
            return job
        self.busy = False
        return None

    def fail_all(self, why: str) -> None:
        """Fail every queued job with ConnectionLost(`why`)."""
        heap = self.waiting
        while heap:
            heapq.heappop(heap)[3].finish(None, ConnectionLost(why))

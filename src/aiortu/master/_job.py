"""A master's unit of work on its line: one transaction, its place in the queue, and
whoever waits for its result.

`LineEngine` queues a `Job` for each transaction
that must wait for the line (lower `priority` first, then lower `order`, then in order of
arrival) in its
`JobQueue`; the engine hands the line to the first one (`JobQueue.next_job`), either
running its usual exchange at once or waking its caller (`Job.wake`). The caller waits
on a future of the event loop (`Job.waiter`) where the link has a loop, else on an
anyio event (`Job.turn`). The job ends with `Job.finish`, which tells whoever waits: the
caller's task through the same future or event, or, for a usual exchange the machine
took over, the caller's future (`Job.caller`).
"""

from __future__ import annotations

import asyncio
import enum
import heapq
import itertools

import anyio

from aiortu.core.machines import Transaction
from aiortu.core.pdu import ExceptionPDU, Response
from aiortu.errors import ConnectionLost

__all__ = ("TURN", "Job", "JobQueue", "JobResult", "Turn", "Waiter")

JobResult = Response | ExceptionPDU | None
"""What a transaction returns: the response, the exception response, or nothing (a
broadcast)."""


class Turn(enum.Enum):
    """What a queued caller's future is completed with when it is handed the line to run
    its transaction itself (through the machine), or failed while queued."""

    TURN = "turn"


TURN = Turn.TURN

Waiter = asyncio.Future[JobResult | Turn]
"""A queued caller's future: its turn, or the result of the usual exchange the engine
ran for it when it handed it the line."""


class Job:
    """A transaction, its place in the queue, and its result."""

    __slots__ = (
        "caller",
        "done",
        "error",
        "granted",
        "order",
        "priority",
        "response",
        "sequence",
        "transaction",
        "turn",
        "usual",
        "waiter",
    )

    def __init__(
        self, transaction: Transaction, priority: int, sequence: int, order: int = 0
    ) -> None:
        self.transaction = transaction
        self.priority = priority
        self.order = order
        """Its place among equal priorities, before the order of arrival (the gateway's turn
        of the connection, for round-robin)."""
        self.sequence = sequence
        self.waiter: Waiter | None = None
        """A queued job's future, where the link has an event loop: `TURN` when it is
        handed the line or failed while queued, or the result of its usual exchange."""
        self.turn: anyio.Event | None = None
        """Set when a queued job is handed the line or failed while queued (no event
        loop: trio)."""
        self.granted = False
        """Whether the job was handed the line."""
        self.usual = False
        """Whether the engine ran the job's usual exchange when it handed it the line:
        the exchange then holds the line, and completes `waiter`."""
        self.done = False
        self.response: JobResult = None
        self.error: Exception | None = None
        self.caller: Waiter | None = None
        """The future of a usual exchange's caller, for a job the machine took over (see
        `taken_over`)."""

    @property
    def taken_over(self) -> bool:
        """Whether the job is a usual exchange the machine took over: the line task runs
        the whole transaction for a caller who awaits `caller`. Not to be confused
        with a job *adopted* by the line task, whose caller is gone and whose attempt on
        the wire is only finished, never retried."""
        return self.caller is not None

    def take_over(self, caller: Waiter) -> None:
        """Make this the job of a usual exchange whose caller awaits `caller`."""
        self.caller = caller
        if caller.done():
            self.transaction.abandoned = True  # cancelled already: no retries
        else:
            caller.add_done_callback(self.on_caller_done)

    def finish(self, response: JobResult, error: Exception | None) -> None:
        """End the job with `response` or `error`, and tell whoever waits for it."""
        self.response = response
        self.error = error
        self.done = True
        self.wake()
        caller = self.caller
        if caller is not None:
            caller.remove_done_callback(self.on_caller_done)
            if caller.done():
                pass  # cancelled: nobody to tell
            elif error is None:
                caller.set_result(response)
            else:
                caller.set_exception(error)

    def wake(self) -> None:
        """Wake the queued caller: its turn has come (or its job is done)."""
        waiter = self.waiter
        if waiter is not None:
            if not waiter.done():
                waiter.set_result(TURN)
        elif self.turn is not None:
            self.turn.set()

    def on_caller_done(self, caller: Waiter) -> None:
        """The caller's future is done: if cancelled, the caller is gone (no retries)."""
        if caller.cancelled():
            self.transaction.abandoned = True


class JobQueue:
    """Who holds the line (`busy`) and who waits for it: lower priority first, then lower
    order, then in order of arrival."""

    __slots__ = ("_sequence", "busy", "waiting")

    def __init__(self) -> None:
        self.waiting: list[tuple[int, int, int, Job]] = []
        """The queued jobs by (priority, order, sequence), a heap (read it; change it through
        the methods). Tuples of ints compare without calling Python code: a queue of
        10,000 callers costs no more per job than one of ten."""
        self._sequence = itertools.count()
        self.busy = False
        """The line belongs to a transaction (running, handed over, or left to the line
        task)."""

    def new_job(self, transaction: Transaction, priority: int, order: int = 0) -> Job:
        """A job for `transaction`, next in order of arrival among equal (priority, order)."""
        return Job(transaction, priority, next(self._sequence), order)

    def push(self, job: Job) -> None:
        """Queue `job` (it has its `Job.waiter` or `Job.turn`)."""
        heapq.heappush(self.waiting, (job.priority, job.order, job.sequence, job))

    def next_job(self) -> Job | None:
        """Take the first job whose caller still waits, and mark the line as its; None
        (the line marked free) if there is none. The engine hands it the line."""
        heap = self.waiting
        while heap:
            job = heapq.heappop(heap)[3]
            waiter = job.waiter
            if job.transaction.abandoned or (waiter is not None and waiter.done()):
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
            job = heapq.heappop(heap)[3]
            if not job.done:
                job.finish(None, ConnectionLost(why))

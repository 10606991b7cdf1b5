"""A master's unit of work on its line: one transaction, its place in the queue, and
whoever waits for its result.

`LineEngine` queues a `Job` for each transaction
that must wait for the line (lower `priority` first, then in order of arrival) and hands
the line to the first one by setting its `Job.turn`. The job ends with
`Job.finish`, which tells whoever waits: the caller's task through the same event,
or, for a usual exchange the machine took over, the caller's future
(`Job.caller`).
"""

from __future__ import annotations

import asyncio

import anyio

from aiortu.core.master_transaction import Transaction
from aiortu.core.pdu import ExceptionPDU, Response

__all__ = ("Job", "JobResult")

JobResult = Response | ExceptionPDU | None
"""What a transaction returns: the response, the exception response, or nothing (a
broadcast)."""


class Job:
    """A transaction, its place in the queue, and its result."""

    __slots__ = (
        "caller",
        "done",
        "error",
        "granted",
        "priority",
        "response",
        "sequence",
        "transaction",
        "turn",
    )

    def __init__(self, transaction: Transaction, priority: int, sequence: int) -> None:
        self.transaction = transaction
        self.priority = priority
        self.sequence = sequence
        self.turn: anyio.Event | None = None
        """Set when a queued job is handed the line, or failed while queued."""
        self.granted = False
        """Whether the job was handed the line."""
        self.done = False
        self.response: JobResult = None
        self.error: Exception | None = None
        self.caller: asyncio.Future[JobResult] | None = None
        """The future of a usual exchange's caller, for a job the machine took over: the
        line task runs the job, and `finish` completes the future (see
        `submit_request`)."""

    def __lt__(self, other: Job) -> bool:
        return (self.priority, self.sequence) < (other.priority, other.sequence)

    def finish(self, response: JobResult, error: Exception | None) -> None:
        """End the job with `response` or `error`, and tell whoever waits for it."""
        self.response = response
        self.error = error
        self.done = True
        if self.turn is not None:
            self.turn.set()
        caller = self.caller
        if caller is not None:
            caller.remove_done_callback(self.on_caller_done)
            if caller.done():
                pass  # cancelled: nobody to tell
            elif error is None:
                caller.set_result(response)
            else:
                caller.set_exception(error)

    def on_caller_done(self, caller: asyncio.Future[JobResult]) -> None:
        """The caller's future is done: if cancelled, the caller is gone (no retries)."""
        if caller.cancelled():
            self.transaction.abandoned = True

"""The master's line: one transaction at a time on one line, for any number of callers.

`LineEngine` runs the sans-IO [`MasterMachine`][aiortu.core.machines.MasterMachine] on a
[`Link`][aiortu.line.Link]. Every caller (the master's methods, the handles, the poller, the
line server) hands it a [`Transaction`][aiortu.core.machines.Transaction] through one
method, `LineEngine.submit`, and awaits what it returns. Its parts, one module each:

- the queue (`_queue.py`): who holds the line, who waits for it, in the transactions' order;
- the fast path (`_fast_path.py`): a register read whose reply comes as usual, without the
  machine, behind one predicate;
- one attempt through the machine (`_attempt.py`): the send, the wait with its timer, the
  late-reply guard;
- the line task (`_line_task.py`): what no caller can run, and a dead link.

On an idle line the transaction runs in the task of the caller that submitted it: the
caller sends the request and waits for the reply itself (or awaits the future of the fast
path, which sent it), so a read costs no hand-over between tasks. When the line is busy,
the caller queues; the transaction that ends hands the line to the next one
(`LineEngine.release`), running its fast path where the predicate lets it, so a queue of
reads costs what one caller costs. On a line with an event loop the engine runs every
queued transaction itself (the fast path, else the line task through the machine) and
completes the caller's future with the result, so a caller may finish from the future's
done-callback, with no task (the line server does); elsewhere the caller is handed the line
(`TURN`) and runs it in its own task.

Cancellation never leaves the line half way through an exchange. A caller cancelled while
queued is dropped; one cancelled before its request began to go out gives the line up at
once (a queued transaction the line task runs for it still goes out once the line task has
begun it, without retries); one cancelled after that leaves its attempt to the line task,
which finishes it without retries, then hands the line on.

It keeps [`UnitStats`][aiortu.master.UnitStats] per unit and their health: a unit is offline
after *offline_after* consecutive failed transactions, and online again after a success. With
*fail_fast_offline*, a request to an offline unit raises [`UnitOffline`][aiortu.errors.UnitOffline]
at once, except for one probe every *probe_interval* seconds. When the link fails, the request
in flight and the queued ones fail with ConnectionLost; requests made while the line is down
wait for it within their timeout, or fail at once (see
[`ReconnectPolicy`][aiortu.master.ReconnectPolicy]).
"""

from __future__ import annotations

from collections.abc import Awaitable

import anyio

from aiortu.core.machines import MasterState, OutcomeKind, Transaction
from aiortu.errors import ConnectionLost, UnitOffline
from aiortu.line import Link, LinkEvent
from aiortu.master._attempt import NO_GUARD
from aiortu.master._config import MasterConfig
from aiortu.master._fast_path import FastPath
from aiortu.master._line_state import LineState
from aiortu.master._line_task import LineTask
from aiortu.master._queue import NO_FUTURE, TURN, EventFuture, Job, JobFuture, JobResult
from aiortu.master._stats import HealthPolicy, UnitStats

__all__ = ("HealthPolicy", "LineEngine", "UnitOffline", "UnitStats")


class LineEngine(LineState):
    """The master's side of one line (see the module docstring).

    `config` gives its policies; `can_reconnect` says whether the line comes back after it
    fails (requests made meanwhile then wait for it, unless the reconnect policy fails fast).
    """

    def __init__(
        self, link: Link, config: MasterConfig | None = None, *, can_reconnect: bool
    ) -> None:
        super().__init__(link, config if config is not None else MasterConfig())
        self._wait_for_reconnect = can_reconnect
        self.fast = FastPath(self)
        self.line_task = LineTask(self)
        self._failed: ConnectionLost | None = None

    def clock(self) -> float:
        """The line's time, in seconds."""
        return self.link.clock()

    @property
    def late_reply_guard(self) -> float:
        """The silence kept after a failed attempt, in seconds."""
        return self.attempts.guard_seconds

    @property
    def transactions(self) -> int:
        """Transactions run on the line (abandoned ones included)."""
        return sum(stats.requests for stats in self.stats.values())

    @property
    def busy(self) -> bool:
        """Whether a transaction holds the line (running, or left to the line task)."""
        return self.queue.busy

    @property
    def queued(self) -> int:
        """Callers waiting for the line."""
        return len(self.queue.waiting)

    def set_unit_turnaround(self, unit: int, seconds: float | None) -> None:
        """Set `unit`'s minimum turnaround (`None`: back to the configured one)."""
        if seconds is None:
            self.unit_turnaround.pop(unit, None)
        else:
            self.unit_turnaround[unit] = seconds

    # -- the seam ---------------------------------------------------------------------------------

    def submit(self, transaction: Transaction) -> Awaitable[JobResult]:
        """Run `transaction` when the line is free, in its `order` among those waiting;
        return the awaitable of its reply (`None` without one).

        Awaiting it raises the transaction's error (ResponseTimeout, FrameError,
        ConnectionLost) and [`UnitOffline`][aiortu.errors.UnitOffline] when failing fast. If
        the caller is cancelled, the request is dropped from the queue or, when in flight,
        finished without retries. Where the fast path runs the transaction, its request is
        on the wire when this returns, and the awaitable is a future.
        """
        future = self.fast.start(transaction)
        if future is None and self.link.loop is not None and self._queues_at_once(transaction):
            # Behind a busy line on an event loop: the engine runs the transaction when its
            # turn comes (the fast path, else the line task), and completes the future.
            transaction.reply_delay = self.reply_delay(transaction.unit)
            future = self._queue(transaction, caller_runs=False).future
        if future is not None:
            return future  # type: ignore[return-value]  # completed with a result only
        return self._submit(transaction)

    def _queues_at_once(self, transaction: Transaction) -> bool:
        """Whether `transaction` goes straight into the queue: the line is up and held,
        and it is not a request that fail-fast may refuse (to a unit known offline)."""
        if not (self.queue.busy and self.open and self._failed is None):
            return False
        if not (self.health.fail_fast_offline and transaction.expects_reply):
            return True
        stats = self.stats.get(transaction.unit)
        return stats is None or stats.online

    async def _submit(self, transaction: Transaction) -> JobResult:
        if self._failed is not None:
            raise ConnectionLost(str(self._failed))
        if not self._connected.is_set():
            await self._wait_connected(transaction.timeout)
        if self.health.fail_fast_offline and transaction.expects_reply:
            # A request that gets no reply is sent all the same: 08/01 to a unit in
            # listen-only mode is how it comes back.
            self._check_offline(transaction.unit)
        transaction.reply_delay = self.reply_delay(transaction.unit)
        queue = self.queue
        if not queue.busy and self.open:
            queue.busy = True  # an idle line: the transaction runs at once, here
            return await self._run(Job(transaction, NO_FUTURE))
        job = self._queue(transaction)
        try:
            result = await job.future
        except BaseException:
            self._left_queue(job)
            raise
        if result is not TURN:
            return result  # the fast path ran it when the line was handed to it
        return await self._run(job)

    async def _run(self, job: Job) -> JobResult:
        """Run `job`, which has the line; return its reply."""
        try:
            return await self.exchange(job)
        finally:
            if self.line_task.job is not job:
                self.release()

    def _queue(self, transaction: Transaction, caller_runs: bool = True) -> Job:
        """Queue `transaction`; return its job, whose caller runs it when handed the line
        (`caller_runs`), else the engine does."""
        link = self.link
        loop = link.loop
        if loop is not None:
            future: JobFuture = loop.create_future()
        else:
            backend = link.backend
            future = EventFuture(anyio.Event() if backend is None else backend.create_event())
        job = self.queue.push(transaction, future, caller_runs)
        if not self.queue.busy and self.open:
            self.release()
        return job

    def _left_queue(self, job: Job) -> None:
        """The caller of queued `job` is gone (cancelled, or failed) while it waited."""
        if job.woken:
            self.release()  # handed the line, yet gone: hand it on
        else:
            # Still queued: the queue skips it. Or its fast path holds the line, and sees
            # the future cancelled.
            job.transaction.abandoned = True

    def release(self) -> None:
        """The transaction that had the line is over (or nobody had it): hand the line to
        the first queued job, running its fast path at once where the predicate lets it,
        else waking its caller."""
        queue = self.queue
        if not self.open:
            # The queue waits for the line task: it fails it (dead link) or serves it.
            queue.busy = False
            self.line_task.wake()
            return
        job = queue.next_job()
        if job is None:
            return
        if self.fast.start(job.transaction, job) is not None:
            return
        if job.caller_runs:
            job.wake()
        else:
            # Nobody runs it but the engine: the line task, through the machine.
            job.future.add_done_callback(job.abandon_if_cancelled)
            self.line_task.take_over(job, on_the_wire=False)

    # -- a transaction through the machine ----------------------------------------------------

    async def exchange(self, job: Job, on_the_wire: bool = False) -> JobResult:
        """Run `job`'s transaction on the line, which is the caller's meanwhile; return its
        reply and tell its future (raise its error).

        `on_the_wire` is for a fast-path exchange taken over: the machine has begun the
        transaction and its first attempt is on the wire.
        """
        transaction = job.transaction
        machine = self.machine
        attempts = self.attempts
        stats = self.stats.get(transaction.unit) or self.unit_stats(transaction.unit)
        if not on_the_wire:
            stats.requests += 1
            machine.begin(transaction)
        try:
            while True:
                if on_the_wire:
                    on_the_wire = False  # a retry sends the request again
                elif attempts.guard_until != NO_GUARD or not attempts.send_at_once():
                    await attempts.send()
                failures = len(transaction.failures)
                outcome = await attempts.outcome(stats)
                if outcome.kind is not OutcomeKind.RETRY:
                    break
                stats.count_failed_attempt(transaction)
                stats.retries += 1
                if len(transaction.failures) > failures:
                    attempts.start_guard()  # timed out or garbled: its reply may still come
        except ConnectionLost as error:
            # Back to IDLE, wherever the line failed: the next line may serve again.
            machine.connection_lost(error)
            job.finish(None, error)
            raise
        except BaseException:
            if self.line_task.job is job:
                raise  # the line task's own, cancelled: it gives the attempt up
            if machine.state is not MasterState.IDLE:
                # The caller is gone with an attempt on the wire (its frame may be on its
                # way): the line task finishes the attempt, without retries.
                self.adopt(job)
            else:
                # Gone before the request went out: nothing is on the wire. An earlier
                # attempt may still be answered late: keep the guard.
                transaction.abandoned = True
                if transaction.failures:
                    attempts.start_guard()
            raise
        self.settle(job, outcome, stats)
        if outcome.error is not None:
            raise outcome.error
        return outcome.response

    # -- the link -----------------------------------------------------------------------------

    def _on_link_event(self, event: LinkEvent | None) -> None:
        """The link's listener: the attempt that waits gets `event`; so does the machine,
        taking the fast path's exchange over, if one is on the wire."""
        fast = self.fast
        if event is None:
            self.open = False
            self.line_task.wake()
            if fast.waiting:
                # Nothing was sent: its caller fails as a queued one does, and the line is
                # free for the line task to see the link gone.
                fast.stop_waiting(self.link.connection_lost_error())
                self.release()
        if fast.on_wire:
            fast.take_over()
        self.attempts.deliver(event)

    def take_over(self, job: Job, on_the_wire: bool) -> None:
        self.line_task.take_over(job, on_the_wire)

    def adopt(self, job: Job) -> None:
        self.line_task.adopt(job)

    def on_time_up(self) -> None:
        """The timer ran out with no attempt of the machine waiting."""
        fast = self.fast
        if fast.on_wire:
            fast.take_over()  # the line task finds the time up

    def close(self, error: ConnectionLost) -> None:
        """Fail every queued request, and every later one, with `error` (first error wins)."""
        if self._failed is None:
            self._failed = error
        self.open = False
        why = str(self._failed)
        self.queue.fail_all(why)
        fast = self.fast
        if fast.waiting:
            fast.stop_waiting(ConnectionLost(why))
        if fast.on_wire:
            # The line task is gone: nobody takes the fast path's exchange over.
            fast.on_wire = False
            self.link.forget_expected()
            fast.fail(ConnectionLost(why))
        job = self.line_task.job
        if job is not None:
            job.finish(None, ConnectionLost(why))
        self.attempts.stop_timer()  # a closed master leaves no timer armed on the loop
        self._connected.set()

    # -- reconnecting and health --------------------------------------------------------------

    @property
    def connected(self) -> bool:
        """Whether the line is up: False while a reconnect is under way and once closed."""
        return self._connected.is_set() and self._failed is None

    async def wait_connected(self) -> None:
        """Wait until the line is up (at once if it is), or the engine is closed."""
        # The event is replaced at each disconnect: wait on the current one.
        while not self._connected.is_set():
            await self._connected.wait()

    async def _wait_connected(self, seconds: float) -> None:
        """Wait up to `seconds` for the line to come back, else raise ConnectionLost."""
        if not self._wait_for_reconnect:
            raise ConnectionLost("the line is down")
        if self.config.reconnection.fail_fast:
            raise ConnectionLost("the line is down and reconnecting; not sent (fail fast)")
        with anyio.move_on_after(seconds):
            await self.wait_connected()
        if self._failed is not None:
            raise ConnectionLost(str(self._failed))
        if not self._connected.is_set():
            raise ConnectionLost(f"the line is down and did not come back within {seconds} s")

    def _check_offline(self, unit: int) -> None:
        # Any unit whose reply is awaited: a broadcast awaits none and never comes here, and
        # unit 0 that does (over Modbus TCP, UDP or TLS) is a unit like any other.
        stats = self.stats.get(unit)
        if stats is None or stats.online:
            return
        now = self.link.clock()
        if now - stats.last_probe < self.health.probe_interval:
            raise UnitOffline(unit, stats.consecutive_failures)
        stats.last_probe = now

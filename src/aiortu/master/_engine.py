"""The master's line: one transaction at a time on one line, for any number of callers.

`LineEngine` owns a [`Link`][aiortu.line.Link] and runs the sans-IO
[`MasterMachine`][aiortu.core.machines.MasterMachine] on it. Callers hand it
[`Transaction`][aiortu.core.machines.Transaction] objects through `LineEngine.submit`.

The line belongs to one transaction at a time, and the transaction runs in the task of
the caller that submitted it: the caller sends the request and waits for the reply
itself, so a read on an idle line costs no hand-over between tasks. When the line is
busy, the caller queues (`JobQueue`: lower *priority* first)
and waits for its turn; the transaction that ends hands the line straight to the next
one. The link hands every frame to the engine ([`listen`][aiortu.line.Link.listen]),
which wakes the waiting transaction directly.

A register read on an idle serial line may skip the machine while its reply comes as
usual: that fast path lives in [`aiortu.master`][aiortu.master], behind one
predicate; `LineEngine.submit_request` calls into it. So does the hand-over: the line
handed to a queued register read runs its usual exchange at once, from the callback
that ended the transaction before it (`LineEngine._grant_next`), so a queue of reads
costs what one caller costs. A queued caller waits on a future of the event loop where
the link has one (the usual exchange completes it), else on an anyio event (trio).

Cancellation never leaves the line half way through an exchange. A caller cancelled
while queued is dropped; one cancelled before its request began to go out gives the line
up at once; one cancelled after that leaves its transaction to the engine's line task
(`LineEngine.serve`), which *adopts* it: it finishes the attempt in flight (its
reply must not reach a later request) without retries, then hands the line on. The line
task also runs the usual exchanges the machine *took over* (for callers who still wait)
and notices a dead link. So the exchanges on the line stay strictly one after the other,
as if one task ran them all. When the line task itself is cancelled (the master closes),
the attempt it runs is given up through the machine and the line is not handed on.

After a failed attempt (timeout or frame error) nothing goes out, the retry included,
until the line has been silent for the late-reply guard (`guard_ends`).

It also keeps [`UnitStats`][aiortu.master.UnitStats] per unit and their health: a unit is offline
after *offline_after* consecutive failed transactions, and online again after a success. With
*fail_fast_offline*, a request to an offline unit raises [`UnitOffline`][aiortu.errors.UnitOffline]
at once, except for one probe every *probe_interval* seconds.

When the link fails, the request in flight and the queued ones fail with
ConnectionLost and `LineEngine.serve` returns; the
`LineConnection` closes the engine for good or serves it
again on a reopened link, while `LineEngine.submit` waits for the line within the
request's timeout or fails at once (see `LineEngine.wait_for_reconnect`).
"""

from __future__ import annotations

import math
from collections import deque
from collections.abc import Awaitable
from typing import Any

import anyio

from aiortu.core.codes import BROADCAST_UNIT
from aiortu.core.errors import FrameError
from aiortu.core.machines import (
    Failure,
    MasterMachine,
    MasterState,
    Outcome,
    OutcomeKind,
    RetryPolicy,
    Transaction,
    frame_error_from_discard,
)
from aiortu.core.pdu import ExceptionPDU, Request, Response
from aiortu.core.rtu import FrameReceived
from aiortu.errors import ConnectionLost, ResponseTimeout, UnitOffline
from aiortu.line import Link, LinkEvent
from aiortu.master._job import TURN, Job, JobQueue, Waiter
from aiortu.master._stats import HealthPolicy, UnitStats
from aiortu.master._usual_exchange import (
    UsualExchange,
    send_usual_exchange,
    take_over,
    usual_exchange_for,
)

__all__ = ("HealthPolicy", "LineEngine", "UnitOffline", "UnitStats", "guard_ends")

_NO_GUARD = -math.inf


def guard_ends(quiet_until: float, last_activity: float, guard: float) -> float:
    """When the late-reply guard is kept: `guard` seconds of silence on the line after
    the failure that set `quiet_until` (the failure plus `guard`).

    Bytes that arrive meanwhile (`last_activity`: the line's last byte) start the silence
    again, at most once over: a line that never falls silent delays a request by two
    guards, not for ever.
    """
    return max(quiet_until, min(last_activity, quiet_until) + guard)


class _LateReplyGuard:
    """The silence kept after a failed attempt before anything goes out (see
    `guard_ends`)."""

    __slots__ = ("seconds", "until")

    def __init__(self, seconds: float) -> None:
        self.seconds = seconds
        self.until = _NO_GUARD
        """The failure plus `seconds`, until a request has kept the guard."""


class _Inbox:
    """What the link delivered to the transaction on the line, and how it is woken."""

    __slots__ = ("arrival", "deadline", "events", "timer", "timer_at", "waiter")

    def __init__(self) -> None:
        self.events: deque[LinkEvent] = deque()
        self.waiter: Any = None
        """The event loop future a transaction waits on, where the link has a loop."""
        self.arrival: anyio.Event | None = None
        """The event a transaction waits on elsewhere."""
        self.deadline = math.inf
        """When the wait in progress ends (the machine's deadline, or the usual
        exchange's response timeout)."""
        self.timer: Any = None
        """One event loop timer for every wait (see LineEngine._arm_timer)."""
        self.timer_at = math.inf


class LineEngine:
    """The master's side of one line (see the module docstring).

    `late_reply_guard` is the silence, in seconds, kept after a failed attempt (timeout
    or frame error) before anything goes out, the retry included (see
    `guard_ends`): a reply that turns up that late is dropped as stale.
    `frame_error_grace` is how long a wait goes on after bad bytes.
    """

    def __init__(
        self,
        link: Link,
        *,
        health: HealthPolicy | None = None,
        late_reply_guard: float = 0.1,
        frame_error_grace: float = 0.05,
    ) -> None:
        self.link = link
        self.health = health if health is not None else HealthPolicy()
        self.machine = MasterMachine(frame_error_grace=frame_error_grace)
        self.stats: dict[int, UnitStats] = {}
        """Statistics by unit address."""
        self.wait_for_reconnect = False
        """Whether requests made while the line is down wait for it to come back (set by
        `LineConnection` when it can reopen the port)."""
        self.fail_fast_reconnect = False
        """With `wait_for_reconnect`: raise at once instead of waiting."""
        self.usual_exchanges = True
        """Whether register reads may run their usual exchange without the machine (see
        [`aiortu.master`][aiortu.master]); false runs every transaction through it."""
        self.min_turnaround = 0.0
        """Seconds from the end of a request on the wire to the first byte of a reply
        that every unit takes at least, unless `unit_turnaround` says otherwise."""
        self.unit_turnaround: dict[int, float] = {}
        """The minimum turnaround of single units (see `min_turnaround`)."""
        self._guard = _LateReplyGuard(late_reply_guard)
        self._jobs = JobQueue()
        self._open = False
        """The line task serves a live link, and the engine is not closed."""
        self._inbox = _Inbox()
        self._usual: UsualExchange | None = None
        """The usual exchange on the wire."""
        self._for_line_task: Job | None = None
        """The job the line task runs: adopted, or taken over (see `Job.taken_over`)."""
        self._wake = anyio.Event()
        self._failed: ConnectionLost | None = None
        self._connected = anyio.Event()
        self._connected.set()

    @property
    def late_reply_guard(self) -> float:
        """The silence kept after a failed attempt, in seconds."""
        return self._guard.seconds

    @property
    def transactions(self) -> int:
        """Transactions run on the line (abandoned ones included)."""
        return sum(stats.requests for stats in self.stats.values())

    @property
    def busy(self) -> bool:
        """Whether a transaction holds the line (running, or left to the line task)."""
        return self._jobs.busy

    @property
    def queued(self) -> int:
        """Callers waiting for the line."""
        return len(self._jobs.waiting)

    # -- the callers' side -----------------------------------------------------------

    def unit_stats(self, unit: int) -> UnitStats:
        """The statistics of `unit` (created empty on first use)."""
        stats = self.stats.get(unit)
        if stats is None:
            stats = self.stats[unit] = UnitStats()
        return stats

    def reply_delay(self, unit: int) -> float | None:
        """The least delay from a request to `unit` leaving the wire to the arrival of
        its reply's first byte, where the link's wire times are real: the unit's minimum
        turnaround plus the byte's own wire time. None where they are not (see
        [`Transaction.reply_delay`][aiortu.core.machines.Transaction.reply_delay])."""
        link = self.link
        if not link.wire_timed:
            return None
        return self.unit_turnaround.get(unit, self.min_turnaround) + link.char_time

    async def submit(
        self, transaction: Transaction, priority: int = 0, order: int = 0
    ) -> Response | ExceptionPDU | None:
        """Run `transaction` when the line is free, and return the reply (`None`
        without one). Queued transactions go by lower `priority`, then lower `order`, then
        in order of arrival.

        Raises the transaction's error (ResponseTimeout, FrameError, ConnectionLost) and
        [`UnitOffline`][aiortu.errors.UnitOffline] when failing fast. If the caller is cancelled,
        the request is dropped from the queue or, when in flight, finished without retries.
        """
        if self._failed is not None:
            raise ConnectionLost(str(self._failed))
        if not self._connected.is_set():
            await self._wait_connected(transaction.timeout)
        if self.health.fail_fast_offline and transaction.expects_reply:
            # A request that gets no reply is sent all the same: 08/01 to a unit in
            # listen-only mode is how it comes back.
            self._check_offline(transaction.unit)
        transaction.reply_delay = self.reply_delay(transaction.unit)
        jobs = self._jobs
        job = jobs.new_job(transaction, priority, order)
        if jobs.busy or not self._open:
            # Wait for the turn here, not in a coroutine of its own: one frame less
            # for each of many waiting callers.
            waiter = self._queue(job)
            try:
                if waiter is not None:
                    result = await waiter
                    if result is not TURN:
                        return result  # its usual exchange ran when it was handed the line
                else:
                    assert job.turn is not None
                    await job.turn.wait()
            except BaseException:
                self._left_queue(job)
                raise
        else:
            jobs.busy = True  # an idle line: the transaction runs at once, here
        return await self._run(job)

    async def _run(self, job: Job) -> Response | ExceptionPDU | None:
        """Run `job`, which has the line; return its reply."""
        if not job.done:
            try:
                await self._exchange(job)
            finally:
                if self._for_line_task is not job:
                    self._release()
        if job.error is not None:
            raise job.error
        return job.response

    def submit_request(
        self,
        unit: int,
        request: Request,
        response_timeout: float,
        policy: RetryPolicy,
        priority: int = 0,
    ) -> Awaitable[Response | ExceptionPDU | None]:
        """`submit` of `Transaction(unit, request, response_timeout, policy)`, as
        an awaitable: where the usual exchange may run (see
        [`aiortu.master`][aiortu.master]), the request goes out now and the return is
        the future its reply completes; else the coroutine of `submit`.
        """
        exchange = self._start_usual(unit, request, response_timeout, policy, priority=priority)
        if exchange is not None:
            # Completed with a result only: nobody hands this future a turn. (No
            # typing.cast: it is a call on every read.)
            return exchange.caller  # type: ignore[return-value]
        return self.submit(Transaction(unit, request, response_timeout, policy), priority)

    def _start_usual(
        self,
        unit: int,
        request: Request,
        response_timeout: float,
        policy: RetryPolicy,
        *,
        priority: int,
        waiter: Waiter | None = None,
    ) -> UsualExchange | None:
        """Send `request`'s usual exchange now where the predicate lets it run, and
        return it; else None, nothing sent.

        `waiter` is the future of a queued caller the line is being handed to (the
        exchange completes it); without one, the line must be free and the exchange
        makes its own future.
        """
        link = self.link
        jobs = self._jobs
        known = usual_exchange_for(
            unit,
            request,
            enabled=self.usual_exchanges,
            line_free=self._open and not jobs.busy,
            handed_line=waiter is not None,
            guard_pending=self._guard.until != _NO_GUARD,
            fail_fast_offline=self.health.fail_fast_offline,
            link=link,
            machine=self.machine,
        )
        if known is None:
            return None
        inbox = self._inbox
        inbox.events.clear()  # nothing that came before can answer it
        stats = self.stats.get(unit) or self.unit_stats(unit)
        exchange = send_usual_exchange(
            link,
            known,
            stats,
            timeout=response_timeout,
            policy=policy,
            priority=priority,
            done=self._release,
            stale=self._on_link_event,
            reply_delay=self.reply_delay(unit),
            caller=waiter,
        )
        if exchange is None:
            return None
        jobs.busy = True
        stats.requests += 1
        self._usual = exchange
        deadline = inbox.deadline = exchange.end + response_timeout
        if deadline < inbox.timer_at:
            self._arm_timer(deadline)
        shape = known.reply_shape
        assert shape is not None
        link.expect(shape[0], shape[1], exchange.on_reply, known.last_reply)
        return exchange

    def _take_over(self) -> None:
        """Something other than the usual reply came during the usual exchange, or its
        time ran out: the machine takes the attempt over, for the line task to run."""
        exchange = self._usual
        assert exchange is not None
        self._usual = None
        self.link.forget_expected()
        self._leave_to_line_task(take_over(exchange, self.machine, self._jobs))

    def _queue(self, job: Job) -> Waiter | None:
        """Queue `job`; return the future its caller awaits (`TURN`, or the result of
        the usual exchange run for it when it is handed the line: see `_grant_next`).

        On an event loop the caller waits on a future of the loop (smaller than an
        anyio event, and what a usual exchange completes); elsewhere (None) on the
        job's anyio event, set when it is handed the line or failed.
        """
        link = self.link
        loop = link.loop
        waiter: Waiter | None = None
        if loop is not None:
            waiter = job.waiter = loop.create_future()
        else:
            backend = link.backend
            job.turn = anyio.Event() if backend is None else backend.create_event()
        jobs = self._jobs
        jobs.push(job)
        if not jobs.busy and self._open:
            self._grant_next()
        return waiter

    def _left_queue(self, job: Job) -> None:
        """The caller of queued `job` is gone (cancelled, or failed) while it waited."""
        if job.usual:
            pass  # its usual exchange holds the line, and sees the future cancelled
        elif job.granted and not job.done:
            self._release()  # handed the line, yet gone: hand it on
        else:
            job.transaction.abandoned = True  # still queued: the queue skips it

    def _grant_next(self) -> None:
        """Hand the line to the first queued job: run its usual exchange at once where
        the predicate lets it (the line is handed to it, so a queue of register reads
        costs what one caller costs), else wake its caller to run the transaction."""
        job = self._jobs.next_job()
        if job is None:
            return
        waiter = job.waiter
        if waiter is not None:
            transaction = job.transaction
            exchange = self._start_usual(
                transaction.unit,
                transaction.request,
                transaction.timeout,
                transaction.policy,
                priority=job.priority,
                waiter=waiter,
            )
            if exchange is not None:
                job.usual = True
                return
        job.wake()

    def _release(self) -> None:
        """The transaction that had the line is over: hand the line on."""
        self._usual = None  # if it was a usual exchange, it is over
        jobs = self._jobs
        if not self._open:
            # The queue waits for the line task: it fails it (dead link) or serves it.
            jobs.busy = False
            self._wake.set()
        elif jobs.waiting:
            self._grant_next()
        else:
            jobs.busy = False

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
        if not self.wait_for_reconnect:
            raise ConnectionLost("the line is down")
        if self.fail_fast_reconnect:
            raise ConnectionLost("the line is down and reconnecting; not sent (fail fast)")
        with anyio.move_on_after(seconds):
            await self.wait_connected()
        if self._failed is not None:
            raise ConnectionLost(str(self._failed))
        if not self._connected.is_set():
            raise ConnectionLost(f"the line is down and did not come back within {seconds} s")

    def _check_offline(self, unit: int) -> None:
        if unit == BROADCAST_UNIT:
            return
        stats = self.stats.get(unit)
        if stats is None or stats.online:
            return
        now = self.link.clock()
        if now - stats.last_probe < self.health.probe_interval:
            raise UnitOffline(unit, stats.consecutive_failures)
        stats.last_probe = now

    # -- the line task ---------------------------------------------------------------

    async def run(self) -> None:
        """Serve `link` until cancelled or the line fails, then fail every request,
        then and later, with ConnectionLost."""
        try:
            self.close(await self.serve(self.link))
        finally:
            self.close(ConnectionLost("the master is closed"))

    async def serve(self, link: Link) -> ConnectionLost:
        """Serve the line on `link` (entered by the caller) until it fails; return why.

        This is the line task: it takes the link's events, runs the transactions
        cancelled callers leave behind and the usual exchanges the machine took over,
        and notices a dead link. The request in flight and the queued ones fail with the
        link's ConnectionLost; requests made afterwards wait for the next `serve`
        or fail (see `submit`).
        """
        self.link = link
        self._inbox.events.clear()
        self._usual = None
        self._open = self._failed is None
        link.listen(self._on_link_event)  # a closed link: _open is false at once
        try:
            while link.receive_nowait() is not None:  # queued before we listened
                pass
        except ConnectionLost:
            pass
        self._connected.set()
        try:
            if not self._jobs.busy:
                self._grant_next()
            while not (link.closed and not self._jobs.busy):
                await self._wake.wait()
                self._wake = anyio.Event()
                job = self._for_line_task
                if job is not None and job.taken_over:
                    await self._finish_taken_over(job)
                elif job is not None:
                    await self._finish_adopted(job)
        finally:
            self._open = False
            link.listen(None)
        lost = link.connection_lost_error()
        self._connected = anyio.Event()
        self._jobs.fail_all(str(lost))
        return lost

    def close(self, error: ConnectionLost) -> None:
        """Fail every queued request, and every later one, with `error` (first error wins)."""
        if self._failed is None:
            self._failed = error
        self._open = False
        why = str(self._failed)
        self._jobs.fail_all(why)
        # The line task is gone: nobody takes a usual exchange on the wire over, or runs
        # one it had taken over but not begun.
        exchange = self._usual
        if exchange is not None:
            self._usual = None
            self.link.forget_expected()
            if not exchange.caller.done():
                exchange.caller.set_exception(ConnectionLost(why))
        job = self._for_line_task
        if job is not None and not job.done:
            job.finish(None, ConnectionLost(why))
        # Nothing waits any more: a closed master leaves no timer armed on the loop.
        inbox = self._inbox
        if inbox.timer is not None:
            inbox.timer.cancel()
            inbox.timer, inbox.timer_at = None, math.inf
        self._connected.set()

    def _on_link_event(self, event: LinkEvent | None) -> None:
        """The link's listener: keep the event and wake the waiting transaction."""
        inbox = self._inbox
        if event is None:
            self._open = False
            self._wake.set()
        else:
            events = inbox.events
            if len(events) >= self.link.queue_size:
                events.popleft()  # the newest frame is the one a waiting master wants
                self.link.events_dropped += 1
            events.append(event)
        if self._usual is not None:
            self._take_over()
        waiter = inbox.waiter
        if waiter is not None and not waiter.done():
            waiter.set_result(None)
        arrival = inbox.arrival
        if arrival is not None:
            arrival.set()

    async def _exchange(self, job: Job, on_the_wire: bool = False) -> None:
        """Run `job`'s transaction on the line; the line is the caller's meanwhile.

        `on_the_wire` is for a usual exchange taken over: the machine has begun the
        transaction and its first attempt is on the wire.
        """
        transaction = job.transaction
        machine = self.machine
        stats = self.stats.get(transaction.unit) or self.unit_stats(transaction.unit)
        if not on_the_wire:
            stats.requests += 1
            machine.begin(transaction)
        try:
            while True:
                if on_the_wire:
                    on_the_wire = False  # a retry sends the request again
                elif self._guard.until != _NO_GUARD or not self._send_at_once():
                    await self._send(job)
                failures = len(transaction.failures)
                outcome = await self._wait_for_attempt(job, stats)
                if outcome.kind is not OutcomeKind.RETRY:
                    break
                stats.count_failed_attempt(transaction)
                stats.retries += 1
                if len(transaction.failures) > failures:
                    # Timed out or garbled, not refused: its reply may still come.
                    self._start_guard()
        except ConnectionLost as error:
            # Back to IDLE, wherever the line failed: the next line may serve again.
            machine.connection_lost(error)
            job.finish(None, error)
            return
        except BaseException:
            if self._for_line_task is not job:
                # Gone before the request went out: nothing is on the wire. An earlier
                # attempt may still be answered late: keep the guard.
                transaction.abandoned = True
                if transaction.failures:
                    self._start_guard()
            raise
        self._settle(job, outcome, stats)

    def _send_at_once(self) -> bool:
        """Send the machine's frame now, where the line lets it go without a wait (no
        coroutine, nothing to cancel), and tell the machine; else send nothing."""
        machine = self.machine
        link = self.link
        frame = machine.frame
        self._inbox.events.clear()  # nothing that came before can answer it
        end = link.send_now(frame)
        if end is None:
            return False
        machine.sent(end - len(frame) * link.char_time, end)
        return True

    async def _send(self, job: Job) -> None:
        """Send the machine's frame for `job` once the late-reply guard is kept and the
        line lets it go, and tell the machine when it went out."""
        if self._guard.until != _NO_GUARD:
            await self._keep_guard()
        if self._send_at_once():
            return
        machine = self.machine
        link = self.link
        frame = machine.frame
        wire_time = len(frame) * link.char_time
        writes = link.writes_begun
        try:
            end = await link.send(frame)
        except ConnectionLost:
            raise
        except BaseException:
            if link.writes_begun != writes:
                # The frame may be on its way: its reply must be waited for.
                start = link.last_write_start
                machine.sent(start, start + wire_time)
                self._adopt(job)
            raise
        machine.sent(end - wire_time, end)

    async def _wait_for_attempt(self, job: Job, stats: UnitStats) -> Outcome:
        """The outcome of the attempt on the wire; a caller gone meanwhile leaves it to
        the line task."""
        try:
            return await self._wait_for_outcome(stats)
        except ConnectionLost:
            raise
        except BaseException:
            self._adopt(job)
            raise

    def _adopt(self, job: Job) -> None:
        """The caller is gone mid-attempt: the line task finishes the attempt."""
        job.transaction.abandoned = True
        self._leave_to_line_task(job)

    def _leave_to_line_task(self, job: Job) -> None:
        self._for_line_task = job
        self._wake.set()

    async def _finish_adopted(self, job: Job) -> None:
        """Finish the attempt of a caller gone mid-attempt (no retries), then hand on."""
        stats = self.unit_stats(job.transaction.unit)
        try:
            outcome = await self._wait_for_outcome(stats)
            # Abandoned: the machine retries nothing, so this is the end.
            if outcome.kind is OutcomeKind.RETRY:  # pragma: no cover - defensive
                stats.count_failed_attempt(job.transaction)
            else:
                self._settle(job, outcome, stats)
        except ConnectionLost as error:
            self.machine.connection_lost(error)
            job.finish(None, error)
        except BaseException:
            self._stop_serving(job)
            raise
        finally:
            self._for_line_task = None
            self._release()

    async def _finish_taken_over(self, job: Job) -> None:
        """Run the rest of a usual exchange the machine took over, for its caller."""
        try:
            await self._exchange(job, on_the_wire=True)
        except BaseException:
            self._stop_serving(job)
            raise
        finally:
            if self._for_line_task is job:
                self._for_line_task = None
            self._release()

    def _stop_serving(self, job: Job) -> None:
        """The line task is cancelled (the master closes) while it runs `job`.

        The attempt on the wire is given up: the machine goes back to IDLE (through its
        table, as if the line were lost) and `job` fails. The line is not handed on: a
        queued caller would begin a transaction nobody can finish; `close` fails
        the queue instead.
        """
        self._open = False
        error = ConnectionLost("the master is closed")
        if self.machine.state is not MasterState.IDLE:
            self.machine.connection_lost(error)
        if not job.done:
            job.finish(None, error)

    def _start_guard(self) -> None:
        """An attempt failed: nothing goes out until the late-reply guard is kept."""
        guard = self._guard
        guard.until = self.link.clock() + guard.seconds

    async def _keep_guard(self) -> None:
        """Wait until the line has been silent for the late-reply guard after the last
        failed attempt (see `guard_ends`), then clear the guard."""
        link = self.link
        guard = self._guard
        while True:
            delay = guard_ends(guard.until, link.last_activity, guard.seconds) - link.clock()
            if delay <= 0:
                break
            await anyio.sleep(delay)
        guard.until = _NO_GUARD

    async def _wait_for_outcome(self, stats: UnitStats) -> Outcome:
        machine = self.machine
        link = self.link
        clock = link.clock
        backend = link.backend
        assert backend is not None
        inbox = self._inbox
        events = inbox.events
        loop = link.loop
        while True:
            while events:
                outcome = self._examine(events.popleft())
                if outcome.skipped is not None:
                    stats.skipped_frames += 1
                if outcome.kind is not OutcomeKind.WAIT:
                    return outcome
            if link.closed:
                raise link.connection_lost_error()
            deadline = machine.deadline
            assert deadline is not None
            now = clock()
            if now >= deadline:
                outcome = machine.expired(now)
                if outcome.kind is not OutcomeKind.WAIT:
                    return outcome
                continue
            if loop is not None:
                # A future of the link's loop, set by the listener or the engine's timer.
                waiter = inbox.waiter = loop.create_future()
                inbox.deadline = deadline
                if deadline < inbox.timer_at:
                    self._arm_timer(deadline)
                try:
                    await waiter
                finally:
                    inbox.waiter = None
                continue
            if not link.backend_clock:
                deadline = backend.current_time() + (deadline - now)
            arrival = inbox.arrival = backend.create_event()
            try:
                with backend.create_cancel_scope(deadline=deadline):
                    await arrival.wait()
            finally:
                inbox.arrival = None

    def _examine(self, event: LinkEvent) -> Outcome:
        """Feed `event` to the machine."""
        if isinstance(event, FrameReceived):
            frame = event.frame
            return self.machine.frame_received(frame[0], frame[1:-2], event.start, event.end)
        error = frame_error_from_discard(event.data, str(event.reason))
        return self.machine.frame_error(error, event.end)

    def _arm_timer(self, deadline: float) -> None:
        """One timer serves every wait on a link with a loop: armed for the earliest
        deadline, it is armed again for the current one if it fires before it (so a
        read that ends in time costs no timer of its own)."""
        inbox = self._inbox
        if inbox.timer is not None:
            inbox.timer.cancel()
        inbox.timer_at = deadline
        inbox.timer = self.link.call_at(deadline, self._on_timer)

    def _on_timer(self) -> None:
        inbox = self._inbox
        inbox.timer, inbox.timer_at, waiter = None, math.inf, inbox.waiter
        usual = self._usual is not None
        if not usual and (waiter is None or waiter.done()):
            return
        if self.link.clock() < inbox.deadline:
            self._arm_timer(inbox.deadline)
        elif usual:
            self._take_over()
        else:
            waiter.set_result(None)

    def _settle(self, job: Job, outcome: Outcome, stats: UnitStats) -> None:
        transaction = job.transaction
        if transaction.failures or outcome.kind is OutcomeKind.FAILED:
            # A failed attempt may still be answered late, even when a retry succeeded.
            self._start_guard()
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
            stats.count_success(
                now - transaction.attempt_start,
                exception=isinstance(response, ExceptionPDU),
                after_timeout=Failure.TIMEOUT in transaction.failures,
                health=self.health,
                now=now,
            )
        job.finish(response, None)

"""The master's line: one transaction at a time on one line, for any number of callers.

:class:`LineEngine` owns a :class:`~aiortu.line._link.Link` and runs the sans-IO
:class:`~aiortu.core.master_machine.MasterMachine` on it. Callers hand it
:class:`~aiortu.core.master_transaction.Transaction` objects through :meth:`LineEngine.submit`.

The line belongs to one transaction at a time, and the transaction runs in the task of
the caller that submitted it: the caller sends the request and waits for the reply
itself, so a read on an idle line costs no hand-over between tasks. When the line is
busy, the caller queues (FIFO, lower *priority* first) and waits for its turn; the
transaction that ends hands the line straight to the next one in the queue. The link
hands every frame to the engine (:meth:`~aiortu.line._link.Link.listen`), which wakes the
waiting transaction directly. On a serial port, the usual reply to a register read (the
shape :attr:`~aiortu.core.master_machine.MasterMachine.usual_reply` gives) is handed over
by the link's read callback as it came (:meth:`~aiortu.line._link.Link.expect`) and ends the
transaction in one step (:meth:`~aiortu.core.master_machine.MasterMachine.take_usual_reply`);
any other frame goes through the machine's table as usual. On an idle line such a read
does not even begin in the machine unless something unusual happens
(:meth:`LineEngine.submit_request`).

Cancellation never leaves the line half way through an exchange. A caller cancelled
while queued is dropped; one cancelled before its request began to go out gives the line
up at once; one cancelled after that leaves its transaction to the engine's line task
(:meth:`LineEngine.serve`), which finishes the attempt in flight (its reply must not
reach a later request) without retries and then hands the line on. So the exchanges on
the line stay strictly one after the other, exactly as if one task ran them all: the
line task runs only what a cancelled caller left behind and the usual exchanges the
machine took over (see :meth:`LineEngine.submit_request`), and notices a dead link.

It also keeps :class:`UnitStats` per unit and their health: a unit is offline after
*offline_after* consecutive failed transactions, and online again after a success. With
*fail_fast_offline*, a request to an offline unit raises :class:`UnitOffline` at once,
except for one probe every *probe_interval* seconds.

When the link fails, the request in flight and the queued ones fail with
ConnectionLost and :meth:`LineEngine.serve` returns; the
:class:`~aiortu.master._connection.LineConnection` closes the engine for good or serves it
again on a reopened link, while :meth:`LineEngine.submit` waits for the line within the
request's timeout or fails at once (see :attr:`LineEngine.wait_for_reconnect`).

:class:`~aiortu.master._client.Master` is the API built on this; see its docstring for the guard
against late replies.
"""

from __future__ import annotations

import asyncio
import heapq
import itertools
import math
from collections import deque
from collections.abc import Awaitable
from typing import Any

import anyio

from aiortu.core.codes import BROADCAST_UNIT
from aiortu.core.errors import FrameError
from aiortu.core.master_machine import KnownRequest, MasterMachine
from aiortu.core.master_transaction import (
    Outcome,
    OutcomeKind,
    RetryPolicy,
    Transaction,
    frame_error_from_discard,
)
from aiortu.core.pdu import ExceptionPDU, Request, Response
from aiortu.core.receiver import FrameReceived
from aiortu.errors import ConnectionLost, ResponseTimeout, UnitOffline
from aiortu.line._link import Link, LinkEvent
from aiortu.master._job import Job, JobResult
from aiortu.master._stats import HealthPolicy, UnitStats

__all__ = ("HealthPolicy", "LineEngine", "UnitOffline", "UnitStats")


_UsualExchange = tuple[
    "asyncio.Future[JobResult]", KnownRequest, int, float, RetryPolicy, int, float, float
]


class LineEngine:
    """The master's side of one line (see the module docstring).

    *late_reply_guard* is the silence, in seconds, kept after a transaction in which an
    attempt failed, before the next request goes out: a reply that turns up that late is
    dropped as stale. *frame_error_grace* is how long a wait goes on after bad bytes.
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
        self.late_reply_guard = late_reply_guard
        self.machine = MasterMachine(frame_error_grace=frame_error_grace)
        self.stats: dict[int, UnitStats] = {}
        """Statistics by unit address."""
        self._queue: list[Job] = []
        self._sequence = itertools.count()
        self._busy = False
        """The line belongs to a transaction (running, handed over, or left to the line task)."""
        self._serving = False
        self._link_closed = False
        self._events: deque[LinkEvent] = deque()
        self._arrival: anyio.Event | None = None
        self._waiter: Any = None
        """The event loop future a transaction waits on, where the link has a loop."""
        self._waiter_deadline = math.inf
        self._usual: tuple[bytes, float] | None = None
        """The usual reply, handed over by the link's read callback (see Link.expect)."""
        self._in_flight: _UsualExchange | None = None
        """The usual exchange on the wire (see submit_request): the caller's future, the
        request known, unit, response timeout, policy, priority, and when the request
        began to go out and had left the wire."""
        self._timer: Any = None
        self._timer_at = math.inf
        self._adopted: Job | None = None
        self._wake = anyio.Event()
        self._quiet_until = -math.inf
        self._failed: ConnectionLost | None = None
        self._connected = anyio.Event()
        self._connected.set()
        self.wait_for_reconnect = False
        """Whether requests made while the line is down wait for it to come back (set by
        :class:`~aiortu.master._connection.LineConnection` when it can reopen the port)."""
        self.fail_fast_reconnect = False
        """With :attr:`wait_for_reconnect`: raise at once instead of waiting."""
        self.transactions = 0
        """Transactions run on the line (abandoned ones included)."""
        self.min_turnaround = 0.0
        """Seconds from the end of a request on the wire to the first byte of a reply
        that every unit takes at least, unless :attr:`unit_turnaround` says otherwise."""
        self.unit_turnaround: dict[int, float] = {}
        """The minimum turnaround of single units (see :attr:`min_turnaround`)."""
        self.usual_exchanges = True
        """Whether register reads may run their usual exchange without the machine (see
        :meth:`submit_request`); false runs every transaction through it."""

    # -- the callers' side -----------------------------------------------------------

    def unit_stats(self, unit: int) -> UnitStats:
        """The statistics of *unit* (created empty on first use)."""
        stats = self.stats.get(unit)
        if stats is None:
            stats = self.stats[unit] = UnitStats()
        return stats

    def reply_delay(self, unit: int) -> float | None:
        """The least delay from a request to *unit* leaving the wire to the arrival of
        its reply's first byte, where the link's wire times are real: the unit's minimum
        turnaround plus the byte's own wire time. None where they are not (see
        :attr:`~aiortu.core.master_transaction.Transaction.reply_delay`)."""
        link = self.link
        if not link.wire_timed:
            return None
        return self.unit_turnaround.get(unit, self.min_turnaround) + link.char_time

    async def submit(
        self, transaction: Transaction, priority: int = 0
    ) -> Response | ExceptionPDU | None:
        """Run *transaction* when the line is free, and return the reply (``None``
        without one).

        Raises the transaction's error (ResponseTimeout, FrameError, ConnectionLost) and
        :class:`UnitOffline` when failing fast. If the caller is cancelled, the request
        is dropped from the queue or, when in flight, finished without retries.
        """
        if self._failed is not None:
            raise ConnectionLost(str(self._failed))
        if not self._connected.is_set():
            await self._wait_connected(transaction.timeout)
        if self.health.fail_fast_offline:
            self._check_offline(transaction.unit)
        transaction.reply_delay = self.reply_delay(transaction.unit)
        job = Job(transaction, priority, next(self._sequence))
        if self._busy or not self._serving or self._link_closed:
            await self._wait_turn(job)
        else:
            self._busy = True  # an idle line: the transaction runs at once, here
        return await self._run(job)

    async def _run(self, job: Job) -> Response | ExceptionPDU | None:
        """Run *job*, which has the line; return its reply."""
        if not job.done:
            try:
                await self._exchange(job)
            finally:
                if self._adopted is not job:
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
        """:meth:`submit` of ``Transaction(unit, request, response_timeout, policy)``, as
        an awaitable.

        On an idle line with a loop, a register read whose reply comes as usual runs
        without the master machine (see
        :meth:`~aiortu.core.master_machine.MasterMachine.usual_exchange`): the request
        goes out now, and the return is a future of the link's loop that the link's read
        callback completes with the response, counted, the line handed on. The caller's
        task is woken once, with its result, and no coroutine of the engine runs.
        Anything else that happens while it waits (another frame, bad bytes, the
        timeout, the link failing) hands the attempt in flight to the machine, which
        goes on exactly as if it had sent the request itself, in the line task; that
        completes the future as :meth:`submit` would return or raise. A caller cancelled
        meanwhile cancels the future: the attempt is finished without retries and its
        reply is counted. Set :attr:`usual_exchanges` false to run every transaction
        through the machine.
        """
        link = self.link
        loop = link.loop
        if (
            self.usual_exchanges
            and loop is not None
            and not self._busy
            and self._serving
            and not self._link_closed
            and self._failed is None
            and not self.health.fail_fast_offline
            and self._quiet_until <= link.clock()
        ):
            known = self.machine.usual_exchange(unit, request)
            if known is not None:
                self._forget_arrivals()
                frame = known.frame
                end = link.send_now(frame)  # None: the line asks for a wait
                if end is not None:
                    self._busy = True
                    stats = self.stats.get(unit) or self.unit_stats(unit)
                    stats.requests += 1
                    self.transactions += 1
                    deadline = end + response_timeout
                    caller = loop.create_future()
                    start = end - len(frame) * link.char_time
                    self._in_flight = (
                        caller, known, unit, response_timeout, policy, priority, start, end
                    )  # fmt: skip
                    self._waiter_deadline = deadline
                    if deadline < self._timer_at:
                        self._arm_timer(deadline)
                    shape = known.reply_shape
                    assert shape is not None
                    link.expect(shape[0], shape[1], self._on_reply_at_once, known.last_reply)
                    return caller  # type: ignore[no-any-return]
        return self.submit(Transaction(unit, request, response_timeout, policy), priority)

    def _on_reply_at_once(self, frame: bytes, end: float) -> None:
        """The link's read callback found the usual reply of the usual exchange."""
        in_flight = self._in_flight
        assert in_flight is not None
        caller, known, unit, _, _, _, start, sent = in_flight
        turnaround = self.reply_delay(unit)
        if turnaround is not None:
            first = end - (len(frame) - 1) * self.link.char_time
            if first < sent + turnaround:
                # Begun before the unit could answer: stale, for the machine to skip.
                self._take_over()
                self._on_link_event(FrameReceived(frame, first, end))
                return
        self._in_flight = None
        response = self.machine.usual_response(known, frame)
        self.stats[unit].count_success(self.link.clock() - start)
        self._release()
        if not caller.done():  # done: cancelled, the reply is counted all the same
            caller.set_result(response)

    def _take_over(self) -> None:
        """Something other than the usual reply came during the usual exchange, or its
        time ran out: the machine takes the attempt over, begun and sent, and the line
        task runs the rest of the transaction for the caller."""
        in_flight = self._in_flight
        assert in_flight is not None
        self._in_flight = None
        caller, known, unit, response_timeout, policy, priority, start, end = in_flight
        self.link.forget_expected()
        transaction = Transaction(unit, known.request, response_timeout, policy)
        transaction.reply_delay = self.reply_delay(unit)
        self.machine.begin(transaction)
        self.machine.sent(start, end)
        job = Job(transaction, priority, next(self._sequence))
        job.caller = caller
        if caller.done():
            transaction.abandoned = True  # cancelled: no retries
        else:
            caller.add_done_callback(job.on_caller_done)
        self._adopted = job
        self._wake.set()

    async def _wait_turn(self, job: Job) -> None:
        """Queue *job* and wait until it is handed the line (or failed)."""
        backend = self.link.backend
        turn = job.turn = anyio.Event() if backend is None else backend.create_event()
        heapq.heappush(self._queue, job)
        if not self._busy and self._serving and not self._link_closed:
            self._grant_next()
        try:
            await turn.wait()
        except BaseException:
            if job.granted and not job.done:
                self._release()  # handed the line, yet gone: hand it on
            else:
                job.transaction.abandoned = True
            raise

    def _grant_next(self) -> None:
        """Hand the line to the first job in the queue, or mark it free."""
        queue = self._queue
        while queue:
            job = heapq.heappop(queue)
            if job.transaction.abandoned:
                continue
            self._busy = True
            job.granted = True
            assert job.turn is not None
            job.turn.set()
            return
        self._busy = False

    def _release(self) -> None:
        """The transaction that had the line is over: hand the line on."""
        if not self._queue and self._serving and not self._link_closed:
            self._busy = False  # nobody waits: what _grant_next would find
            return
        if self._link_closed or not self._serving:
            # The queue waits for the line task: it fails it (dead link) or serves it.
            self._busy = False
            self._wake.set()
            return
        self._grant_next()

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
        """Wait up to *seconds* for the line to come back, else raise ConnectionLost."""
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
        """Serve :attr:`link` until cancelled or the line fails, then fail every request,
        then and later, with ConnectionLost."""
        try:
            self.close(await self.serve(self.link))
        finally:
            self.close(ConnectionLost("the master is closed"))

    async def serve(self, link: Link) -> ConnectionLost:
        """Serve the line on *link* (entered by the caller) until it fails; return why.

        This is the line task: it takes the link's events, finishes the transactions
        that cancelled callers leave behind, and notices a dead link. The request in
        flight and the queued ones fail with the link's ConnectionLost; requests made
        afterwards wait for the next :meth:`serve` or fail (see :meth:`submit`).
        """
        self.link = link
        self._link_closed = False
        self._events.clear()
        self._usual = None
        link.listen(self._on_link_event)
        try:
            while link.receive_nowait() is not None:  # queued before we listened
                pass
        except ConnectionLost:
            pass
        self._serving = True
        self._connected.set()
        try:
            if not self._busy:
                self._grant_next()
            while not (self._link_closed and not self._busy):
                await self._wake.wait()
                self._wake = anyio.Event()
                job = self._adopted
                if job is not None:
                    await self._finish_adopted(job)
        finally:
            self._serving = False
            link.listen(None)
        lost = link.connection_lost_error()
        self._connected = anyio.Event()
        self._fail_queued(lost)
        return lost

    def close(self, error: ConnectionLost) -> None:
        """Fail every queued request, and every later one, with *error* (first error wins)."""
        if self._failed is None:
            self._failed = error
        self._fail_queued(self._failed)
        # The line task is gone: nobody takes a usual exchange on the wire over, or runs
        # one it had taken over but not begun.
        if self._in_flight is not None:
            caller = self._in_flight[0]
            self._in_flight = None
            self.link.forget_expected()
            if not caller.done():
                caller.set_exception(ConnectionLost(str(self._failed)))
        job = self._adopted
        if job is not None and not job.done:
            job.finish(None, ConnectionLost(str(self._failed)))
        self._connected.set()

    def _on_link_event(self, event: LinkEvent | None) -> None:
        """The link's listener: keep the event and wake the waiting transaction."""
        if event is None:
            self._link_closed = True
            self._wake.set()
        else:
            events = self._events
            if len(events) >= self.link.queue_size:
                events.popleft()  # the newest frame is the one a waiting master wants
                self.link.events_dropped += 1
            events.append(event)
        if self._in_flight is not None:
            self._take_over()
        waiter = self._waiter
        if waiter is not None and not waiter.done():
            waiter.set_result(None)
        arrival = self._arrival
        if arrival is not None:
            arrival.set()

    def _on_usual_reply(self, frame: bytes, end: float) -> None:
        """The link's read callback found the usual reply (see Link.expect)."""
        self._usual = (frame, end)
        waiter = self._waiter
        if waiter is not None and not waiter.done():
            waiter.set_result(None)

    def _fail_queued(self, error: ConnectionLost) -> None:
        while self._queue:
            job = heapq.heappop(self._queue)
            if not job.done:
                job.finish(None, ConnectionLost(str(error)))

    async def _exchange(self, job: Job, on_the_wire: bool = False) -> None:
        """Run *job*'s transaction on the line; the line is the caller's meanwhile.

        *on_the_wire* is for a usual exchange taken over (see :meth:`submit_request`):
        the machine has begun the transaction and its first attempt is on the wire.
        """
        transaction = job.transaction
        machine = self.machine
        link = self.link
        stats = self.stats.get(transaction.unit) or self.unit_stats(transaction.unit)
        if not on_the_wire:
            stats.requests += 1
            self.transactions += 1
            machine.begin(transaction)
        try:
            while True:
                if not on_the_wire:
                    if self._quiet_until > link.clock():
                        await self._keep_guard()
                    frame = machine.frame
                    self._forget_arrivals()
                    wire_time = len(frame) * link.char_time
                    writes = link.writes_begun
                    # At once where the line allows it (no coroutine, nothing to cancel).
                    sent_at_once = link.send_now(frame)
                    try:
                        end = await link.send(frame) if sent_at_once is None else sent_at_once
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
                on_the_wire = False  # a retry sends the request again
                outcome = await self._wait_for_attempt(job, stats)
                if outcome.kind is not OutcomeKind.RETRY:
                    break
                stats.count_failed_attempt(transaction)
                stats.retries += 1
        except ConnectionLost as error:
            # Back to IDLE, wherever the line failed: the next line may serve again.
            machine.connection_lost(error)
            job.finish(None, error)
            return
        except BaseException:
            if self._adopted is not job:
                # Gone before the request went out: nothing is on the wire. An earlier
                # attempt may still be answered late: keep the guard.
                transaction.abandoned = True
                if transaction.failures:
                    self._quiet_until = link.clock() + self.late_reply_guard
            raise
        self._settle(job, outcome, stats)

    def _forget_arrivals(self) -> None:
        """A request is about to go out: nothing that came before can answer it."""
        self._events.clear()
        self._usual = None

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
        self._adopted = job
        self._wake.set()

    async def _finish_adopted(self, job: Job) -> None:
        if job.caller is not None:
            await self._finish_taken_over(job)
            return
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
        finally:
            self._adopted = None
            self._release()

    async def _finish_taken_over(self, job: Job) -> None:
        """Run the rest of a usual exchange the machine took over, for its caller."""
        try:
            await self._exchange(job, on_the_wire=True)
        except BaseException:
            # The line task is cancelled: the master is closing.
            if not job.done:
                job.finish(None, ConnectionLost("the master is closed"))
            raise
        finally:
            if self._adopted is job:
                self._adopted = None
            self._release()

    async def _keep_guard(self) -> None:
        delay = self._quiet_until - self.link.clock()
        if delay > 0:
            await anyio.sleep(delay)

    async def _wait_for_outcome(self, stats: UnitStats) -> Outcome:
        machine = self.machine
        link = self.link
        clock = link.clock
        backend = link.backend
        assert backend is not None
        events = self._events
        loop = link.loop
        # Where the link has a loop, the usual reply (a register read's) comes straight
        # from its read callback to _on_usual_reply, without an event and the queue.
        usual = machine.usual_reply if loop is not None else None
        while True:
            while events:
                event = events.popleft()
                if isinstance(event, FrameReceived):
                    frame = event.frame
                    outcome = machine.frame_received(frame[0], frame[1:-2], event.start, event.end)
                else:
                    error = frame_error_from_discard(event.data, str(event.reason))
                    outcome = machine.frame_error(error, event.end)
                if outcome.skipped is not None:
                    stats.skipped_frames += 1
                if outcome.kind is not OutcomeKind.WAIT:
                    return outcome
            if self._usual is not None:
                frame, end = self._usual
                self._usual = None
                start = end - (len(frame) - 1) * link.char_time
                response = machine.take_usual_reply(frame, end, start)
                if response is not None:
                    return Outcome(OutcomeKind.DONE, response)
                # Not for this machine at this moment: the usual way, as an event.
                events.append(FrameReceived(frame, start, end))
                continue
            if self._link_closed:
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
                waiter = self._waiter = loop.create_future()
                self._waiter_deadline = deadline
                if deadline < self._timer_at:
                    self._arm_timer(deadline)
                if usual is not None:
                    link.expect(usual[0], usual[1], self._on_usual_reply)
                try:
                    await waiter
                finally:
                    self._waiter = None
                    if usual is not None:
                        link.forget_expected()
                continue
            if not link.backend_clock:
                deadline = backend.current_time() + (deadline - now)
            arrival = self._arrival = backend.create_event()
            try:
                with backend.create_cancel_scope(deadline=deadline):
                    await arrival.wait()
            finally:
                self._arrival = None

    def _arm_timer(self, deadline: float) -> None:
        """One timer serves every wait on a link with a loop: armed for the earliest
        deadline, it is armed again for the current one if it fires before it."""
        if self._timer is not None:
            self._timer.cancel()
        self._timer_at = deadline
        self._timer = self.link.call_at(deadline, self._on_timer)

    def _on_timer(self) -> None:
        self._timer, self._timer_at, waiter = None, math.inf, self._waiter
        usual = self._in_flight is not None
        if not usual and (waiter is None or waiter.done()):
            return
        if self.link.clock() < self._waiter_deadline:
            self._arm_timer(self._waiter_deadline)
        elif usual:
            self._take_over()
        else:
            waiter.set_result(None)

    def _settle(self, job: Job, outcome: Outcome, stats: UnitStats) -> None:
        transaction = job.transaction
        if transaction.failures or outcome.kind is OutcomeKind.FAILED:
            # An earlier attempt may still be answered late; keep the line quiet a while
            # so that such a reply arrives before the next request and is dropped.
            self._quiet_until = self.link.clock() + self.late_reply_guard
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
            stats.count_success(
                self.link.clock() - transaction.attempt_start,
                exception=isinstance(response, ExceptionPDU),
            )
        job.finish(response, None)

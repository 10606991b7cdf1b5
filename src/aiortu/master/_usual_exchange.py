"""The usual exchange: the master's fast path, in one place.

A register read on an idle serial line usually goes like this: the request goes out, the
unit's reply comes back whole in one chunk with a good CRC, and the transaction is over.
Run through the master machine, that reply takes SEND_UNICAST, REPLY_RECEIVED and REPLY_OK
and leaves the machine IDLE with nothing to remember, so the engine may run it without
the machine:

1. `usual_exchange_for` says whether the shortcut may run: every condition is
   named there, and nowhere else.
2. `send_usual_exchange` sends the request at once (no wait, no yield) and returns
   the `UsualExchange` on the wire, whose `caller` future the
   caller awaits. The engine asks the link to hand the usual reply (its first bytes and
   length) straight from the read callback
   ([`expect`][aiortu.line.Link.expect]).
3. That reply ends it (`UsualExchange.on_reply`, called by the link): it is
   decoded and counted, the line handed on, and the future completed. One that began
   before the unit could have answered (where the line's wire times are real) is stale:
   it goes to the machine as a frame, which skips it (step 4). The caller's
   task is woken once, and no coroutine of the engine runs.
4. Anything else (another frame, bad bytes, the response timeout, the line lost) makes
   the machine take the attempt over (`take_over`): it begins the transaction
   and is told the request went out when it did, so it knows everything it would have
   known had it sent the request itself, and the engine's line task runs the rest
   (retries, the late-reply guard, statistics) for the caller.

So a reply ends a transaction by one of two routes: the usual reply here, or the table
of [`MasterMachine`][aiortu.core.machines.MasterMachine]. The differential tests run the
same scenarios with the shortcut on and off and compare results, statistics and bytes on
the wire.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

from aiortu.core.machines import KnownRequest, MasterMachine, RetryPolicy, Transaction
from aiortu.core.pdu import Request
from aiortu.core.rtu import FrameReceived
from aiortu.line import Link
from aiortu.master._job import Job, JobQueue, Waiter
from aiortu.master._stats import UnitStats

__all__ = (
    "UsualExchange",
    "send_usual_exchange",
    "take_over",
    "usual_exchange_for",
)


@dataclass(slots=True, eq=False)
class UsualExchange:
    """A register read on the wire, run without the machine (see the module docstring)."""

    caller: Waiter
    """What the caller awaits: completed with the response, or by the line task after
    `take_over`; cancelled if the caller is. A queued caller's own future where the
    line was handed to it (never completed with `TURN` here)."""
    known: KnownRequest
    """What the machine remembers of the request: its frame, its reply's shape."""
    stats: UnitStats
    """The unit's statistics (its request is counted already)."""
    timeout: float
    """The response timeout, from `end`."""
    policy: RetryPolicy
    """How a failed attempt is retried, once the machine has taken it over."""
    priority: int
    """The caller's priority, should the machine take it over."""
    start: float
    """When the request began to go out (the link's clock)."""
    end: float
    """When it had left the wire."""
    done: Callable[[], None]
    """What the engine does once the usual reply came: hand the line on."""
    stale: Callable[[FrameReceived], None]
    """What the engine does with a stale reply: the machine takes it over and skips it."""
    reply_delay: float | None
    """The unit's least delay to the reply's first byte, or None without real wire
    times (see
    [`Transaction.reply_delay`][aiortu.core.machines.Transaction.reply_delay])."""
    stale_before: float
    """A usual reply that ends sooner began before `end` plus `reply_delay`: stale
    (minus infinity without a reply delay). One comparison on the fast path."""
    char_time: float
    """The wire time of a character, to date a stale reply's first byte."""

    def on_reply(self, frame: bytes, end: float) -> None:
        """The link's read callback: `frame`, the usual reply (its shape matched, its CRC
        checked), ended at `end`. Count it, hand the line on, complete the future."""
        if end < self.stale_before:
            # Begun before the unit could answer: the machine skips it as stale.
            self.stale(FrameReceived(frame, end - (len(frame) - 1) * self.char_time, end))
            return
        response = MasterMachine.usual_response(self.known, frame)
        self.stats.count_success(end - self.start)
        self.done()
        caller = self.caller
        if not caller.done():  # done: cancelled; the reply is counted all the same
            caller.set_result(response)


def usual_exchange_for(
    unit: int,
    request: Request,
    *,
    enabled: bool,
    line_free: bool,
    handed_line: bool = False,
    guard_pending: bool,
    fail_fast_offline: bool,
    link: Link,
    machine: MasterMachine,
) -> KnownRequest | None:
    """What the machine remembers of `request` to `unit` where the usual exchange may run
    for it; else None, and the transaction goes through the machine.

    One more condition is tried rather than asked: the link must let the request go at
    once ([`send_now`][aiortu.line.Link.send_now]; see `send_usual_exchange`).
    """
    if not (
        # The engine's switch: off, every transaction goes through the machine.
        enabled
        # The reply is handed over by the link's read callback: a stream that pushes its
        # bytes (a serial port) has one, and an event loop for the caller's future.
        and link.loop is not None
        # Nobody holds the line or waits for it, and the line task serves it (it runs
        # what the machine takes over); or the queue has just handed the line to this
        # request's caller, the first in it (the line task serves it then too), so a
        # queue of register reads runs each as one caller's.
        and (line_free or handed_line)
        # After a failed attempt the late-reply guard comes first: the machine's route
        # keeps it.
        and not guard_pending
        # Requests to offline units may be refused, which the machine's route decides.
        and not fail_fast_offline
    ):
        return None
    # The machine is IDLE (nothing in flight to take over), has no transition observer
    # (it must see every transition), and the request is a register read to one unit
    # (its reply has a fixed shape, spotted without decoding).
    return machine.usual_exchange(unit, request)


def send_usual_exchange(
    link: Link,
    known: KnownRequest,
    stats: UnitStats,
    *,
    timeout: float,
    policy: RetryPolicy,
    priority: int,
    done: Callable[[], None],
    stale: Callable[[FrameReceived], None],
    reply_delay: float | None,
    caller: Waiter | None = None,
) -> UsualExchange | None:
    """Send `known`'s request now and return the exchange on the wire, or None (nothing
    sent) where the line asks for a wait (see [`send_now`][aiortu.line.Link.send_now]).

    The exchange completes `caller` (a queued caller's future), or a new future.
    `reply_delay` is the unit's least delay to its reply's first byte (None: the line's
    wire times are not real, and no reply is stale by its time here)."""
    frame = known.frame
    end = link.send_now(frame)
    if end is None:
        return None
    char_time = link.char_time
    start = end - len(frame) * char_time
    if caller is None:
        caller = link.loop.create_future()
    if reply_delay is None:
        stale_before = -math.inf
    else:
        shape = known.reply_shape
        assert shape is not None
        # The reply's first byte, at its end less (length - 1) characters, must come at
        # `end + reply_delay` or later.
        stale_before = end + reply_delay + (shape[1] - 1) * char_time
    return UsualExchange(
        caller, known, stats, timeout, policy, priority, start, end, done, stale,
        reply_delay, stale_before, char_time,
    )  # fmt: skip


def take_over(exchange: UsualExchange, machine: MasterMachine, jobs: JobQueue) -> Job:
    """Hand `exchange`'s attempt, begun and on the wire, to `machine`; return the job the
    line task runs for the caller (see `Job.taken_over`).

    A caller already gone (its future cancelled) leaves the transaction abandoned: the
    attempt is finished, not retried.
    """
    known = exchange.known
    transaction = Transaction(known.frame[0], known.request, exchange.timeout, exchange.policy)
    transaction.reply_delay = exchange.reply_delay
    machine.begin(transaction)
    machine.sent(exchange.start, exchange.end)
    job = jobs.new_job(transaction, exchange.priority)
    job.take_over(exchange.caller)
    return job

"""The master's fast path, in one class: a register read whose reply comes as usual runs
without the machine.

A register read on an idle serial line usually goes like this: the request goes out, the
unit's reply comes back whole in one chunk with a good CRC, and the transaction is over.
Run through the master machine, that reply takes SEND_UNICAST, REPLY_RECEIVED and REPLY_OK
and leaves the machine IDLE with nothing to remember, so the engine may run it without the
machine. `FastPath` does, one exchange at a time:

1. `FastPath.may_run` is the predicate: every condition under which it may run is named
   there, and nowhere else.
2. `FastPath.start` sends the request (no yield: at once where the line is quiet, else
   from a timer callback once the frame gap has passed,
   [`call_when_quiet`][aiortu.line.Link.call_when_quiet]) and asks the link to hand the
   reply of the usual shape (first bytes, length) straight from its read callback
   ([`expect`][aiortu.line.Link.expect]). It returns the future the caller awaits: a new
   one, or the future of the queued caller the line was just handed to. So a queue of
   reads runs from callbacks, each caller woken once, with its reply.
3. That reply ends it (`FastPath.on_reply`): decoded and counted, the line handed on, the
   future completed. One that began before the unit could have answered (where the line's
   wire times are real) is stale: the machine takes it over and skips it. The caller's task
   is woken once, and no coroutine of the engine runs.
4. Anything else (another frame, bad bytes, the response timeout, the line lost) makes the
   machine take the attempt over (`FastPath.take_over`, called by the engine): it begins the
   transaction and is told the request went out when it did, so it knows everything it
   would have known had it sent the request itself, and the engine's line task runs the
   rest (retries, the late-reply guard, statistics) for the caller, who awaits the same
   future.

So a reply ends a transaction by one of two routes: here, or the table of
[`MasterMachine`][aiortu.core.machines.MasterMachine]. The differential tests run the same
scenarios with the fast path on and off and compare results, statistics and the bytes on the
wire.
"""

from __future__ import annotations

import math
from typing import Any

from aiortu.core.machines import KnownRequest, MasterMachine, Transaction
from aiortu.core.rtu import FrameReceived
from aiortu.line import ReplyTap
from aiortu.master._attempt import NO_GUARD
from aiortu.master._line_state import LineState
from aiortu.master._queue import Job, JobFuture
from aiortu.master._stats import UnitStats

__all__ = ("FastPath",)


class FastPath:
    """The fast path of the engine whose state is `engine` (see the module docstring);
    off where its configuration says so (`fast_path`)."""

    __slots__ = (
        "_engine",
        "_future",
        "_known",
        "_stale_before",
        "_start",
        "_stats",
        "_taps",
        "_transaction",
        "enabled",
        "on_wire",
        "waiting",
    )

    def __init__(self, engine: LineState) -> None:
        self._engine = engine
        self.enabled = engine.config.fast_path
        self.on_wire = False
        """Whether an exchange of the fast path is on the wire (it then holds the line)."""
        self.waiting = False
        """Whether its request waits for the line to fall silent (it holds the line)."""
        self._transaction: Any = None
        self._future: Any = None
        self._known: Any = None
        self._stats: Any = None
        self._start = 0.0
        self._stale_before = -math.inf
        self._taps: dict[tuple[bytes, int], ReplyTap] = {}
        """A reply tap for each reply shape, made once (see Link.expect)."""

    def may_run(self, transaction: Transaction, handed: bool) -> KnownRequest | None:
        """The predicate: what the machine remembers of `transaction`'s request where the
        fast path may run it; else None, and it goes through the machine. `handed`: the
        queue has just handed the line to it.

        The line's silence is not a condition: a request that comes before the frame gap
        has passed waits for it on a timer (see `start`). What is left to try is the write
        itself: a stream that does not take it at once hands the transaction to the machine.
        """
        engine = self._engine
        if not (
            # Nobody holds the line (nobody waits for it then), or the queue has just handed
            # it to this caller: a queue of register reads runs each as one caller's. (First:
            # a caller that finds the line busy is told at once.)
            (handed or not engine.queue.busy)
            # The engine's switch: off, every transaction goes through the machine.
            and self.enabled
            # The reply is handed over by the link's read callback: a stream that pushes its
            # bytes (a serial port) has one, and an event loop for the caller's future.
            and engine.link.loop is not None
            # The line task serves a live link (it runs what the machine takes over).
            and engine.open
            # The link writes without a yield: nobody else sends, the stream has not failed.
            and engine.link.sends_at_once
            # After a failed attempt the late-reply guard comes first: the machine's route
            # keeps it.
            and engine.attempts.guard_until == NO_GUARD
            # With fail-fast, a request to an offline unit may be refused: the machine's
            # route decides. One to a unit not known to be offline goes.
            and not (engine.health.fail_fast_offline and _offline(engine, transaction.unit))
        ):
            return None
        # The machine is IDLE (nothing in flight to take over), has no transition observer
        # (it must see every transition), awaits no late reply from the unit (its table
        # recognises one), and the request is a register read to one unit (its reply has a
        # fixed shape, spotted without decoding).
        return engine.machine.usual_exchange(transaction.unit, transaction.request)

    def start(self, transaction: Transaction, job: Job | None = None) -> JobFuture | None:
        """Run `transaction` where the predicate lets it, and return the future its caller
        awaits (`job`'s, for a queued caller the line is handed to); else None. The request
        goes out now if the line is quiet, else once it is (`Link.call_when_quiet`): the
        fast path holds the line meanwhile (`waiting`)."""
        known = self.may_run(transaction, job is not None)
        if known is None:
            return None
        engine = self._engine
        link = engine.link
        engine.queue.busy = True
        self._transaction = transaction
        self._known = known
        future = self._future = link.loop.create_future() if job is None else job.future
        self._send()
        return future

    def _send_when_quiet(self) -> None:
        """The line has been quiet for its frame gap: send, unless the caller is gone (the
        line is then handed on, nothing sent)."""
        self.waiting = False
        if self._future.done():
            self._transaction.abandoned = True
            self._engine.release()
            return
        self._send()

    def _send(self) -> None:
        """Send the request and expect its reply (see the module docstring). A line that has
        not been quiet for its frame gap yet has the request wait for it; a stream that does
        not take the write at once (earlier bytes still queued in it) leaves the transaction
        to the machine, on the line task."""
        engine = self._engine
        link = engine.link
        attempts = engine.attempts
        attempts.events.clear()  # nothing that came before can answer it
        known = self._known
        transaction: Transaction = self._transaction
        frame = known.frame
        end = link.send_now(frame)
        if end is None:
            # Asked only when the write did not go: a poll on a quiet line asks nothing more.
            if link.quiet_at() > link.clock():
                self.waiting = True
                link.call_when_quiet(self._send_when_quiet)
            else:
                self._hand_to_machine(on_the_wire=False)
            return
        self.on_wire = True
        char_time = link.char_time
        self._start = end - len(frame) * char_time
        unit = transaction.unit
        stats = self._stats = engine.stats.get(unit) or engine.unit_stats(unit)
        stats.requests += 1
        shape = known.reply_shape
        assert shape is not None
        if link.wire_timed:
            # The reply's first byte, at its end less (length - 1) characters, must come at
            # `end + reply_delay` or later.
            delay = transaction.reply_delay = (
                engine.unit_turnaround.get(unit, engine.min_turnaround) + char_time
            )
            self._stale_before = end + delay + (shape[1] - 1) * char_time
        else:
            self._stale_before = -math.inf
        attempts.arm(end + transaction.timeout)  # it keeps an earlier timer
        tap = self._taps.get(shape)
        if tap is None:
            tap = self._taps[shape] = ReplyTap(shape[0], shape[1], self.on_reply, None)
        tap.checked = known.last_reply
        link.expect(tap)

    def on_reply(self, frame: bytes, end: float) -> None:
        """The link's read callback: `frame`, the usual reply (its shape matched, its CRC
        checked), ended at `end`. Count it, hand the line on, complete the future."""
        engine = self._engine
        if end < self._stale_before:
            # Begun before the unit could answer: the machine takes over, and skips it.
            self.take_over()
            start = end - (len(frame) - 1) * engine.link.char_time
            engine.attempts.deliver(FrameReceived(frame, start, end))
            return
        self.on_wire = False
        engine.attempts.deadline = math.inf
        known = self._known
        # A poll loop gets the same reply again and again: the same response (see
        # MasterMachine.usual_response), without a call.
        response = (
            known.last_response
            if frame == known.last_reply
            else MasterMachine.usual_response(known, frame)
        )
        stats: UnitStats = self._stats
        stats.count_success(end - self._start)
        future = self._future
        if engine.queue.waiting or not engine.open:
            engine.release()  # may start the next caller's exchange here
        else:
            engine.queue.busy = False
        if not future.done():  # done: cancelled; the reply is counted all the same
            future.set_result(response)

    def take_over(self) -> None:
        """Something other than the usual reply came, or the time ran out: the machine
        takes the attempt over, for the line task to run the rest for the caller."""
        engine = self._engine
        self.on_wire = False
        engine.link.forget_expected()
        self._hand_to_machine(on_the_wire=True)

    def _hand_to_machine(self, *, on_the_wire: bool) -> None:
        """The line task runs the transaction through the machine for the caller, who
        awaits the same future: the rest of it (`on_the_wire`: its first attempt is out),
        or all of it."""
        engine = self._engine
        transaction: Transaction = self._transaction
        if not on_the_wire:
            transaction.reply_delay = engine.reply_delay(transaction.unit)
        else:
            machine = engine.machine
            machine.begin(transaction)
            machine.sent(self._start, self._start + len(self._known.frame) * engine.link.char_time)
        future = self._future
        job = Job(transaction, future)
        if future.done():
            transaction.abandoned = True  # cancelled already: no retries
        else:
            future.add_done_callback(job.abandon_if_cancelled)
        engine.take_over(job, on_the_wire)

    def stop_waiting(self, error: BaseException) -> None:
        """The line is lost (or the engine closes) while the request waits for the
        silence: nothing was sent; its caller gets `error`."""
        self.waiting = False
        self._engine.link.cancel_quiet_call()
        self.fail(error)

    def fail(self, error: BaseException) -> None:
        """The engine closes with the exchange on the wire: its caller gets `error`."""
        future = self._future
        if not future.done():
            future.set_exception(error)


def _offline(engine: LineState, unit: int) -> bool:
    stats = engine.stats.get(unit)
    return stats is not None and not stats.online

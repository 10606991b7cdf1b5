"""The master's line task: the one task that serves a line for as long as its link lives.

Callers run their own transactions (see [`aiortu.master`][aiortu.master]); the line task runs
what no caller can: the attempt a cancelled caller left on the wire (*adopted*: finished,
never retried, so that its reply reaches no later request) and the exchange the machine took
over from the fast path (*taken over*: the rest of the transaction, retries included, for a
caller who awaits its future; all of it where the stream did not take the fast path's write
at once). It also notices a dead link, and fails the queue then.
"""

from __future__ import annotations

import anyio

from aiortu.core.machines import MasterState, OutcomeKind
from aiortu.errors import ConnectionLost
from aiortu.line import Link
from aiortu.master._line_state import LineState
from aiortu.master._queue import Job

__all__ = ("LineTask",)


class LineTask:
    """The line task of the engine whose state is `engine` (see the module docstring)."""

    __slots__ = ("_engine", "_on_the_wire", "_wake", "job", "taken_over")

    def __init__(self, engine: LineState) -> None:
        self._engine = engine
        self._wake = anyio.Event()
        self.job: Job | None = None
        """The job the line task runs: adopted, or taken over (`taken_over`)."""
        self.taken_over = False
        self._on_the_wire = True

    def wake(self) -> None:
        """Have the line task look at the line again (a job for it, or the link closed)."""
        self._wake.set()

    def adopt(self, job: Job) -> None:
        """`job`'s caller is gone mid-attempt: finish the attempt, without retries."""
        job.transaction.abandoned = True
        self.job, self.taken_over = job, False
        self._wake.set()

    def take_over(self, job: Job, on_the_wire: bool) -> None:
        """Run the rest of `job`, begun by the fast path, for its caller (all of it unless
        its first attempt is `on_the_wire`)."""
        self.job, self.taken_over, self._on_the_wire = job, True, on_the_wire
        self._wake.set()

    async def serve(self, link: Link) -> ConnectionLost:
        """Serve the line on `link` (entered by the caller) until it fails; return why.

        The request in flight and the queued ones fail with the link's ConnectionLost;
        requests made afterwards wait for the next `serve` or fail (see the engine's
        `submit`)."""
        engine = self._engine
        engine.attach(link)
        try:
            if not engine.queue.busy:
                engine.release()
            while not (link.closed and not engine.queue.busy):
                await self._wake.wait()
                self._wake = anyio.Event()
                job = self.job
                if job is not None and self.taken_over:
                    await self._finish_taken_over(job)
                elif job is not None:
                    await self._finish_adopted(job)
        finally:
            engine.detach()
        return link.connection_lost_error()

    async def _finish_adopted(self, job: Job) -> None:
        """Finish the attempt of a caller gone mid-attempt (no retries), then hand on."""
        engine = self._engine
        stats = engine.unit_stats(job.transaction.unit)
        try:
            outcome = await engine.attempts.outcome(stats)
            # Abandoned: the machine retries nothing, so this is the end.
            if outcome.kind is OutcomeKind.RETRY:  # pragma: no cover - defensive
                stats.count_failed_attempt(job.transaction)
            else:
                engine.settle(job, outcome, stats)
        except ConnectionLost as error:
            engine.machine.connection_lost(error)
            job.finish(None, error)
        except BaseException:
            self._stop_serving(job)
            raise
        finally:
            self.job = None
            engine.release()

    async def _finish_taken_over(self, job: Job) -> None:
        """Run the rest of a fast-path exchange the machine took over, for its caller."""
        engine = self._engine
        try:
            if self._on_the_wire or not job.future.done():  # done: cancelled, not begun
                await engine.exchange(job, on_the_wire=self._on_the_wire)
        except Exception as error:
            job.finish(None, error)  # told already, unless the error is a bug's
        except BaseException:
            self._stop_serving(job)
            raise
        finally:
            if self.job is job:
                self.job = None
            engine.release()

    def _stop_serving(self, job: Job) -> None:
        """The line task is cancelled (the master closes) while it runs `job`.

        The attempt on the wire is given up: the machine goes back to IDLE (through its
        table, as if the line were lost) and `job` fails. The line is not handed on: a
        queued caller would begin a transaction nobody can finish; the engine's close fails
        the queue instead.
        """
        engine = self._engine
        engine.open = False
        error = ConnectionLost("the master is closed")
        if engine.machine.state is not MasterState.IDLE:
            engine.machine.connection_lost(error)
        job.finish(None, error)

"""One client connection of the gateway: its window, its turns on each line, its writer.

- **The window.** At most `window` requests of the connection wait for the line at once;
  the connection's reader waits (`room`) before it takes the next, so nothing more is read
  from a client whose window is full, and TCP holds it back.
- **Turns.** Each request to a line takes the connection's next turn there (`turn`), never
  earlier than the line's current turn: the engine's queue serves lower turns first, so busy
  connections interleave round-robin and a newcomer waits for one request of each.
- **Leaving.** `leave` cancels the connection's requests: those still queued are dropped
  before they reach the line, one on the wire completes there (the engine finishes it).
- **Callbacks and workers.** A request whose reply comes as an event loop future (a read the
  engine runs itself) is answered from the future's done-callback, with no task; the
  connection keeps those futures (`on_line`) to cancel them when it leaves. The others run on
  the connection's own tasks, at most one per request in flight: one that has answered its
  request takes the next queued (`put`), or waits for it (`park`), so a request costs no
  task of its own.
- **Stalls.** A reply that cannot be written (the client reads nothing) for `idle_timeout`
  seconds makes the connection idle: `send` says so, and the gateway closes it.
"""

from __future__ import annotations

from collections import deque
from collections.abc import Callable
from functools import partial
from typing import Any, Final, Generic, TypeVar

import anyio
import anyio.abc

from aiortu.core.mbap import Adu
from aiortu.line import loop_clock
from aiortu.transport import Framing, PushServerStream, RoleRules, write_now

__all__ = ("GONE", "Connection", "Turns")

R = TypeVar("R")

GONE: Final = (anyio.EndOfStream, anyio.BrokenResourceError, anyio.ClosedResourceError)
"""What a stream raises once its client has gone."""


class Turns:
    """A line's current turn: the highest turn of a request the line has answered."""

    __slots__ = ("now",)

    def __init__(self) -> None:
        self.now = 0


class Connection(Generic[R]):
    """One client, whose requests are `R`s (see the module docstring)."""

    def __init__(
        self,
        stream: anyio.abc.ByteStream,
        framing: Framing,
        *,
        priority: int,
        window: int,
        idle_timeout: float,
        client: str,
        rules: RoleRules | None = None,
        role: str | None = None,
    ) -> None:
        self.stream = stream
        self._write_now: Callable[[bytes], bool] = (
            stream.write_now if isinstance(stream, PushServerStream) else partial(write_now, stream)
        )
        """Write at once where the stream takes bytes without a wait (False: nothing written)."""
        self.priority = priority
        self.window = window
        self.framing = framing
        self.idle_timeout = idle_timeout
        self.client = client
        self.rules = rules
        """The listener's access rules (None: every request is allowed)."""
        self.role = role
        """The role of the client's certificate (None: the rules' default role)."""
        self.warned = False
        """Whether a refused request of this connection was logged as a warning."""
        self.in_flight = 0
        """Requests started and not answered yet."""
        self.clock = loop_clock()
        """Reads the event loop's time in seconds (a connection is made in the loop)."""
        self.heard = self.clock()
        """When the client last sent bytes or was answered (on `clock`)."""
        self.open = True
        self.tasks: anyio.abc.TaskGroup | None = None
        """The connection's requests (set while it is served)."""
        self.pending: deque[R] = deque()
        """Requests started that no worker has taken yet (see `put`)."""
        self.on_line: set[Any] = set()
        """The futures of the requests answered from a callback, until they are done."""
        self.unsent: deque[tuple[Adu, bytes]] = deque()
        """Replies the stream did not take at once, for the connection's writer (see
        `send_later`)."""
        self._unsent_event = anyio.Event()
        self._parked: list[anyio.Event] = []
        self._turns: dict[Turns, int] = {}
        self._freed: anyio.Event | None = None
        self._send_lock = anyio.Lock(fast_acquire=True)

    def turn(self, line: Turns) -> int:
        """The connection's next turn on `line` (see the module docstring)."""
        turn = max(self._turns.get(line, 0), line.now)
        self._turns[line] = turn + 1
        return turn

    async def room(self) -> None:
        """Wait until the window has room."""
        while self.in_flight >= self.window:
            await self.freed()

    async def freed(self) -> None:
        """Wait until a request is answered."""
        freed = self._freed = anyio.Event()
        await freed.wait()

    def done(self) -> None:
        """A request is answered (or dropped): its place in the window is free."""
        self.in_flight -= 1
        self.heard = self.clock()
        freed = self._freed
        if freed is not None:
            self._freed = None
            freed.set()

    def put(self, request: R) -> bool:
        """Queue `request` for the connection's workers and wake one that is parked; False
        when none is (start one: at most one per request in flight is ever needed)."""
        self.pending.append(request)
        if not self._parked:
            return False
        self._parked.pop().set()
        return True

    @property
    def parked(self) -> bool:
        """Whether a worker waits in `park` (`put` hands it the next request)."""
        return bool(self._parked)

    async def park(self) -> None:
        """Wait, as a worker with nothing to do, until `put` queues a request."""
        worker = anyio.Event()
        self._parked.append(worker)
        await worker.wait()

    def send_now(self, request: Adu, reply: bytes) -> bool:
        """Send `reply` with `request`'s ids at once where the stream takes it without a wait
        and no earlier reply waits (True; also for a client gone: nothing to send); False:
        nothing sent, use `send_later`."""
        if not self.open:
            return True
        if self._send_lock.locked() or self.unsent:
            return False
        return self._write_now(self.framing.encode(request, reply))

    def send_later(self, request: Adu, reply: bytes) -> None:
        """Have the connection's writer send `reply` (from a callback, where no task can)."""
        self.unsent.append((request, reply))
        self._unsent_event.set()

    async def next_unsent(self) -> tuple[Adu, bytes]:
        """The oldest reply `send_later` kept, once there is one (for the writer)."""
        while not self.unsent:
            await self._unsent_event.wait()
            self._unsent_event = anyio.Event()
        return self.unsent[0]

    async def send(self, request: Adu, reply: bytes) -> bool:
        """Send `reply` with `request`'s ids; a client gone leaves (see `leave`). False when
        the reply could not be written for `idle_timeout` seconds: the client reads nothing."""
        if not self.open:
            return True
        data = self.framing.encode(request, reply)
        if not self._send_lock.locked() and self._write_now(data):
            return True
        with anyio.move_on_after(self.idle_timeout):
            async with self._send_lock:
                try:
                    await self.stream.send(data)
                except GONE:
                    self.leave()
            return True
        return not self.open

    def leave(self) -> None:
        """The client has gone, or is sent away: drop its requests (see the module docstring)."""
        self.open = False
        for future in self.on_line:
            future.cancel()  # queued: dropped; on the wire: it completes there
        if self.tasks is not None:
            self.tasks.cancel_scope.cancel()

"""The messages waiting for the broker, in order, within a bound of messages and bytes.

The bridge keeps polling while the broker is away; what it would have published waits here
and goes out, oldest first, when the broker is back. Past `max_messages` or `max_bytes` the
oldest messages are dropped and counted in [`Outbox.dropped`][aiortu.bridge.Outbox.dropped]:
a bounded memory, and a count that tells how much was lost.
"""

from __future__ import annotations

from collections import deque
from collections.abc import Callable, Collection, Iterable, Sequence
from dataclasses import dataclass, field
from operator import attrgetter

import anyio

from aiortu.errors import InvalidValue

__all__ = ("Message", "Outbox")


@dataclass(slots=True)
class Message:
    """One message for the broker: `payload` on `topic` at `qos`, `retain`ed or not.

    `created` is when the bridge made it (the clock of `anyio.current_time`); `metrics` is
    set on a Sparkplug B message, whose payload is encoded when it is sent (its sequence
    number is the session's at that moment).
    """

    topic: str
    payload: bytes
    qos: int = 1
    retain: bool = False
    created: float = 0.0
    metrics: object = field(default=None, repr=False)

    @property
    def size(self) -> int:
        """The bytes the message holds (its topic and payload)."""
        return _size((self,))


_TOPIC, _PAYLOAD = attrgetter("topic"), attrgetter("payload")


def _size(messages: Collection[Message]) -> int:
    """The bytes `messages` hold (their topics and payloads), counted in C: a poll's messages
    are put and taken by the batch."""
    return sum(map(len, map(_TOPIC, messages))) + sum(map(len, map(_PAYLOAD, messages)))


class Outbox:
    """A FIFO of [`Message`][aiortu.bridge.Message]s bounded by `max_messages` and `max_bytes`
    (see the module docstring)."""

    def __init__(self, max_messages: int = 100_000, max_bytes: int = 64 * 1024 * 1024) -> None:
        if isinstance(max_messages, bool) or not isinstance(max_messages, int) or max_messages < 1:
            raise InvalidValue("max_messages", max_messages, "an integer >= 1")
        if isinstance(max_bytes, bool) or not isinstance(max_bytes, int) or max_bytes < 1:
            raise InvalidValue("max_bytes", max_bytes, "an integer >= 1")
        self.max_messages = max_messages
        self.max_bytes = max_bytes
        self._queue: deque[Message] = deque()
        self._bytes = 0
        self._ready = anyio.Event()
        self._listener: Callable[[], None] | None = None
        self.dropped = 0
        """Messages dropped, oldest first, to stay within the bound."""
        self.accepted = 0
        """Messages put in, every one counted."""

    def __len__(self) -> int:
        return len(self._queue)

    @property
    def bytes(self) -> int:
        """The bytes the waiting messages hold."""
        return self._bytes

    def put(self, message: Message) -> None:
        """Queue `message` last; drop the oldest while over the bound."""
        self.put_all((message,))

    def put_all(self, messages: Sequence[Message]) -> None:
        """Queue `messages` last, in their order; drop the oldest while over the bound (what
        stays is what putting them one by one would leave)."""
        if not messages:
            return
        self._queue.extend(messages)
        self._bytes += _size(messages)
        self.accepted += len(messages)
        self._trim()
        self._wake()

    def put_back(self, messages: Iterable[Message]) -> None:
        """Queue `messages` (sent but never acknowledged) first, in their order."""
        back = list(messages)
        self._queue.extendleft(reversed(back))
        self._bytes += _size(back)
        self._trim()
        if self._queue:
            self._wake()

    def take(self, count: int) -> list[Message]:
        """Up to `count` messages from the front."""
        queue = self._queue
        if count >= len(queue):
            taken = list(queue)
            queue.clear()
            self._bytes = 0
            return taken
        taken = [queue.popleft() for _ in range(count)]
        self._bytes -= _size(taken)
        return taken

    def notify(self, listener: Callable[[], None] | None) -> None:
        """Call `listener` (a plain function, which may `take`) after each put, in place of
        waking [`wait`][aiortu.bridge.Outbox.wait]; None wakes `wait` again. A session that
        writes from the event loop's callbacks sends at once this way, with no task woken."""
        self._listener = listener

    def _wake(self) -> None:
        if self._listener is not None:
            self._listener()
        else:
            self._ready.set()

    async def wait(self) -> None:
        """Return once a message waits (at once if one does)."""
        while not self._queue:
            self._ready = anyio.Event()
            await self._ready.wait()

    def _trim(self) -> None:
        queue = self._queue
        while len(queue) > self.max_messages or (self._bytes > self.max_bytes and len(queue) > 1):
            self._bytes -= queue.popleft().size
            self.dropped += 1

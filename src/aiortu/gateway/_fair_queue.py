"""Round-robin between connections: a chatty client cannot starve a quiet one.

Each connection has a lane of requests waiting for the line. `FairQueue.take` serves the lanes
of the lowest priority value first, and within one priority one request from each lane in turn,
so a request waits for at most one request of every other busy lane of its priority (plus those
already handed to the engine), however many the others have queued.
"""

from __future__ import annotations

from collections import deque
from typing import Generic, TypeVar

import anyio

__all__ = ("FairQueue", "Lane")

_T = TypeVar("_T")


class Lane(Generic[_T]):
    """The requests of one connection waiting for the line, oldest first."""

    __slots__ = ("items", "priority", "queued")

    def __init__(self, priority: int) -> None:
        self.priority = priority
        self.items: deque[_T] = deque()
        self.queued = False


class FairQueue(Generic[_T]):
    """Lanes served in turn, lower priority values first (see the module docstring)."""

    def __init__(self) -> None:
        self._rings: dict[int, deque[Lane[_T]]] = {}
        self._changed = anyio.Event()

    def put(self, lane: Lane[_T], item: _T) -> None:
        """Queue `item` at the end of `lane`."""
        lane.items.append(item)
        if not lane.queued:
            lane.queued = True
            self._rings.setdefault(lane.priority, deque()).append(lane)
        self._changed.set()

    def take_nowait(self) -> _T | None:
        """The next item in turn, or None when every lane is empty."""
        for priority in sorted(self._rings):
            ring = self._rings[priority]
            if not ring:
                continue
            lane = ring.popleft()
            item = lane.items.popleft()
            if lane.items:
                ring.append(lane)  # to the back: the others go first
            else:
                lane.queued = False
            return item
        return None

    async def take(self) -> _T:
        """Wait for the next item in turn."""
        while (item := self.take_nowait()) is None:
            self._changed = anyio.Event()
            await self._changed.wait()
        return item

    def drop(self, lane: Lane[_T]) -> None:
        """Forget `lane` and what it holds (its connection closed)."""
        lane.items.clear()
        if lane.queued:
            lane.queued = False
            self._rings[lane.priority].remove(lane)

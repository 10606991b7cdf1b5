"""What the pollers share: run in the background as an async context manager, and hand
their results to `async for` through a bounded stream that drops the oldest."""

from __future__ import annotations

from collections.abc import AsyncIterator
from types import TracebackType
from typing import Generic, Self, TypeVar

import anyio
import anyio.abc
from anyio.streams.memory import MemoryObjectReceiveStream, MemoryObjectSendStream

__all__ = ("BackgroundPoll",)

T = TypeVar("T")


class BackgroundPoll(Generic[T]):
    """A poll loop (`run`) started by `async with` and stopped at its end; an async iterator of
    its results. Subclasses call `_open_stream` in `__init__` and give `dropped` its docstring."""

    _task_name = "aiortu poll"
    dropped: int

    def _open_stream(self, max_pending: int) -> None:
        self._send: MemoryObjectSendStream[T]
        self._receive: MemoryObjectReceiveStream[T]
        self._send, self._receive = anyio.create_memory_object_stream[T](max_pending)
        self._task_group: anyio.abc.TaskGroup | None = None
        self.dropped = 0

    async def run(self, *, cycles: int | None = None, duration: float | None = None) -> None:
        raise NotImplementedError

    def _publish(self, item: T) -> None:
        try:
            self._send.send_nowait(item)
        except anyio.WouldBlock:
            # Drop the oldest: a consumer that catches up wants the newest values.
            self._receive.receive_nowait()
            self.dropped += 1
            self._send.send_nowait(item)
        except anyio.ClosedResourceError:
            pass

    async def __aenter__(self) -> Self:
        self._task_group = anyio.create_task_group()
        await self._task_group.__aenter__()
        self._task_group.start_soon(self.run, name=self._task_name)
        return self

    async def __aexit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        traceback: TracebackType | None,
    ) -> bool | None:
        task_group, self._task_group = self._task_group, None
        if task_group is None:
            return None
        task_group.cancel_scope.cancel()
        return await task_group.__aexit__(exc_type, exc, traceback)

    def __aiter__(self) -> AsyncIterator[T]:
        return self

    async def __anext__(self) -> T:
        try:
            return await self._receive.receive()
        except (anyio.EndOfStream, anyio.ClosedResourceError):
            raise StopAsyncIteration from None

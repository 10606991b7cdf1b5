"""One event loop in a thread of its own, which every blocking object shares, and `Running`:
an async object entered in that loop and left from any thread.

The loop's thread starts with the first blocking object and stops when the last is closed
([`anyio.from_thread.BlockingPortalProvider`][]). One loop for all of them lets a blocking master
and a blocking slave share an in-memory [`VirtualBus`][aiortu.testing.VirtualBus], whose
endpoints belong to the loop that uses them. A call from a thread waits on the loop, so it works
as well in a thread whose own loop is running (Jupyter, IPython, `python -m asyncio`).
"""

from __future__ import annotations

import atexit
import concurrent.futures
import functools
import threading
from collections.abc import Callable
from contextlib import AbstractAsyncContextManager, AbstractContextManager
from types import TracebackType
from typing import Any, Generic, ParamSpec, Self, TypeVar

from anyio.from_thread import BlockingPortal, BlockingPortalProvider

from aiortu._derived import derive
from aiortu.errors import ConnectionLost

__all__ = ("Running", "running")

_T = TypeVar("_T")
_P = ParamSpec("_P")

_PROVIDER = BlockingPortalProvider()

_open: dict[int, Running[Any]] = {}
"""The objects not closed yet, oldest first: closed at exit, newest first, while the loop's
thread still runs (left to the garbage collector, the loop would be stopped when no thread
can run any more, and the interpreter would hang on its way out)."""


@atexit.register
def _close_at_exit() -> None:
    for running in reversed(list(_open.values())):
        running.close()


class Running(Generic[_T]):
    """An async object (a slave, a server, a bus) running in the blocking API's event loop
    thread; a context manager. [`close`][aiortu.blocking.Running.close] leaves it, from any
    thread. Its `value` is the object itself: read its attributes (a server's `port`, a bus's
    `paths`), but call its async methods through the blocking API only."""

    def __init__(self, enter: Callable[[], AbstractAsyncContextManager[_T]], what: str) -> None:
        """Make the async context manager `enter()` in the loop and enter it there; `what`
        names the object in errors ("the master")."""
        self._what = what
        self._lock = threading.Lock()
        self._closed = False
        self._portal: BlockingPortal = _PROVIDER.__enter__()
        try:
            self._loop_thread = self._portal.call(threading.get_ident)
            self._context: AbstractContextManager[_T] = self._portal.wrap_async_context_manager(
                self._portal.call(enter)
            )
            self.value: _T = self._context.__enter__()
        except BaseException:
            _PROVIDER.__exit__(None, None, None)
            raise
        _open[id(self)] = self

    @property
    def closed(self) -> bool:
        """Whether [`close`][aiortu.blocking.Running.close] was called."""
        return self._closed

    def call(self, function: Callable[..., Any], /, *args: Any, **kwargs: Any) -> Any:
        """Run `function(*args, **kwargs)` in the loop (awaited if it is async) and return its
        result; raise [`ConnectionLost`][aiortu.errors.ConnectionLost] once closed."""
        if self._closed:
            raise ConnectionLost(f"{self._what} is closed")
        self._check_thread()
        try:
            future = self._portal.start_task_soon(functools.partial(function, *args, **kwargs))
        except RuntimeError:  # the loop stopped: closed meanwhile
            raise ConnectionLost(f"{self._what} is closed") from None
        try:
            return future.result()
        except concurrent.futures.CancelledError:
            raise ConnectionLost(f"{self._what} is closed") from None
        except BaseException:
            future.cancel()  # KeyboardInterrupt in the waiting thread: stop the call too
            raise

    def close(self) -> None:
        """Leave the object (its `async with` ends in the loop) and release the loop, whose
        thread stops with the last object; from any thread but the loop's, at most once."""
        self._check_thread()
        with self._lock:
            if self._closed:
                return
            self._closed = True
            _open.pop(id(self), None)
            try:
                self._context.__exit__(None, None, None)
            finally:
                _PROVIDER.__exit__(None, None, None)

    def _check_thread(self) -> None:
        if threading.get_ident() == self._loop_thread:
            raise RuntimeError(
                f"{self._what} cannot be used blocking from its own event loop"
                " (in a handler or a callback it runs): await the async object instead"
            )

    def __enter__(self) -> Self:
        return self

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        traceback: TracebackType | None,
    ) -> None:
        self.close()


def running(
    opener: Callable[_P, AbstractAsyncContextManager[_T]], what: str, doc: str, returns: str
) -> Callable[_P, Running[_T]]:
    """A function that takes `opener`'s arguments and returns the object it opens, entered in
    the blocking API's loop, as a [`Running`][aiortu.blocking.Running]."""

    def start(*args: _P.args, **kwargs: _P.kwargs) -> Running[_T]:
        return Running(lambda: opener(*args, **kwargs), what)

    derive(start, opener, None, doc=doc, returns=returns)
    return start

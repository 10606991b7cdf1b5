"""The push extension: a byte stream that hands over received bytes and writes without a yield.

Any `anyio.abc.ByteStream` carries a line; a stream that also has the two methods of
[`PushStream`][aiortu.transport.PushStream] lets the [`Link`][aiortu.line.Link] skip a task wake-up
per chunk read and per frame sent. The serial port's [`SerialStream`][aiortu.transport.SerialStream]
implements it. The extension is structural: a stream needs no base class, only both methods with
these signatures.

The link checks for it once, when it is made (`isinstance(stream, PushStream)`), and keeps the bound
methods, so the check costs nothing per chunk. It reads a push stream through
[`PushStream.set_receiver`][aiortu.transport.PushStream.set_receiver] only where the running event
loop offers `call_at` timers (asyncio); elsewhere (trio) it reads it through `receive()` like any
other stream, so a push stream must keep `receive()` and `send()` working as well.
"""

from __future__ import annotations

import asyncio
from collections.abc import Callable
from typing import Protocol, runtime_checkable

import anyio
import anyio.lowlevel

__all__ = ("PushStream", "loop_pushes")


def loop_pushes() -> bool:
    """Whether the running event loop is asyncio's, whose protocol callbacks can push a network
    stream's bytes (a master's Modbus TCP, UDP and TLS streams are pushed there)."""
    try:
        asyncio.get_running_loop()
    except RuntimeError:
        return False
    return True


@runtime_checkable
class PushStream(Protocol):
    """The methods a byte stream adds to push its bytes and to write without a yield.

    Both are called from the event loop's thread, never from another thread, and both
    must return without blocking or yielding: they are plain functions, not coroutines.
    """

    def set_receiver(
        self,
        receiver: Callable[[bytes], None] | None,
        on_lost: Callable[[], None] | None = None,
    ) -> None:
        """Hand every chunk received from now on to `receiver`, instead of keeping it
        for `receive()`; `None` keeps chunks for `receive()` again.

        Called by the link's reader task when it starts (with its chunk callback) and
        when it stops (with `None`). The stream must:

        - call `receiver` with each non-empty chunk, in order, in the event loop's thread: from a
          callback (the serial port's read callback) or from the task that wrote the bytes (an
          in-memory line), never from inside this stream's own
          [`send_nowait`][aiortu.transport.PushStream.send_nowait]; bytes already kept go to
          `receiver` at once, before this method returns;
        - call `on_lost` once when the stream fails or is closed, also at once if it
          already has; `receive()` then raises what ended the stream
          (`anyio.BrokenResourceError`, `anyio.EndOfStream` or
          `anyio.ClosedResourceError`);
        - keep nothing for `receive()` while a receiver is set.

        `receiver` may call [`send_nowait`][aiortu.transport.PushStream.send_nowait] (a slave
        answers from there), and may raise only on a bug: the link catches everything in it and ends
        its reader.
        """
        ...

    def send_nowait(self, item: bytes) -> bool:
        """Write `item` now, without a yield, if the stream can take it; return whether
        it did.

        Called by the link ([`send`][aiortu.line.Link.send] and
        [`send_now`][aiortu.line.Link.send_now]), from a task or from a *receiver* callback,
        before it falls back to `await send(item)`. True means the stream has all of
        `item`: written, or queued behind nothing and going out as soon as the port can
        take it, in order. False means nothing was written (closed, failed, or earlier
        bytes still queued); the caller then uses `send()`, which waits its turn or
        raises why.
        """
        ...


def ended(error: BaseException | None, transport: object | None) -> BaseException | None:
    """Why a pushed connection takes no more writes: the `error` it ended with, or closed
    before it had a `transport`; None while it takes them."""
    if error is None and transport is None:
        return anyio.ClosedResourceError()
    return error


class WriteGate:
    """An asyncio transport's write flow control, for a pushed stream: whether its buffer is
    below the high-water mark (`open`), and a wait until it drains."""

    __slots__ = ("_drained", "open")

    def __init__(self) -> None:
        self.open = True
        self._drained: asyncio.Future[None] | None = None

    def pause(self) -> None:
        """The transport's buffer went above its high-water mark."""
        self.open = False

    def resume(self) -> None:
        """The buffer drained below its low-water mark, or the connection ended: a writer
        waiting sees which."""
        self.open = True
        drained = self._drained
        if drained is not None and not drained.done():
            drained.set_result(None)

    async def write(
        self,
        write_now: Callable[[bytes], bool],
        item: bytes,
        failure: Callable[[], BaseException | None],
    ) -> None:
        """`write_now(item)` once the buffer has room: a stream's `send`. `failure()` says why
        the connection can take nothing more (None while it can); it is raised."""
        await anyio.lowlevel.checkpoint()
        while not write_now(item):
            error = failure()
            if error is not None:
                raise error
            await self.drained()

    async def drained(self) -> None:
        """Wait for the next `resume`."""
        self._drained = asyncio.get_running_loop().create_future()
        try:
            await self._drained
        finally:
            self._drained = None

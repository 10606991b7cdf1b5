"""The serial transport's write path when the OS buffer fills: no spin, nothing lost."""

from __future__ import annotations

import asyncio
import contextlib
import os
from collections.abc import Iterator
from typing import Any

import anyio

from aiortu.transport import SerialStream, open_serial
from tests.transport.ptys import LINE, Pty, open_pty

_FILL_LIMIT = 16 * 1024 * 1024
"""Far more than any pty buffers: the fill loop stops at a partial write long before."""


@contextlib.contextmanager
def recorded_loop_exceptions() -> Iterator[list[dict[str, Any]]]:
    """Every context the running loop's exception handler is called with, while inside."""
    loop = asyncio.get_running_loop()
    previous = loop.get_exception_handler()
    seen: list[dict[str, Any]] = []
    loop.set_exception_handler(lambda _loop, context: seen.append(context))
    try:
        yield seen
    finally:
        loop.set_exception_handler(previous)


def block(number: int) -> bytes:
    """256 bytes that say where they belong: a reordered or lost block shows."""
    return number.to_bytes(4, "big") * 64


def fill(stream: SerialStream) -> bytearray:
    """Write blocks without a yield until the driver takes one only in part; return
    every block taken (the rest of the last one is queued in the transport)."""
    sent = bytearray()
    while len(sent) < _FILL_LIMIT:
        data = block(len(sent) // 256)
        if not stream.send_nowait(data):
            return sent  # the block before was written in part: the rest waits
        sent += data
    raise AssertionError("the pty never filled up")


async def drain(pty: Pty, count: int) -> bytes:
    """Read as the device until *count* bytes have come."""
    received = bytearray()
    with anyio.fail_after(10):
        while len(received) < count:
            await anyio.wait_readable(pty.master)
            with contextlib.suppress(BlockingIOError):
                received += os.read(pty.master, 65536)
    return bytes(received)


async def test_a_full_output_buffer_drains_in_order_and_then_idles() -> None:
    with recorded_loop_exceptions() as loop_exceptions, open_pty() as pty:
        async with await open_serial(pty.path, LINE) as stream:
            sent = fill(stream)
            assert stream._transport.get_write_buffer_size() > 0
            # The reader stalls: a send waits behind the bytes still queued.
            tail = block(len(sent) // 256 + 1)
            async with anyio.create_task_group() as tg:
                tg.start_soon(stream.send, tail)
                await anyio.sleep(0.2)
                # The reader resumes and takes everything.
                received = await drain(pty, len(sent) + len(tail))
            assert stream._transport.get_write_buffer_size() == 0
            assert stream.send_nowait(block(0))  # the fast path is open again
            received += await drain(pty, 256)
            # Idle: nothing is left watching the writable descriptor. A writer left there
            # would run on every pass of the loop: the dependency's raises each time (the
            # exception list catches that), one that finds nothing to write spins
            # silently. remove_writer() is False when no writer is registered.
            await anyio.sleep(0.05)  # a few loop passes: any writer would have run
            assert not stream._transport._watching_writable
            assert not asyncio.get_running_loop().remove_writer(stream._transport._fd)
        assert received == sent + tail + block(0)
        assert loop_exceptions == []


async def test_closing_with_output_queued_sends_it_all_then_releases_the_port() -> None:
    with recorded_loop_exceptions() as loop_exceptions, open_pty() as pty:
        stream = await open_serial(pty.path, LINE)
        sent = fill(stream)
        assert stream._transport.get_write_buffer_size() > 0
        aborted: list[bool] = []
        abort = stream._transport.abort
        stream._transport.abort = lambda: (aborted.append(True), abort())[1]  # type: ignore[method-assign]
        async with anyio.create_task_group() as tg:
            tg.start_soon(stream.aclose)
            received = await drain(pty, len(sent))
        assert received == sent
        assert stream._protocol.done.is_set()
        assert aborted == []  # closed once the queue drained, not after the close timeout
        assert not stream._transport._watching_writable
        # Released: the port opens again at once (it is opened exclusively).
        async with await open_serial(pty.path, LINE):
            pass
        assert loop_exceptions == []


async def test_a_hangup_with_output_queued_breaks_the_send_and_stops_watching() -> None:
    with recorded_loop_exceptions() as loop_exceptions, open_pty() as pty:
        stream = await open_serial(pty.path, LINE)
        try:
            fill(stream)
            failed: list[BaseException] = []

            async def send_tail() -> None:
                try:
                    await stream.send(block(0))
                except anyio.BrokenResourceError as error:
                    failed.append(error)

            async with anyio.create_task_group() as tg:
                tg.start_soon(send_tail)
                await anyio.sleep(0.05)
                pty.close_master()  # the adapter is unplugged: the queued bytes cannot go
            assert len(failed) == 1
            assert not stream._transport._watching_writable
            assert stream._transport.get_write_buffer_size() == 0
            with anyio.fail_after(2):
                await stream._protocol.done.wait()
            assert loop_exceptions == []  # reported by the stream, not logged by the loop
        finally:
            await stream.aclose()

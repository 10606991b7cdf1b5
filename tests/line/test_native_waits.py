"""The backend's cheapest waits: the same behaviour under asyncio and trio."""

from __future__ import annotations

import time

import anyio
import anyio.lowlevel
import pytest

from aiortu.line import loop_clock, native_waits
from tests.virtual_clock import on_virtual_clock

BACKENDS = ("asyncio", "trio")


async def _waiter_wakes_from_a_callback() -> None:
    waits = native_waits()
    waiter = waits.waiter()
    assert not waiter.done()
    order: list[str] = []

    def wake() -> None:
        order.append("callback")
        waiter.set_result(None)

    waits.call_soon(wake)
    order.append("called soon")  # call_soon never runs the callback inside the call
    with anyio.fail_after(5):
        await waiter
    assert waiter.done()
    assert order == ["called soon", "callback"]
    assert abs(waits.time() - anyio.current_time()) < 0.1


async def _a_cancelled_wait_ends() -> None:
    waiter = native_waits().waiter()
    with anyio.move_on_after(0.01) as scope:
        await waiter
    assert scope.cancelled_caught


async def _timed_callbacks_only_on_asyncio(backend: str) -> None:
    waits = native_waits()
    if backend == "asyncio":
        assert waits.loop is not None
        assert waits.call_at is not None
        fired = anyio.Event()
        waits.call_at(waits.time() + 0.001, fired.set)
        with anyio.fail_after(5):
            await fired.wait()
    else:
        assert waits.loop is None
        assert waits.call_at is None


@pytest.mark.parametrize("backend", BACKENDS)
def test_a_waiter_is_woken_by_a_callback_called_soon(backend: str) -> None:
    anyio.run(_waiter_wakes_from_a_callback, backend=backend)


@pytest.mark.parametrize("backend", BACKENDS)
def test_a_wait_can_be_cancelled(backend: str) -> None:
    anyio.run(_a_cancelled_wait_ends, backend=backend)


@pytest.mark.parametrize("backend", BACKENDS)
def test_timed_callbacks_exist_only_where_the_loop_has_them(backend: str) -> None:
    anyio.run(_timed_callbacks_only_on_asyncio, backend, backend=backend)


def test_the_loop_clock_of_asyncio_s_own_loops_is_time_monotonic() -> None:
    async def clock() -> object:
        return loop_clock()

    assert anyio.run(clock, backend="asyncio") is time.monotonic


@on_virtual_clock
async def test_the_loop_clock_tells_the_backend_s_time_virtual_or_not() -> None:
    clock = loop_clock()
    assert clock is not time.monotonic  # the virtual loop tells time of its own
    start = clock()
    assert start == anyio.current_time()
    await anyio.sleep(1000)  # no real time: the clock jumps
    assert clock() - start == 1000
    assert clock() == anyio.current_time()


def test_the_loop_clock_reads_the_running_loop_unless_given_its_token() -> None:
    with pytest.raises(RuntimeError):
        loop_clock()  # no event loop runs

    async def clocks() -> tuple[object, object]:
        token = anyio.lowlevel.current_token()
        return loop_clock(token), loop_clock()

    given, running = anyio.run(clocks, backend="trio")
    assert given == running

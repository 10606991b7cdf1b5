"""Many concurrent callers on one master and one slave: every attempt reaches the slave.

On every kind of test bench line (an unpaced VirtualBus, pushing or read as a plain
stream, virtual_pair, the pty bus), a thousand callers each read three times; nothing
times out, nothing is retried, the slave counts one message per request and every caller
gets its own registers.
"""

from __future__ import annotations

import time
from collections.abc import AsyncIterator, Callable
from contextlib import AbstractAsyncContextManager, asynccontextmanager
from dataclasses import dataclass
from typing import Any

import anyio
import pytest

import aiortu
from aiortu.testing import PtyBus, VirtualBus, virtual_pair

pytestmark = pytest.mark.timeout(60)

VALUES = list(range(1000, 1100))
ROUNDS = 3


@dataclass
class Bench:
    """A master and a slave (unit 1) on one line."""

    master: aiortu.Master
    slave: aiortu.Slave


async def read_as_callers(
    bench: Bench, callers: int, hold_up: Callable[[], None] | None = None
) -> None:
    """*callers* tasks each read 10 registers ROUNDS times at their own address; check
    each result. *hold_up*, a blocking call, runs in one more task started after them:
    it holds up the loop pass that runs their first steps."""
    wrong: list[int] = []

    async def caller(number: int) -> None:
        address = number % 90
        for _ in range(ROUNDS):
            registers = await bench.master.read_holding_registers(1, address, 10)
            if registers != VALUES[address : address + 10]:
                wrong.append(number)

    async with anyio.create_task_group() as group:
        for number in range(callers):
            group.start_soon(caller, number)
        if hold_up is not None:
            group.start_soon(_run_sync, hold_up)
    assert wrong == []


async def _run_sync(function: Callable[[], None]) -> None:
    function()


def assert_every_attempt_served(bench: Bench, requests: int) -> None:
    stats = bench.master.unit_stats(1)
    counted = (stats.requests, stats.successes, stats.timeouts, stats.retries, stats.failures)
    assert counted == (requests, requests, 0, 0, 0)
    assert bench.slave.counters.server_message_count == requests
    assert bench.slave.counters.bus_communication_error_count == 0


def store() -> aiortu.MemoryStore:
    return aiortu.MemoryStore(holding_registers={0: VALUES})


@asynccontextmanager
async def on_streams(master_stream, slave_stream) -> AsyncIterator[Bench]:
    slave = aiortu.Slave(slave_stream, {1: store()}, frame_gap=0)
    async with slave, aiortu.Master(master_stream, frame_gap=0, timeout=5) as master:
        yield Bench(master, slave)


@asynccontextmanager
async def on_virtual_bus(**options: Any) -> AsyncIterator[Bench]:
    bus = VirtualBus(2, **options)
    async with on_streams(bus[0], bus[1]) as bench:
        yield bench
    assert bus[0].overrun_bytes == bus[1].overrun_bytes == 0


STREAMED = {"chunk_size": 256}
"""An unpaced bus whose endpoints do not push: the master's and the slave's links read
it from a task through ``receive()``, as any plain byte stream."""


@asynccontextmanager
async def on_virtual_pair() -> AsyncIterator[Bench]:
    a, b = virtual_pair()
    async with on_streams(a, b) as bench:
        yield bench


@asynccontextmanager
async def on_pty_bus() -> AsyncIterator[Bench]:
    async with PtyBus(2) as bus:
        slave = aiortu.serve(bus.paths[1], {1: store()}, parity="N", frame_gap=0)
        master = aiortu.open_master(bus.paths[0], parity="N", frame_gap=0, timeout=5)
        async with slave as served, master as opened:
            yield Bench(opened, served)


BENCHES: dict[str, Callable[[], AbstractAsyncContextManager[Bench]]] = {
    "VirtualBus": on_virtual_bus,
    "VirtualBus streamed": lambda: on_virtual_bus(**STREAMED),
    "virtual_pair": on_virtual_pair,
    "PtyBus": on_pty_bus,
}


@pytest.mark.parametrize("callers", [1, 10, 1000])
@pytest.mark.parametrize("line", list(BENCHES))
async def test_every_caller_is_served_once(line: str, callers: int) -> None:
    async with BENCHES[line]() as bench:
        await read_as_callers(bench, callers)
        assert_every_attempt_served(bench, callers * ROUNDS)


@pytest.mark.parametrize("options", [{}, STREAMED], ids=["pushed", "streamed"])
async def test_no_request_lost_when_the_first_one_meets_the_slaves_first_deadline(
    options: dict[str, Any],
) -> None:
    # A slave's receiver starts with a t3.5 deadline. When a thousand callers start, one
    # pass of the event loop runs all their first steps and can outlast that deadline
    # (here a step that blocks for it makes sure it does): the first request then arrives
    # in the loop pass that also ends the deadline, and the slave's read of the line was
    # cancelled after it had taken the request off the bus. It must keep it. (A pushing
    # bus has no such read; the streamed one is read as any byte stream is.)
    bus = VirtualBus(2, **options)
    async with aiortu.Master(bus[0], frame_gap=0, timeout=5) as master:
        await anyio.sleep(0.01)  # the master's line task is up and waiting for work
        async with aiortu.Slave(bus[1], {1: store()}, frame_gap=0) as slave:
            bench = Bench(master, slave)
            busy = 4 * slave.link.settings.t3_5
            await read_as_callers(bench, 1000, lambda: time.sleep(busy))
            assert_every_attempt_served(bench, 1000 * ROUNDS)


async def test_a_cancelled_receive_leaves_the_bytes_on_the_bus() -> None:
    a, b = virtual_pair()
    await a.send(b"request")
    with anyio.CancelScope() as scope:
        scope.cancel()
        await b.receive()
    assert b.pending == len(b"request")
    with anyio.fail_after(5):
        assert await b.receive() == b"request"


async def test_a_reader_cancelled_after_taking_bytes_keeps_them() -> None:
    # The reader takes the bytes out of the buffer, then yields once; the canceller runs
    # in that pass. The bytes already taken must still reach the reader.
    a, b = virtual_pair(chunk_size=256)
    await a.send(b"request")
    got: list[bytes] = []
    scope = anyio.CancelScope()

    async def reader() -> None:
        with scope:
            got.append(await b.receive())

    async def canceller() -> None:
        scope.cancel()

    with anyio.fail_after(5):
        async with anyio.create_task_group() as group:
            group.start_soon(reader)
            group.start_soon(canceller)
    assert got == [b"request"]
    assert b.pending == 0

"""The blocking API: the async master's operations, handles and broadcast, made from the one
definition, run from threads (several at once), from a thread whose own loop runs, and closed
from any thread."""

from __future__ import annotations

import asyncio
import inspect
import os
import random
import signal
import threading
import time
from collections.abc import Iterator

import pytest

import aiortu.blocking
from aiortu.blocking import BlockingBroadcastHandle, BlockingMaster, BlockingUnitHandle
from aiortu.errors import (
    ConnectionLost,
    ExceptionResponse,
    InvalidRequest,
    InvalidValue,
    PortNotFound,
    ResponseTimeout,
)
from aiortu.master import BroadcastHandle, Master, UnitHandle
from aiortu.slave import Block, MemoryStore
from aiortu.testing import VirtualBus

UNITS = (1, 2)


def _async_methods(cls: type) -> set[str]:
    return {
        name
        for name, member in inspect.getmembers(cls)
        if not name.startswith("_") and inspect.iscoroutinefunction(member)
    }


def _portal_threads() -> list[threading.Thread]:
    return [thread for thread in threading.enumerate() if "portal" in thread.name]


@pytest.fixture
def bench() -> Iterator[tuple[BlockingMaster, dict[int, MemoryStore]]]:
    """A blocking master and a blocking slave (units 1 and 2) on one in-memory bus."""
    bus = VirtualBus(2)
    stores = {
        unit: MemoryStore(
            coils=[Block(0, 64)], holding_registers=[Block(0, 200, [unit * 1000] * 200)]
        )
        for unit in UNITS
    }
    with (
        aiortu.blocking.start_slave(bus[1], stores, frame_gap=0),
        aiortu.blocking.start_master(bus[0], frame_gap=0, timeout=0.5) as master,
    ):
        yield master, stores
    assert _portal_threads() == []  # the loop's thread stopped with the last object


@pytest.mark.parametrize(
    ("blocking", "source"),
    [
        (BlockingMaster, Master),
        (BlockingUnitHandle, UnitHandle),
        (BlockingBroadcastHandle, BroadcastHandle),
    ],
)
def test_every_async_method_has_its_blocking_form(blocking: type, source: type) -> None:
    for name in _async_methods(source):
        method = getattr(blocking, name)
        original = getattr(source, name)
        assert not inspect.iscoroutinefunction(method), name
        assert method.__doc__ == original.__doc__, name
        assert inspect.signature(method) == inspect.signature(original), name
        assert method.__qualname__ == f"{blocking.__name__}.{name}"


def test_reads_writes_handles_and_broadcast(
    bench: tuple[BlockingMaster, dict[int, MemoryStore]],
) -> None:
    master, _ = bench
    assert master.read_holding_registers(1, 0, 3) == [1000, 1000, 1000]
    master.write_registers(2, 10, [1, 2, 3])
    assert master.read_holding_registers(2, 10, 3, timeout=0.5) == [1, 2, 3]
    handle = master.slave(2)
    assert (handle.master, handle.unit) == (master, 2)
    handle.write_float32(20, 21.5)
    assert handle.read_float32(20) == 21.5
    assert handle.read_reference("40011", 2) == [1, 2]
    master.broadcast.write_coils(0, [True, False, True])
    master.broadcast.write_register(address=30, value=9, priority=1)
    for unit in UNITS:
        assert master.read_coils(unit, 0, 3) == [True, False, True]
    assert master.read_holding_registers(1, 30, 1) == [9]
    assert master.unit_stats(0).requests == 2  # the broadcasts
    snapshot = master.statistics
    assert snapshot[1].requests == master.unit_stats(1).requests > 0
    master.read_coils(1, 0, 1)
    assert snapshot[1].requests == master.unit_stats(1).requests - 1  # a snapshot
    assert master.is_online(1)
    assert master.connected


def test_errors_are_the_async_apis(bench: tuple[BlockingMaster, dict[int, MemoryStore]]) -> None:
    master, _ = bench
    with pytest.raises(ExceptionResponse) as raised:
        master.read_holding_registers(1, 199, 2)
    assert raised.value.code == 2
    with pytest.raises(InvalidRequest, match=r"^count = 0 is outside"):
        master.slave(1).read_holding_registers(0, 0)
    with pytest.raises(ResponseTimeout):
        master.read_holding_registers(9, 0, 1, timeout=0.05)


def test_several_threads_at_once_on_one_master(
    bench: tuple[BlockingMaster, dict[int, MemoryStore]],
) -> None:
    master, _ = bench
    seed = random.randrange(2**32)
    failures: list[str] = []

    def caller(index: int) -> None:
        # Each thread owns ten registers of one unit and checks what it wrote.
        chance = random.Random(seed + index)
        unit = UNITS[index % 2]
        base = 100 + 10 * (index // 2)
        handle = master.slave(unit)
        try:
            for _ in range(25):
                values = [chance.randrange(0x10000) for _ in range(chance.randint(1, 10))]
                handle.write_registers(base, values)
                if handle.read_holding_registers(base, len(values)) != values:
                    failures.append(f"thread {index}: read back differs")
        except Exception as error:  # reported below with the seed
            failures.append(f"thread {index}: {error!r}")

    threads = [threading.Thread(target=caller, args=(index,)) for index in range(8)]
    for thread in threads:
        thread.start()
    for thread in threads:
        thread.join(timeout=60)
    assert failures == [], f"seed {seed}"
    assert master.unit_stats(1).requests + master.unit_stats(2).requests == 8 * 25 * 2
    assert master.unit_stats(1).failures == 0


def test_a_loop_running_in_the_calling_thread(
    bench: tuple[BlockingMaster, dict[int, MemoryStore]],
) -> None:
    master, _ = bench

    async def notebook_cell() -> list[int]:
        # As in Jupyter or `python -m asyncio`: a loop runs in this thread, and the code
        # calls the blocking API without awaiting.
        master.write_register(1, 5, 55)
        return master.read_holding_registers(1, 5, 1)

    assert asyncio.run(notebook_cell()) == [55]


def test_close_from_another_thread_ends_a_waiting_call() -> None:
    bus = VirtualBus(2)  # no slave: a read waits for its whole timeout
    master = aiortu.blocking.start_master(bus[0], frame_gap=0, timeout=30, retries=0)
    threading.Timer(0.2, master.close).start()
    start = time.monotonic()
    with pytest.raises(ConnectionLost, match="the master is closed"):
        master.read_holding_registers(1, 0, 1)
    assert time.monotonic() - start < 10
    assert master.closed
    with pytest.raises(ConnectionLost, match=r"^the master is closed$"):
        master.read_coils(1, 0, 1)
    master.close()  # again: nothing to do
    assert _portal_threads() == []


def test_the_loops_own_thread_is_told_to_await() -> None:
    bus = VirtualBus(2)
    with aiortu.blocking.start_master(bus[0], frame_gap=0) as master:

        def in_the_loop() -> None:
            master.read_coils(1, 0, 1)

        with pytest.raises(RuntimeError, match="cannot be used blocking from its own event loop"):
            master._running.call(in_the_loop)


def test_serve_and_open_master_over_tcp_and_a_pty_bus() -> None:
    store = MemoryStore(holding_registers=[Block(0, 10, list(range(10)))])
    with aiortu.blocking.serve("tcp://127.0.0.1:0", {1: store}) as server:
        port = server.value.port  # type: ignore[union-attr]
        with aiortu.blocking.open_master(f"tcp://127.0.0.1:{port}", timeout=2) as master:
            assert master.read_holding_registers(1, 0, 3) == [0, 1, 2]
    with aiortu.blocking.pty_bus(2) as bus:
        device, other = bus.value.paths
        with (
            aiortu.blocking.serve(other, {1: store}, baudrate=19200, parity="N", stopbits=2),
            aiortu.blocking.open_master(
                device, baudrate=19200, parity="N", stopbits=2, timeout=2
            ) as master,
        ):
            assert master.slave(1).read_holding_registers(7, 3) == [7, 8, 9]
    assert _portal_threads() == []


def test_ctrl_c_in_the_calling_thread_stops_the_call() -> None:
    bus = VirtualBus(2)  # no slave: a read waits for its whole timeout
    with aiortu.blocking.start_master(bus[0], frame_gap=0, retries=0) as master:

        def interrupted_read() -> None:
            # The signal is sent from inside pytest.raises: it cannot land outside it.
            threading.Timer(0.2, os.kill, (os.getpid(), signal.SIGINT)).start()
            master.read_holding_registers(1, 0, 1, timeout=30)

        start = time.monotonic()
        with pytest.raises(KeyboardInterrupt):
            interrupted_read()
        assert time.monotonic() - start < 20
    assert master.closed


def test_an_opening_error_is_raised_and_leaves_no_thread() -> None:
    with pytest.raises(PortNotFound):
        aiortu.blocking.open_master("/dev/ttyUSB-none-such", reconnect=False)
    with pytest.raises(InvalidValue, match=r"^timeout must be"):
        aiortu.blocking.start_master(VirtualBus(2)[0], timeout=-1)
    assert _portal_threads() == []

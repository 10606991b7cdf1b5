"""Benchmark of the in-memory test bench: a master and a slave on an unpaced VirtualBus.

Run from the repository root with aiortu and socat installed::

    python benchmarks/bench_inmemory.py [--quick] [--section NAME ...]

Sections (each a function ``section_*``; ``--section`` picks some):

(a) pair: one caller reads 10 holding registers in a loop from an aiortu ``Slave``
    (``frame_gap=0``). In memory: ``Master`` and ``Slave`` in this process on an unpaced
    :class:`~aiortu.testing.VirtualBus`; CPU is this process's ``process_time`` over the
    timed reads, master and slave together. Over a socat pty pair: the same master in
    this process, ``aiortu serve`` in a subprocess (``bench_servers.py aiortu``); CPU is
    this process's plus the server's (from /proc), socat's own shown apart. The two take
    turns round by round.
(b) callers: 1, 10, 100, 1000 and 10,000 callers on one master, in memory as in (a);
    each caller waits until all have started, then reads a share of the reads (at least
    3 each): CPU per read and reads/s over all of them (the callers' wake-ups included).
    Beside it, the same callers as bare tasks without a master (each read a loop future
    completed by a callback in turn): what waking that many tasks costs, and the rest.
    The sizes take turns round by round. Every run checks that every read was right,
    that the slave got one message per request and that nothing timed out or was retried.
    Then the memory per waiting caller: callers started against a slave that does not
    answer (all but one wait for their turn in the master's queue), ``tracemalloc``'s
    traced memory before and after, divided by the callers; and per caller after the
    first (the one caller's figure taken out), which leaves out the line's fixed cost.
(c) scale: 10,000 callers each read 3 times on an unpaced ``VirtualBus`` (pushing, and
    with ``chunk_size=256``, which the links read as a plain stream), on ``virtual_pair``
    and on a ``PtyBus`` (master, slave and relay in this process): the checks of (b),
    the wall time and the CPU per read.
"""

from __future__ import annotations

import argparse
import asyncio
import collections
import gc
import sys
import time
import tracemalloc
from collections.abc import AsyncIterator, Callable
from contextlib import AbstractAsyncContextManager, asynccontextmanager
from dataclasses import dataclass

import anyio

sys.path.insert(0, __file__.rsplit("/", 1)[0])
import benchlib

import aiortu
from aiortu.testing import PtyBus, VirtualBus, virtual_pair

VALUES = list(range(10))
PTY = {"baudrate": 19200, "parity": "N", "stopbits": 2}
"""The settings of bench_servers.py's slave (ptys keep no parity)."""
CALLERS = (1, 10, 100, 1000, 10_000)


def verdict(met: bool) -> str:
    return "met" if met else "MISSED"


@dataclass
class Run:
    """What one timed run measured."""

    reads: int
    wall: float
    cpu: float

    @property
    def rate(self) -> float:
        return self.reads / self.wall

    @property
    def cpu_per_read(self) -> float:
        return self.cpu / self.reads


def store() -> aiortu.MemoryStore:
    return aiortu.MemoryStore(holding_registers={0: VALUES})


@asynccontextmanager
async def in_memory(make: Callable[[], tuple[object, object]] = lambda: tuple(VirtualBus(2))):
    """A master and a slave (unit 1) in this process on the streams *make* returns."""
    master_end, slave_end = make()
    slave = aiortu.Slave(slave_end, {1: store()}, frame_gap=0)  # type: ignore[arg-type]
    master = aiortu.Master(master_end, frame_gap=0, timeout=5)  # type: ignore[arg-type]
    async with slave, master:
        yield master, slave


@asynccontextmanager
async def on_pty_bus() -> AsyncIterator[tuple[aiortu.Master, aiortu.Slave]]:
    async with PtyBus(2) as bus:
        slave = aiortu.serve(bus.paths[1], {1: store()}, frame_gap=0, **PTY)  # type: ignore[arg-type]
        master = aiortu.open_master(bus.paths[0], frame_gap=0, timeout=5, **PTY)  # type: ignore[arg-type]
        async with slave as served, master as opened:
            yield opened, served


async def callers_run(
    bench: AbstractAsyncContextManager[tuple[aiortu.Master, aiortu.Slave]],
    callers: int,
    each: int,
) -> Run:
    """*callers* tasks read *each* times once all have started; checks every outcome."""
    wrong = 0
    async with bench as (master, slave):
        await master.read_holding_registers(1, 0, 10)
        go = anyio.Event()

        async def caller() -> None:
            nonlocal wrong
            await go.wait()
            for _ in range(each):
                if await master.read_holding_registers(1, 0, 10) != VALUES:
                    wrong += 1

        async with anyio.create_task_group() as group:
            for _ in range(callers):
                group.start_soon(caller)
            await anyio.sleep(0.05 + callers * 20e-6)  # every caller waits for go
            wall, cpu = time.perf_counter(), time.process_time()
            go.set()
        wall, cpu = time.perf_counter() - wall, time.process_time() - cpu
        reads = callers * each
        stats = master.unit_stats(1)
        served = slave.counters.server_message_count - 1
        outcome = (wrong, stats.requests - 1, stats.timeouts, stats.retries, served)
        if outcome != (0, reads, 0, 0, reads):
            raise AssertionError(
                f"{callers} callers: wrong, requests, timeouts, retries, served = {outcome}"
            )
    return Run(reads, wall, cpu)


async def bare_callers_run(callers: int, each: int) -> Run:
    """*callers* bare tasks in the pattern of :func:`callers_run`, without a master: each
    "read" awaits a future of the loop that a loop callback completes, one at a time,
    handing on to the next queued future. What waking that many tasks in turn costs."""
    loop = asyncio.get_running_loop()
    queue: collections.deque[asyncio.Future[None]] = collections.deque()
    busy = False

    def finish(future: asyncio.Future[None]) -> None:
        nonlocal busy
        if queue:
            loop.call_soon(finish, queue.popleft())
        else:
            busy = False
        future.set_result(None)

    def read() -> asyncio.Future[None]:
        nonlocal busy
        future = loop.create_future()
        if busy:
            queue.append(future)
        else:
            busy = True
            loop.call_soon(finish, future)
        return future

    go = anyio.Event()

    async def caller() -> None:
        await go.wait()
        for _ in range(each):
            await read()

    async with anyio.create_task_group() as group:
        for _ in range(callers):
            group.start_soon(caller)
        await anyio.sleep(0.05 + callers * 20e-6)
        wall, cpu = time.perf_counter(), time.process_time()
        go.set()
    wall, cpu = time.perf_counter() - wall, time.process_time() - cpu
    return Run(callers * each, wall, cpu)


async def sequential_in_memory(reads: int) -> Run:
    async with in_memory() as (master, _):
        for _ in range(20):
            await master.read_holding_registers(1, 0, 10)
        wall, cpu = time.perf_counter(), time.process_time()
        for _ in range(reads):
            if await master.read_holding_registers(1, 0, 10) != VALUES:
                raise AssertionError("the in-memory pair read the wrong registers")
        wall, cpu = time.perf_counter() - wall, time.process_time() - cpu
    return Run(reads, wall, cpu)


async def sequential_over_pty(port: str, reads: int, server: int, socat: int) -> tuple[Run, float]:
    """Like :func:`sequential_in_memory` against the server process *server*; the CPU
    counts this process and the server; socat's CPU per read is returned apart."""
    async with aiortu.open_master(port, frame_gap=0, timeout=5, **PTY) as master:  # type: ignore[arg-type]
        for _ in range(20):
            await master.read_holding_registers(1, 0, 10)
        served, relayed = benchlib.cpu_seconds(server), benchlib.cpu_seconds(socat)
        wall, cpu = time.perf_counter(), time.process_time()
        for _ in range(reads):
            if await master.read_holding_registers(1, 0, 10) != VALUES:
                raise AssertionError("the pair over the pty read the wrong registers")
        wall, cpu = time.perf_counter() - wall, time.process_time() - cpu
        served = benchlib.cpu_seconds(server) - served
        relayed = benchlib.cpu_seconds(socat) - relayed
    return Run(reads, wall, cpu + served), relayed / reads


def section_pair(args: argparse.Namespace) -> list[str]:
    reads = 1000 if args.quick else 5000
    rounds = 2 if args.quick else 5
    memory: list[Run] = []
    pty: list[Run] = []
    socat: list[float] = []
    with benchlib.Children() as children:
        client_port, server_port = children.socat_pair()
        relay = children.processes[-1].pid
        server = children.server("aiortu", server_port, "--frame-gap", "0").pid
        for _ in range(rounds):
            memory.append(anyio.run(sequential_in_memory, reads))
            run, relayed = anyio.run(sequential_over_pty, client_port, reads, server, relay)
            pty.append(run)
            socat.append(relayed)
    rows = []
    for name, runs in (
        ("in memory, one process (VirtualBus)", memory),
        ("socat pty, two processes", pty),
    ):
        rates = [run.rate for run in runs]
        rows.append(
            [
                name,
                f"{benchlib.median(rates):,.0f}",
                f"{min(rates):,.0f}..{max(rates):,.0f}",
                f"{benchlib.median([run.cpu_per_read for run in runs]) * 1e6:.0f}",
            ]
        )
    rows[1][3] += f" (+ socat {benchlib.median(socat) * 1e6:.0f})"
    cpu = benchlib.median([run.cpu_per_read for run in memory]) * 1e6
    faster = benchlib.median([run.rate for run in memory]) / benchlib.median([r.rate for r in pty])
    return [
        f"(a) pair: one caller, 10 holding registers, master and slave with frame_gap=0; "
        f"{rounds} interleaved rounds of {reads} reads",
        "",
        benchlib.table(
            ["Line", "reads/s (median)", "min..max", "CPU us/read, master + slave"], rows
        ),
        "",
        f"Targets: <= 150 us CPU per read in memory: {verdict(cpu <= 150)} ({cpu:.0f} us); "
        f"more reads/s than over socat: {verdict(faster > 1)} ({faster:.2f}x).",
    ]


def memory_per_waiting_caller(callers: int) -> tuple[float, float]:
    """Bytes of traced memory per caller waiting on a master whose slave is silent, and
    per task of the same kind (anyio, in a task group) waiting on one shared Event."""

    async def traced(start: Callable[[anyio.abc.TaskGroup], None]) -> float:
        gc.collect()
        tracemalloc.start()
        before = tracemalloc.get_traced_memory()[0]
        async with anyio.create_task_group() as group:
            for _ in range(callers):
                start(group)
            await anyio.sleep(0.1 + callers * 50e-6)
            waiting = tracemalloc.get_traced_memory()[0] - before
            tracemalloc.stop()
            group.cancel_scope.cancel()
        return waiting / callers

    async def main() -> tuple[float, float]:
        bus = VirtualBus(2)  # nobody reads bus[1]: every read waits
        async with aiortu.Master(bus[0], frame_gap=0, timeout=60) as master:
            caller = await traced(
                lambda group: group.start_soon(master.read_holding_registers, 1, 0, 10)
            )
        event = anyio.Event()
        bare = await traced(lambda group: group.start_soon(event.wait))
        return caller, bare

    return anyio.run(main)


def section_callers(args: argparse.Namespace) -> list[str]:
    rounds = 1 if args.quick else 3
    total = 5000 if args.quick else 20_000
    runs: dict[int, list[Run]] = {callers: [] for callers in CALLERS}
    bare: dict[int, list[Run]] = {callers: [] for callers in CALLERS}
    for _ in range(rounds):
        for callers in CALLERS:
            each = max(3, total // callers)
            runs[callers].append(anyio.run(callers_run, in_memory(), callers, each))
            bare[callers].append(anyio.run(bare_callers_run, callers, each))
    memory = {callers: memory_per_waiting_caller(callers) for callers in CALLERS}
    return callers_report(rounds, runs, bare, memory)


def callers_report(
    rounds: int,
    runs: dict[int, list[Run]],
    bare: dict[int, list[Run]],
    memory: dict[int, tuple[float, float]],
) -> list[str]:
    """Section (b)'s table and verdicts."""
    # Each caller after the first: the line's fixed cost (its first request) left out.
    first = memory[1][0]
    extra = {n: (n * memory[n][0] - first) / (n - 1) for n in CALLERS if n > 1}
    cpus = {n: benchlib.median([run.cpu_per_read for run in rs]) * 1e6 for n, rs in runs.items()}
    bares = {n: benchlib.median([run.cpu_per_read for run in rs]) * 1e6 for n, rs in bare.items()}
    # The master's and the line's share: the tasks' own wake-ups taken out.
    beyond = {n: cpus[n] - bares[n] for n in CALLERS}
    rows = [
        [
            f"{callers:,}",
            f"{runs[callers][0].reads:,}",
            f"{benchlib.median([run.rate for run in runs[callers]]):,.0f}",
            f"{cpus[callers]:.1f}",
            spread_of([run.cpu_per_read * 1e6 for run in runs[callers]]),
            f"{bares[callers]:.1f}",
            f"{beyond[callers]:.1f}",
            f"{memory[callers][0] / 1024:.2f}",
            f"{extra[callers] / 1024:.2f}" if callers > 1 else "-",
            f"{memory[callers][1] / 1024:.2f}",
        ]
        for callers in CALLERS
    ]
    spread = max(cpus.values()) / min(cpus.values()) - 1
    worst = max(extra.values()) / 1024
    many = [n for n in CALLERS if n > 1]
    spread_many = max(cpus[n] for n in many) / min(cpus[n] for n in many) - 1
    spread_beyond = max(beyond.values()) / min(beyond.values()) - 1
    return [
        f"(b) callers: in memory (unpaced VirtualBus), 10 holding registers; {rounds} "
        "interleaved rounds; every read checked, no timeout, no retry, one slave message "
        "per request",
        "",
        benchlib.table(
            [
                "Callers",
                "reads per run",
                "reads/s (median)",
                "CPU us/read (median)",
                "min..max",
                "bare tasks: CPU us/read",
                "the rest: CPU us/read",
                "KiB per waiting caller",
                "KiB per caller after the first",
                "KiB per bare waiting task",
            ],
            rows,
        ),
        "",
        f"Targets: CPU per read within 20 % from 1 to 10,000 callers: {verdict(spread <= 0.2)} "
        f"(the dearest {spread:.0%} above the cheapest; {spread_many:.0%} from 10 to 10,000); "
        f"memory per waiting caller under 5 KiB: {verdict(worst < 5)} (at most {worst:.2f} KiB "
        "per caller after the first; the first carries the line's fixed cost of its first "
        "request). A bare waiting task is what the caller's own task costs without the "
        "master. Bare tasks: the same callers without a master, each read a future "
        "completed by a loop callback in turn (waking that many tasks one after the "
        "other); the rest is the master's, the slave's and the line's CPU per read, "
        f"within {spread_beyond:.0%} from 1 to 10,000 callers.",
    ]


def spread_of(values: list[float]) -> str:
    return f"{min(values):.1f}..{max(values):.1f}"


BENCHES: dict[
    str, Callable[[], AbstractAsyncContextManager[tuple[aiortu.Master, aiortu.Slave]]]
] = {
    "VirtualBus(2)": in_memory,
    "VirtualBus(2, chunk_size=256), read as a stream": lambda: in_memory(
        lambda: tuple(VirtualBus(2, chunk_size=256))
    ),
    "virtual_pair()": lambda: in_memory(virtual_pair),
    "PtyBus(2), one process": on_pty_bus,
}


def section_scale(args: argparse.Namespace) -> list[str]:
    callers = 1000 if args.quick else 10_000
    rows = []
    for name, bench in BENCHES.items():
        run = anyio.run(callers_run, bench(), callers, 3)
        rows.append(
            [
                name,
                f"{callers:,}",
                f"{run.reads:,}",
                f"{run.wall:.2f}",
                f"{run.rate:,.0f}",
                f"{run.cpu_per_read * 1e6:.0f}",
            ]
        )
    return [
        f"(c) scale: {callers:,} callers, 3 reads each; every read checked, no timeout, no "
        "retry, one slave message per request (the run stops at the first miss)",
        "",
        benchlib.table(["Line", "callers", "reads", "wall s", "reads/s", "CPU us/read"], rows),
    ]


SECTIONS = {"pair": section_pair, "callers": section_callers, "scale": section_scale}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--quick", action="store_true", help="fewer rounds and reads")
    benchlib.add_section_argument(parser, SECTIONS)
    benchlib.run_sections(parser.parse_args(), SECTIONS)


if __name__ == "__main__":
    main()

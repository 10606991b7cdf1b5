"""Benchmark of the async master: against pymodbus over a pty pair, and on paced virtual lines.

Run from the repository root with aiortu, pymodbus and socat installed::

    python benchmarks/bench_master.py [--quick] [--section NAME ...]

Sections (each a function ``section_*``; ``--section`` picks some):

(a) pymodbus: over a socat pty pair, against pymodbus's RTU server in a subprocess, the
    client reads 10 holding registers in a loop: aiortu's ``Master`` with ``frame_gap=0``
    and with the spec's t3.5, and pymodbus's ``AsyncModbusSerialClient`` and
    ``ModbusSerialClient``. Each round opens the client, warms up, times *requests*
    reads, and closes it; the contenders take turns round by round. Requests/s is wall
    time; client CPU is this process's ``process_time`` over the timed reads (the server
    runs in its own process and is not counted).
(b) paced: a paced :class:`~aiortu.testing.VirtualBus` at 9600, 19200 and 115200 baud
    (8E1) carrying an aiortu ``Slave`` (its default frame gap t3.5) and an aiortu
    ``Master`` (t3.5) in this process; the master reads 10 holding registers back to
    back. Transactions/s as a share of ``LineSettings.transaction_rate(8, 25)``, the
    wire limit (both frames at the character rate plus two t3.5), and the shortest gap
    between bursts in ``bus.trace``.
(c) units: 247 units served by one ``Slave`` (one shared store) on one paced 19200 line;
    an ``aiortu.Poller`` reads 10 registers from each unit per cycle, cycles back to back.
    The all-alive cycle against 247 x the wire-limited transaction time; then with 50
    units not served (master timeout 0.2 s), the cycle times from the second cycle on
    against the all-alive one, for the master's and poller's default health settings and
    for tuned ones.
(d) lines: 16 paced 19200 lines (``PtyBus`` + aiortu slave, in a subprocess) and 16
    masters in this process, each polling 247 units in a loop; this process's CPU as a
    share of one core, and per transaction.
"""

from __future__ import annotations

import argparse
import asyncio
import contextlib
import itertools
import statistics
import sys
import time
from collections.abc import Callable
from typing import Any

import anyio

sys.path.insert(0, __file__.rsplit("/", 1)[0])
import benchlib

import aiortu
from aiortu.core.pdu import ReadHoldingRegistersRequest, ReadHoldingRegistersResponse
from aiortu.core.rtu import encode_frame
from aiortu.slave._store import Block
from aiortu.testing import VirtualBus

EXPECTED = list(range(10))
REQUEST = encode_frame(1, ReadHoldingRegistersRequest(0, 10).encode())
REPLY = encode_frame(1, ReadHoldingRegistersResponse(tuple(EXPECTED)).encode())
BARE = "reference: bare asyncio client, no Modbus logic"
BLOCKING = "reference: blocking read/write, no Modbus logic"
REQUEST_LENGTH, REPLY_LENGTH = 8, 25
PTY = {"baudrate": 19200, "parity": "N", "stopbits": 2}
"""Ptys keep no parity here: the socat sections run at 19200 8N2 (only the timing uses it)."""


CHANGING_OURS = "aiortu Master, frame_gap=0, registers changing on every read"
CHANGING_THEIRS = "pymodbus AsyncModbusSerialClient, registers changing on every read"


def quiet_pymodbus() -> None:
    import logging
    import warnings

    warnings.filterwarnings("ignore")
    logging.getLogger("pymodbus").setLevel(logging.CRITICAL)


# -- (a) against pymodbus over a socat pty pair ---------------------------------------------


def counting(values: list[int]) -> bool:
    """Whether *values* are what the changing server sends: n, n + 1, ... (mod 65536)."""
    return len(values) == 10 and all(
        value == (values[0] + offset) & 0xFFFF for offset, value in enumerate(values)
    )


def fixed(values: list[int]) -> bool:
    """Whether *values* are registers 0..9 of the server with fixed values."""
    return values == EXPECTED


async def run_aiortu(
    port: str, requests: int, frame_gap: float | None, check: Callable[[list[int]], bool] = fixed
) -> tuple[float, float]:
    async with aiortu.open_master(port, frame_gap=frame_gap, timeout=1.0, **PTY) as master:
        for _ in range(20):
            await master.read_holding_registers(1, 0, 10)
        wall, cpu = time.perf_counter(), time.process_time()
        for _ in range(requests):
            if not check(await master.read_holding_registers(1, 0, 10)):
                raise AssertionError("aiortu read the wrong registers")
        wall, cpu = time.perf_counter() - wall, time.process_time() - cpu
    return requests / wall, cpu / requests


async def run_pymodbus_async(
    port: str, requests: int, check: Callable[[list[int]], bool] = fixed
) -> tuple[float, float]:
    from pymodbus.client import AsyncModbusSerialClient

    client = AsyncModbusSerialClient(port, timeout=1.0, retries=0, **PTY)
    await client.connect()
    try:
        for _ in range(20):
            await client.read_holding_registers(0, count=10, device_id=1)
        wall, cpu = time.perf_counter(), time.process_time()
        for _ in range(requests):
            reply = await client.read_holding_registers(0, count=10, device_id=1)
            if not check(reply.registers):
                raise AssertionError("pymodbus read the wrong registers")
        wall, cpu = time.perf_counter() - wall, time.process_time() - cpu
    finally:
        client.close()
    return requests / wall, cpu / requests


def run_pymodbus_sync(port: str, requests: int) -> tuple[float, float]:
    from pymodbus.client import ModbusSerialClient

    client = ModbusSerialClient(port, timeout=1.0, retries=0, **PTY)
    client.connect()
    try:
        for _ in range(20):
            client.read_holding_registers(0, count=10, device_id=1)
        wall, cpu = time.perf_counter(), time.process_time()
        for _ in range(requests):
            reply = client.read_holding_registers(0, count=10, device_id=1)
            if reply.registers != EXPECTED:
                raise AssertionError("pymodbus read the wrong registers")
        wall, cpu = time.perf_counter() - wall, time.process_time() - cpu
    finally:
        client.close()
    return requests / wall, cpu / requests


def section_pymodbus(args: argparse.Namespace) -> list[str]:
    quiet_pymodbus()
    requests = 100 if args.quick else 1000
    rounds = 2 if args.quick else 9
    t35 = aiortu.LineSettings(**PTY).t3_5  # type: ignore[arg-type]
    # Each contender runs on the port of the server with fixed registers, or (CHANGING)
    # on that of the server whose registers change on every read.
    contenders: dict[str, Callable[[str], tuple[float, float]]] = {
        "aiortu Master, frame_gap=0": lambda p: asyncio.run(run_aiortu(p, requests, 0)),
        "pymodbus AsyncModbusSerialClient": lambda p: asyncio.run(run_pymodbus_async(p, requests)),
        BARE: lambda p: asyncio.run(benchlib.bare_asyncio_reads(p, REQUEST, REPLY, requests)),
        BLOCKING: lambda p: benchlib.blocking_reads(p, REQUEST, REPLY, requests),
        "pymodbus ModbusSerialClient (sync)": lambda p: run_pymodbus_sync(p, requests // 4),
        f"aiortu Master, frame_gap=t3.5 ({t35 * 1e3:.2f} ms)": lambda p: asyncio.run(
            run_aiortu(p, requests // 4, None)
        ),
        CHANGING_OURS: lambda p: asyncio.run(run_aiortu(p, requests, 0, counting)),
        CHANGING_THEIRS: lambda p: asyncio.run(run_pymodbus_async(p, requests, counting)),
    }
    results: dict[str, list[tuple[float, float]]] = {name: [] for name in contenders}
    with benchlib.Children() as children:
        client_port, server_port = children.socat_pair()
        children.server("pymodbus", server_port)
        changing_client_port, changing_server_port = children.socat_pair()
        children.server("pymodbus", changing_server_port, "--changing")
        for _ in range(rounds):
            for name, run in contenders.items():
                changing = name in (CHANGING_OURS, CHANGING_THEIRS)
                results[name].append(run(changing_client_port if changing else client_port))
    rates = {name: benchlib.median([r for r, _ in rs]) for name, rs in results.items()}
    cpus = {name: benchlib.median([c for _, c in rs]) for name, rs in results.items()}
    reference = "pymodbus AsyncModbusSerialClient"
    rows = []
    for name in contenders:
        spread = results[name]
        rows.append(
            [
                name,
                f"{rates[name]:,.0f}",
                f"{min(r for r, _ in spread):,.0f}..{max(r for r, _ in spread):,.0f}",
                f"{rates[name] / rates[reference]:.2f}x",
                f"{cpus[name] * 1e6:.0f}",
                f"{cpus[name] / cpus[reference]:.2f}x",
            ]
        )
    ours = "aiortu Master, frame_gap=0"
    speed = rates[ours] / rates[reference]
    cpu = cpus[ours] / cpus[reference]
    changing_cpu = cpus[CHANGING_OURS] / cpus[CHANGING_THEIRS]
    bare = rates[BARE] / rates[reference]
    blocking = rates[BLOCKING] / rates[reference]
    return [
        f"(a) pymodbus: 10 holding registers over a socat pty pair from pymodbus's RTU server; "
        f"{rounds} interleaved rounds of {requests} reads ({requests // 4} for pymodbus's "
        "sync client and aiortu at t3.5); the last two rows read from a second pymodbus "
        "server whose registers change on every read",
        "",
        benchlib.table(
            [
                "Client",
                "requests/s (median)",
                "min..max",
                "vs pymodbus async",
                "client CPU us/request",
                "CPU vs pymodbus async",
            ],
            rows,
        ),
        "",
        f"Targets: >= 1.5x pymodbus's requests/s: {verdict(speed >= 1.5)} ({speed:.2f}x); "
        f"<= 0.5x its CPU per request: {verdict(cpu <= 0.5)} ({cpu:.2f}x; with registers "
        f"that change on every read, {changing_cpu:.2f}x pymodbus's CPU on the same server). "
        f"The references with no Modbus logic reach {bare:.2f}x (asyncio) and "
        f"{blocking:.2f}x (blocking calls) pymodbus's requests/s against the same server.",
    ]


def verdict(met: bool) -> str:
    return "met" if met else "MISSED"


# -- (b) paced virtual lines ------------------------------------------------------------------


def gaps(bus: VirtualBus) -> tuple[float, float, float]:
    """The shortest gap between bursts in the trace, and the mean gaps before the slave's
    replies and before the master's requests (seconds)."""
    entries = list(bus.trace)
    pairs = [(b.start - a.end, b.sender) for a, b in itertools.pairwise(entries)]
    before_reply = [gap for gap, sender in pairs if sender == 1]
    before_request = [gap for gap, sender in pairs if sender == 0]
    return (
        min(gap for gap, _ in pairs),
        statistics.fmean(before_reply),
        statistics.fmean(before_request),
    )


async def paced_run(baudrate: int, seconds: float) -> tuple[float, tuple[float, float, float]]:
    """Return transactions/s and :func:`gaps` for *seconds* of back-to-back reads."""
    settings = aiortu.LineSettings(baudrate)
    bus = VirtualBus(2, settings=settings, trace_size=100_000)
    store = aiortu.MemoryStore(holding_registers=[Block(0, 100, range(100))])
    async with aiortu.Slave(bus[1], {1: store}, settings), aiortu.Master(bus[0], settings) as m:
        for _ in range(3):
            await m.read_holding_registers(1, 0, 10)
        bus.trace.clear()
        done = 0
        start = time.perf_counter()
        with anyio.move_on_after(seconds):
            while True:
                if await m.read_holding_registers(1, 0, 10) != EXPECTED:
                    raise AssertionError("wrong registers")
                done += 1
        elapsed = time.perf_counter() - start
        found = gaps(bus)
    return done / elapsed, found


def section_paced(args: argparse.Namespace) -> list[str]:
    seconds = 0.5 if args.quick else 3.0
    rounds = 2 if args.quick else 7
    targets = {9600: 0.95, 19200: 0.95, 115200: 0.85}
    rates: dict[int, list[float]] = {b: [] for b in targets}
    found: dict[int, list[tuple[float, float, float]]] = {b: [] for b in targets}
    for _ in range(rounds):
        for baudrate in targets:
            rate, gap = anyio.run(paced_run, baudrate, seconds)
            rates[baudrate].append(rate)
            found[baudrate].append(gap)
    rows = []
    notes = []
    for baudrate, target in targets.items():
        settings = aiortu.LineSettings(baudrate)
        limit = settings.transaction_rate(REQUEST_LENGTH, REPLY_LENGTH)
        rate = statistics.median(rates[baudrate])
        gap = min(g[0] for g in found[baudrate])
        before_reply = statistics.median(g[1] for g in found[baudrate])
        before_request = statistics.median(g[2] for g in found[baudrate])
        share = rate / limit
        rows.append(
            [
                f"{baudrate} 8E1",
                f"{limit:.1f}",
                f"{rate:.1f}",
                f"{min(rates[baudrate]) / limit:.1%}..{max(rates[baudrate]) / limit:.1%}",
                f"{share:.1%}",
                f"{target:.0%}",
                f"{settings.t3_5 * 1e3:.3f}",
                f"{gap * 1e3:.3f}",
                f"{before_reply * 1e3:.3f} / {before_request * 1e3:.3f}",
            ]
        )
        notes.append(
            f"{baudrate}: share {verdict(share >= target)}, gap >= t3.5 "
            f"{verdict(gap >= settings.t3_5 - 1e-9)}"
        )
    return [
        f"(b) paced: aiortu Master + Slave on a paced VirtualBus, 10-register reads back to back; "
        f"{rounds} interleaved rounds of {seconds:g} s per baud rate",
        "",
        benchlib.table(
            [
                "Line",
                "wire limit tx/s",
                "tx/s (median)",
                "share min..max",
                "share of wire limit",
                "target",
                "t3.5 ms",
                "shortest gap ms",
                "mean gap ms before reply / request",
            ],
            rows,
        ),
        "",
        "Targets: " + "; ".join(notes) + ".",
    ]


# -- (c) 247 units on one paced line ---------------------------------------------------------


async def poll_cycles(
    units: int,
    dead: int,
    cycles: int,
    master_options: dict[str, Any],
    poller_options: dict[str, Any],
) -> list[float]:
    """Cycle times of a poller reading 10 registers from each of *units* units, the last
    *dead* of them not served."""
    settings = aiortu.LineSettings(19200)
    bus = VirtualBus(2, settings=settings)
    store = aiortu.MemoryStore(holding_registers=[Block(0, 100, range(100))])
    served = dict.fromkeys(range(1, units - dead + 1), store)
    # Two points 9 registers apart: the poller merges them into one 10-register read.
    points = [
        aiortu.Point(f"u{unit}.{address}", unit, "holding_registers", address)
        for unit in range(1, units + 1)
        for address in (0, 9)
    ]
    async with (
        aiortu.Slave(bus[1], served, settings),
        aiortu.Master(bus[0], settings, **master_options) as master,
    ):
        poller = aiortu.Poller(master, points, interval=1e-3, **poller_options)
        durations: list[float] = []
        poller.on_cycle(lambda report: durations.append(report.duration))
        await poller.run(cycles=cycles)
    return durations


def section_units(args: argparse.Namespace) -> list[str]:
    units = 40 if args.quick else 247
    dead = 8 if args.quick else 50
    alive_cycles = 2 if args.quick else 3
    dead_cycles = 2 if args.quick else 3
    settings = aiortu.LineSettings(19200)
    wire = units * settings.transaction_time(REQUEST_LENGTH, REPLY_LENGTH)
    configs: list[tuple[str, dict[str, Any], dict[str, Any]]] = [
        ("defaults (retries 2, offline after 3, probe every 5 s)", {"timeout": 0.2}, {}),
        (
            "retries 0, offline after 1, probe every 5 s",
            {"timeout": 0.2, "retries": 0, "offline_after": 1},
            {},
        ),
        (
            "retries 0, offline after 1, probe every 60 s",
            {"timeout": 0.2, "retries": 0, "offline_after": 1},
            {"offline_probe_interval": 60.0},
        ),
    ]
    alive: list[float] = []
    dead_runs: list[list[float]] = []
    # A B A C A D A: the all-alive cycle is measured between the runs with dead units.
    alive += anyio.run(poll_cycles, units, 0, alive_cycles, {"timeout": 0.2}, {})
    for _, master_options, poller_options in configs:
        dead_runs.append(
            anyio.run(poll_cycles, units, dead, dead_cycles, master_options, poller_options)
        )
        alive += anyio.run(poll_cycles, units, 0, alive_cycles, {"timeout": 0.2}, {})
    alive_cycle = statistics.median(alive)
    share = wire / alive_cycle
    rows = [
        [
            f"all {units} alive",
            f"{wire:.3f}",
            f"{alive_cycle:.3f} (min {min(alive):.3f}, max {max(alive):.3f}, n={len(alive)})",
            f"{share:.1%}",
            "-",
        ]
    ]
    later_ratios = []
    for (name, _, _), durations in zip(configs, dead_runs, strict=True):
        later = max(durations[1:])
        later_ratios.append(later / alive_cycle)
        rows.append(
            [
                f"{dead} dead, {name}",
                f"{wire:.3f}",
                ", ".join(f"{d:.3f}" for d in durations),
                "-",
                f"{later / alive_cycle:.2f}x",
            ]
        )
    return [
        f"(c) units: {units} units on one paced 19200 8E1 line, one 10-register read per unit "
        f"per cycle (aiortu.Poller), master timeout 0.2 s",
        "",
        benchlib.table(
            [
                "Case",
                "wire limit s/cycle",
                "cycle times s",
                "share of wire limit",
                "longest cycle from the 2nd on / all-alive",
            ],
            rows,
        ),
        "",
        f"Targets: all-alive cycle >= 90% of the wire limit: {verdict(share >= 0.9)} "
        f"({share:.1%}); with {dead} dead, cycles from the second on <= 1.1x all-alive: "
        + ", ".join(
            f"{name.split(' (')[0]}: {verdict(r <= 1.1)} ({r:.2f}x)"
            for (name, _, _), r in zip(configs, later_ratios, strict=True)
        )
        + ".",
    ]


# -- (d) 16 paced lines in one process ---------------------------------------------------------


async def many_lines(paths: list[str], units: int, seconds: float) -> tuple[float, float, int]:
    """Poll *units* units on every line for *seconds*; return (wall, CPU, transactions)."""
    counts = [0] * len(paths)

    async def poll(index: int, master: aiortu.Master) -> None:
        while True:
            for unit in range(1, units + 1):
                await master.read_holding_registers(unit, 0, 10)
                counts[index] += 1

    async with contextlib.AsyncExitStack() as stack:
        masters = [
            await stack.enter_async_context(aiortu.open_master(path, timeout=1.0, **PTY))
            for path in paths
        ]
        async with anyio.create_task_group() as tasks:
            for index, master in enumerate(masters):
                tasks.start_soon(poll, index, master)
            await anyio.sleep(1.0)  # warm up
            before = sum(counts)
            wall, cpu = time.perf_counter(), time.process_time()
            await anyio.sleep(seconds)
            wall, cpu = time.perf_counter() - wall, time.process_time() - cpu
            done = sum(counts) - before
            tasks.cancel_scope.cancel()
    return wall, cpu, done


def section_lines(args: argparse.Namespace) -> list[str]:
    lines = 4 if args.quick else 16
    seconds = 2.0 if args.quick else 10.0
    rounds = 1 if args.quick else 3
    units = 247
    settings = aiortu.LineSettings(**PTY)  # type: ignore[arg-type]
    limit = settings.transaction_rate(REQUEST_LENGTH, REPLY_LENGTH)
    rows = []
    shares = []
    for latency in (0.0, 0.004):
        row, share = lines_run(lines, seconds, rounds, units, latency, limit)
        rows.append(row)
        shares.append(share)
    return [
        f"(d) lines: {lines} paced 19200 8N2 pty lines (PtyBus + aiortu slave, in a subprocess), "
        f"{lines} masters in this process each reading 10 registers from units 1..{units} in a "
        f"loop; {rounds} runs of {seconds:g} s per delivery",
        "",
        benchlib.table(
            [
                "Delivery to the master",
                "transactions/s (all lines)",
                "master process CPU (of one core)",
                "master CPU us/transaction",
                "master CPU at the full wire rate",
                "slave process CPU",
            ],
            rows,
        ),
        "",
        "Target: the master's CPU below 50% of one core at the full wire rate: "
        + ", ".join(
            f"{name}: {verdict(share < 0.5)} ({share:.1%})"
            for name, share in zip(("byte by byte", "4 ms chunks"), shares, strict=True)
        )
        + ".",
    ]


def lines_run(
    lines: int, seconds: float, rounds: int, units: int, latency: float, limit: float
) -> tuple[list[str], float]:
    samples = []
    with benchlib.Children() as children:
        server = children.start(
            [sys.executable, benchlib.SERVERS, "paced-lines", "--lines", str(lines),
             "--units", str(units), "--latency", str(latency)],
            stdout=benchlib.subprocess.PIPE,
            stdin=benchlib.subprocess.DEVNULL,
        )  # fmt: skip
        assert server.stdout is not None
        paths = server.stdout.readline().decode().split()
        if server.stdout.readline().decode().strip() != "ready" or len(paths) != lines:
            raise RuntimeError("the paced lines did not start")
        for _ in range(rounds):
            before = benchlib.cpu_seconds(server.pid)
            wall, cpu, done = anyio.run(many_lines, paths, units, seconds)
            slave_cpu = benchlib.cpu_seconds(server.pid) - before
            samples.append((wall, cpu, done, slave_cpu))
    share = statistics.median(s[1] / s[0] for s in samples)
    per_tx = statistics.median(s[1] / s[2] for s in samples)
    rate = statistics.median(s[2] / s[0] for s in samples)
    slave_share = statistics.median(s[3] / s[0] for s in samples)
    at_wire = per_tx * lines * limit
    name = "byte by byte" if latency == 0 else f"chunks, {latency * 1e3:g} ms adapter latency"
    row = [
        name,
        f"{rate:,.0f} ({rate / lines / limit:.0%} of {lines} x {limit:.1f})",
        f"{share:.1%}",
        f"{per_tx * 1e6:.0f}",
        f"{at_wire:.1%}",
        f"{slave_share:.1%}",
    ]
    return row, at_wire


SECTIONS: dict[str, Callable[[argparse.Namespace], list[str]]] = {
    "pymodbus": section_pymodbus,
    "paced": section_paced,
    "units": section_units,
    "lines": section_lines,
}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--quick", action="store_true", help="a short smoke run")
    benchlib.add_section_argument(parser, SECTIONS)
    benchlib.run_sections(parser.parse_args(), SECTIONS)


if __name__ == "__main__":
    main()

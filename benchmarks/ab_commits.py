"""Interleaved A/B of two source trees: the master's and the slave's CPU per read.

Run from the repository root with pymodbus and socat installed::

    python benchmarks/ab_commits.py BEFORE AFTER [--rounds 8] [--requests 3000]
        [--part master|slave|calls ...]

BEFORE and AFTER are checkouts of the repository (for an older commit,
``git archive COMMIT | tar -x -C DIR``); each runs with ``PYTHONPATH=TREE/src``, and its
slave is its own ``TREE/benchmarks/bench_servers.py``. Every timed run is a fresh
process, and the contenders take turns round by round, the order rotated each round so
that none always runs first.

master: one socat pty pair at 19200 8N2 and one pymodbus RTU server; each round, a fresh
    process per contender reads 10 holding registers *requests* times (after 20 reads of
    warm-up) and reports its own ``process_time`` per read: aiortu's ``Master``
    (``frame_gap=0``) of BEFORE and of AFTER, pymodbus's ``AsyncModbusSerialClient`` and
    the bare asyncio client with no Modbus logic (``benchlib.bare_asyncio_reads``).
slave: each round, a fresh slave process per contender on a socat pty pair of its own
    (aiortu's of BEFORE and of AFTER with ``frame_gap=0``, pymodbus's server), read by
    pymodbus's ``AsyncModbusSerialClient`` in this process; the slave's CPU per request
    is read from /proc around the timed reads (in clock ticks of 10 ms: use 6000 reads or
    more per round).
calls: the Python function calls (and coroutine resumptions) of one read of each tree's
    master, counted with ``sys.setprofile`` over up to 1000 reads in one process each:
    a figure the load of the machine does not move.

Prints the machine, the commands, the load average before and after, and a table per
part: medians, min..max, and the ratios to AFTER and to pymodbus.
"""

from __future__ import annotations

import argparse
import asyncio
import os
import subprocess
import sys
import time
from collections.abc import Callable

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import benchlib

PTY = {"baudrate": 19200, "parity": "N", "stopbits": 2}
EXPECTED = list(range(10))
PYMODBUS = "pymodbus AsyncModbusSerialClient"
BARE = "reference: bare asyncio client, no Modbus logic"
PYMODBUS_SERVER = "pymodbus server"


def load() -> str:
    with open("/proc/loadavg", encoding="ascii") as loadavg:
        return " ".join(loadavg.read().split()[:3])


def commit(tree: str) -> str:
    argv = ["git", "-C", tree, "rev-parse", "--short", "HEAD"]
    found = subprocess.run(argv, check=False, capture_output=True, text=True)
    return found.stdout.strip() if found.returncode == 0 else "(not a git checkout)"


# -- the child processes of the master part ---------------------------------------------------


async def child_aiortu(port: str, requests: int, count_calls: bool = False) -> tuple[str, float]:
    """Time *requests* reads; return where aiortu came from and the CPU seconds per read
    (with *count_calls*, the Python function calls and resumptions per read instead)."""
    import aiortu

    calls = 0

    def count(frame: object, event: str, arg: object) -> None:
        nonlocal calls
        calls += event == "call"

    async with aiortu.open_master(port, frame_gap=0, timeout=1.0, **PTY) as master:  # type: ignore[arg-type]
        for _ in range(20):
            await master.read_holding_registers(1, 0, 10)
        cpu = time.process_time()
        if count_calls:
            sys.setprofile(count)
        for _ in range(requests):
            if await master.read_holding_registers(1, 0, 10) != EXPECTED:
                raise AssertionError("aiortu read the wrong registers")
        sys.setprofile(None)
        cost = calls if count_calls else time.process_time() - cpu
        return aiortu.__file__, cost / requests


async def pymodbus_reads(port: str, requests: int) -> float:
    """Read *requests* times with pymodbus's async client; return this process's CPU s."""
    from pymodbus.client import AsyncModbusSerialClient

    client = AsyncModbusSerialClient(port, timeout=1.0, retries=0, **PTY)  # type: ignore[arg-type]
    await client.connect()
    try:
        for _ in range(20):
            await client.read_holding_registers(0, count=10, device_id=1)
        cpu = time.process_time()
        for _ in range(requests):
            reply = await client.read_holding_registers(0, count=10, device_id=1)
            if reply.registers != EXPECTED:
                raise AssertionError("pymodbus read the wrong registers")
        return time.process_time() - cpu
    finally:
        client.close()


async def child_bare(port: str, requests: int) -> float:
    from aiortu.core.pdu import ReadHoldingRegistersRequest, ReadHoldingRegistersResponse
    from aiortu.core.rtu import encode_frame

    request = encode_frame(1, ReadHoldingRegistersRequest(0, 10).encode())
    reply = encode_frame(1, ReadHoldingRegistersResponse(tuple(EXPECTED)).encode())
    _, cpu = await benchlib.bare_asyncio_reads(port, request, reply, requests)
    return cpu


def child(kind: str, port: str, requests: int) -> None:
    """Run one timed client in this (fresh) process; print its CPU seconds per read."""
    import logging
    import warnings

    warnings.filterwarnings("ignore")
    logging.getLogger("pymodbus").setLevel(logging.CRITICAL)
    if kind in ("aiortu", "calls"):
        path, cpu = asyncio.run(child_aiortu(port, requests, kind == "calls"))
        print(path)
    elif kind == "pymodbus":
        cpu = asyncio.run(pymodbus_reads(port, requests)) / requests
    else:
        cpu = asyncio.run(child_bare(port, requests))
    print(cpu)


def run_child(tree: str, kind: str, port: str, requests: int) -> float:
    env = {**os.environ, "PYTHONPATH": os.path.join(tree, "src")}
    argv = [sys.executable, os.path.abspath(__file__), "--child", kind, port, str(requests)]
    done = subprocess.run(argv, env=env, capture_output=True, text=True, check=False)
    if done.returncode != 0:
        raise RuntimeError(f"the {kind} client of {tree} failed:\n{done.stderr}")
    lines = done.stdout.split()
    if kind in ("aiortu", "calls") and not lines[0].startswith(os.path.realpath(tree)):
        raise RuntimeError(f"the client of {tree} imported aiortu from {lines[0]}")
    return float(lines[-1])


# -- the parts --------------------------------------------------------------------------------


def rotated(names: list[str], turn: int) -> list[str]:
    turn %= len(names)
    return names[turn:] + names[:turn]


def part_master(before: str, after: str, rounds: int, requests: int) -> dict[str, list[float]]:
    contenders: dict[str, tuple[str, str]] = {
        "before": (before, "aiortu"),
        "after": (after, "aiortu"),
        PYMODBUS: (after, "pymodbus"),
        BARE: (after, "bare"),
    }
    results: dict[str, list[float]] = {name: [] for name in contenders}
    with benchlib.Children() as children:
        client_port, server_port = children.socat_pair()
        children.server("pymodbus", server_port)
        for turn in range(rounds):
            for name in rotated(list(contenders), turn):
                tree, kind = contenders[name]
                results[name].append(run_child(tree, kind, client_port, requests))
    return results


def part_calls(before: str, after: str, rounds: int, requests: int) -> dict[str, list[float]]:
    """Python calls per read of each tree's master (one run each: the count is the same
    whatever the load)."""
    results: dict[str, list[float]] = {}
    with benchlib.Children() as children:
        client_port, server_port = children.socat_pair()
        children.server("pymodbus", server_port)
        for name, tree in (("before", before), ("after", after)):
            results[name] = [run_child(tree, "calls", client_port, min(requests, 1000))]
    return results


def slave_round(children: benchlib.Children, argv: list[str], tree: str, requests: int) -> float:
    """Start a fresh slave with *argv*, read from it; return its CPU seconds per request."""
    client_port, server_port = children.socat_pair()
    env = {**os.environ, "PYTHONPATH": os.path.join(tree, "src")}
    slave = children.start(
        # The script, its mode, the port, then the options (its port is optional).
        [sys.executable, *argv[:2], server_port, *argv[2:]],
        stdout=subprocess.PIPE,
        stdin=subprocess.DEVNULL,
        env=env,
    )
    assert slave.stdout is not None
    if slave.stdout.readline().decode().strip() != "ready":
        raise RuntimeError(f"the slave {argv} did not start")
    before = benchlib.cpu_seconds(slave.pid)
    asyncio.run(pymodbus_reads(client_port, requests))
    cpu = benchlib.cpu_seconds(slave.pid) - before
    children.stop_all()
    return cpu / requests


def part_slave(before: str, after: str, rounds: int, requests: int) -> dict[str, list[float]]:
    def servers(tree: str, *mode: str) -> tuple[str, list[str]]:
        return tree, [os.path.join(tree, "benchmarks", "bench_servers.py"), *mode]

    contenders = {
        "before": servers(before, "aiortu", "--frame-gap", "0"),
        "after": servers(after, "aiortu", "--frame-gap", "0"),
        PYMODBUS_SERVER: servers(after, "pymodbus"),
    }
    results: dict[str, list[float]] = {name: [] for name in contenders}
    for turn in range(rounds):
        for name in rotated(list(contenders), turn):
            tree, argv = contenders[name]
            with benchlib.Children() as children:
                results[name].append(slave_round(children, argv, tree, requests))
    return results


def report(title: str, results: dict[str, list[float]], reference: str, unit: str) -> list[str]:
    cpu = {name: benchlib.median(values) for name, values in results.items()}
    scale = 1e6 if unit.startswith("CPU") else 1.0
    rows = [
        [
            name,
            f"{cpu[name] * scale:.1f}",
            f"{min(values) * scale:.1f}..{max(values) * scale:.1f}",
            f"{cpu[name] / cpu['after']:.3f}x",
            f"{cpu[name] / cpu[reference]:.2f}x",
        ]
        for name, values in results.items()
    ]
    headers = [title, f"{unit} (median)", "min..max", "vs after", f"vs {reference}"]
    per_round = " ".join(
        f"{a / b:.2f}" for a, b in zip(results["after"], results["before"], strict=True)
    )
    return [
        benchlib.table(headers, rows),
        "",
        f"after / before: {cpu['after'] / cpu['before']:.3f}x (medians); round by round "
        f"(same round, the order rotated): {per_round}",
    ]


PARTS: dict[str, tuple[str, Callable[..., dict[str, list[float]]], str, str]] = {
    "master": ("Master (client process CPU)", part_master, PYMODBUS, "CPU us/read"),
    "slave": ("Slave (slave process CPU)", part_slave, PYMODBUS_SERVER, "CPU us/read"),
    "calls": ("Master (Python calls)", part_calls, "before", "calls/read"),
}


def main() -> None:
    if len(sys.argv) > 1 and sys.argv[1] == "--child":
        child(sys.argv[2], sys.argv[3], int(sys.argv[4]))
        return
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("before", help="the checkout before (its src/ is put on PYTHONPATH)")
    parser.add_argument("after", help="the checkout after")
    parser.add_argument("--rounds", type=int, default=8)
    parser.add_argument("--requests", type=int, default=3000)
    parser.add_argument("--part", action="append", choices=list(PARTS))
    args = parser.parse_args()
    before, after = os.path.realpath(args.before), os.path.realpath(args.after)
    print("\n".join(benchlib.header()))
    print(f"before: {before} at {commit(before)}; after: {after} at {commit(after)}")
    for name in args.part or list(PARTS):
        title, run, reference, unit = PARTS[name]
        started = load()
        results = run(before, after, args.rounds, args.requests)
        print()
        print(f"{name}: {args.rounds} rounds of {args.requests} reads of 10 holding registers")
        print(f"load average (1, 5, 15 min) before: {started}; after: {load()}")
        print()
        print("\n".join(report(title, results, reference, unit)), flush=True)


if __name__ == "__main__":
    main()

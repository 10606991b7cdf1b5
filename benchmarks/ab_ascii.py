"""Interleaved A/B of two source trees over Modbus ASCII: the master's and the server's CPU
and Python calls per read.

Run from the repository root with pymodbus and socat installed::

    python benchmarks/ab_ascii.py BEFORE AFTER [--rounds 8] [--requests 2000]
        [--part master|server|calls ...]

BEFORE and AFTER are checkouts of the repository; each runs with ``PYTHONPATH=TREE/src``.
Every line is a socat pty pair at 19200 8N2 (a pty keeps neither parity nor 7 data bits), every
timed run a fresh process, and the contenders take turns round by round, the order rotated each
round so that none always runs first.

master: each round, a fresh process per contender reads 10 holding registers *requests* times
    (after 20 reads of warm-up) from pymodbus's ASCII server and reports its own
    ``process_time`` per read: aiortu's master of BEFORE and of AFTER, and pymodbus's
    ``AsyncModbusSerialClient`` (ASCII framer).
server: each round, a fresh server process per contender on a pty pair of its own (aiortu's
    `serve(..., framing="ascii")` of BEFORE and of AFTER, pymodbus's ASCII server), read by
    pymodbus's client in this process; the server's CPU per request is the sum of its threads'
    ``/proc/PID/task/*/schedstat`` run times (nanoseconds) around the timed reads.
calls: the Python function calls (and coroutine resumptions) per read of each tree's master
    (against pymodbus's server) and of each tree's server (read by pymodbus's client), counted
    with ``sys.setprofile`` over up to 1000 reads: figures the machine's load does not move.
instructions: the user-space instructions per read of each tree's master and of pymodbus's
    client against pymodbus's server, counted by callgrind (valgrind): the difference between
    runs of 100 and 400 reads, over 300. Neither the kernel's work (the pty, epoll) nor the
    load counts.

Prints the machine, the commits, the load average before and after, and a table per part:
medians, min..max, and the ratios to AFTER and to pymodbus.
"""

from __future__ import annotations

import argparse
import asyncio
import os
import re
import subprocess
import sys
import tempfile
import threading
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import benchlib
from ab_commits import commit, load, rotated

LINE = {"baudrate": 19200, "bytesize": 8, "parity": "N", "stopbits": 2}
PEERS = str(Path(__file__).resolve().parents[1] / "tests" / "transport" / "pymodbus_peers.py")
PYMODBUS = "pymodbus"


class CallCounter:
    """Counts the Python calls of the thread that starts it."""

    def __init__(self) -> None:
        self.calls = 0

    def __call__(self, frame: object, event: str, arg: object) -> None:
        if event == "call":
            self.calls += 1

    def start(self) -> None:
        sys.setprofile(self)

    def stop(self) -> None:
        sys.setprofile(None)


# -- the child processes ------------------------------------------------------------------------


async def master_reads(
    port: str, requests: int, count_calls: bool, framing: str = "ascii"
) -> tuple[str, float]:
    """*requests* reads by aiortu's master: where aiortu came from, and CPU s (or calls) a read."""
    import aiortu

    counter = CallCounter()
    options: dict[str, Any] = {"framing": framing} if framing == "ascii" else {"frame_gap": 0}
    async with aiortu.open_master(port, timeout=1.0, retries=0, **options, **LINE) as master:
        for _ in range(20):
            expected = await master.read_holding_registers(1, 0, 10)
        cpu = time.process_time()
        if count_calls:
            counter.start()
        for _ in range(requests):
            if await master.read_holding_registers(1, 0, 10) != expected:
                raise AssertionError("aiortu read the wrong registers")
        counter.stop()
        cost = counter.calls if count_calls else time.process_time() - cpu
    return aiortu.__file__, cost / requests


async def pymodbus_reads(port: str, requests: int) -> float:
    """*requests* reads by pymodbus's ASCII client; this process's CPU seconds in all."""
    import pymodbus
    from pymodbus.client import AsyncModbusSerialClient

    client = AsyncModbusSerialClient(
        port, framer=pymodbus.FramerType.ASCII, timeout=1.0, retries=0, **LINE
    )  # type: ignore[arg-type]
    await client.connect()
    try:
        for _ in range(20):
            expected = (await client.read_holding_registers(0, count=10, device_id=1)).registers
        cpu = time.process_time()
        for _ in range(requests):
            reply = await client.read_holding_registers(0, count=10, device_id=1)
            if reply.registers != expected:
                raise AssertionError("pymodbus read the wrong registers")
        return time.process_time() - cpu
    finally:
        client.close()


async def serve(port: str, count_calls: bool) -> None:
    """aiortu's ASCII server for unit 1; prints `ready`, and on each line of stdin the calls
    counted since the last (with *count_calls*; else 0)."""
    import anyio

    import aiortu

    counter = CallCounter()
    store = aiortu.MemoryStore(holding_registers={0: list(range(40))})
    loop = asyncio.get_running_loop()

    def report() -> None:
        counter.stop()
        print(counter.calls, flush=True)
        counter.calls = 0
        if count_calls:
            counter.start()

    def stdin_lines() -> None:
        for _ in sys.stdin:
            loop.call_soon_threadsafe(report)

    async with aiortu.serve(port, {1: store}, framing="ascii", **LINE):  # type: ignore[arg-type]
        print(aiortu.__file__, flush=True)
        if count_calls:
            counter.start()
        threading.Thread(target=stdin_lines, daemon=True).start()
        await anyio.sleep_forever()


def child(kind: str, port: str, requests: int) -> None:
    import logging
    import warnings

    warnings.filterwarnings("ignore")
    logging.getLogger("pymodbus").setLevel(logging.CRITICAL)
    logging.getLogger("aiortu").setLevel(logging.ERROR)
    if kind in ("serve", "serve-calls"):
        asyncio.run(serve(port, kind == "serve-calls"))
        return
    if kind == "pymodbus":
        print(asyncio.run(pymodbus_reads(port, requests)) / requests)
        return
    framing = "rtu" if kind == "rtu" else "ascii"
    path, cost = asyncio.run(master_reads(port, requests, kind == "calls", framing))
    print(path)
    print(cost)


def _env(tree: str) -> dict[str, str]:
    return {**os.environ, "PYTHONPATH": os.path.join(tree, "src")}


def _check_origin(tree: str, path: str) -> None:
    if not path.startswith(os.path.realpath(tree)):
        raise RuntimeError(f"the process of {tree} imported aiortu from {path}")


def run_child(tree: str, kind: str, port: str, requests: int) -> float:
    argv = [sys.executable, os.path.abspath(__file__), "--child", kind, port, str(requests)]
    done = subprocess.run(argv, env=_env(tree), capture_output=True, text=True, check=False)
    if done.returncode != 0:
        raise RuntimeError(f"the {kind} client of {tree} failed:\n{done.stderr}")
    lines = done.stdout.split()
    if kind != "pymodbus":
        _check_origin(tree, lines[0])
    return float(lines[-1])


def start_server(
    children: benchlib.Children, tree: str | None, port: str, calls: bool = False
) -> subprocess.Popen[bytes]:
    """aiortu's server of *tree* (pymodbus's when None) on *port*, once it serves."""
    if tree is None:
        argv = [sys.executable, "-W", "ignore", PEERS, "ascii", port]
        env = dict(os.environ)
    else:
        kind = "serve-calls" if calls else "serve"
        argv = [sys.executable, os.path.abspath(__file__), "--child", kind, port, "0"]
        env = _env(tree)
    process = children.start(argv, stdout=subprocess.PIPE, stdin=subprocess.PIPE, env=env)
    assert process.stdout is not None
    line = process.stdout.readline().decode().strip()
    if tree is not None:
        _check_origin(tree, line)
    elif line != "ready 0":
        raise RuntimeError(f"pymodbus's server did not start: {line!r}")
    return process


def server_calls(process: subprocess.Popen[bytes]) -> int:
    """The calls *process* (a `serve-calls` child) counted since it last said."""
    assert process.stdin is not None
    assert process.stdout is not None
    process.stdin.write(b"\n")
    process.stdin.flush()
    return int(process.stdout.readline())


# -- the parts --------------------------------------------------------------------------------


def part_master(before: str, after: str, rounds: int, requests: int) -> dict[str, list[float]]:
    contenders = {
        "before": (before, "aiortu"),
        "after": (after, "aiortu"),
        PYMODBUS: (after, PYMODBUS),
    }
    results: dict[str, list[float]] = {name: [] for name in contenders}
    with benchlib.Children() as children:
        client_port, server_port = children.socat_pair()
        start_server(children, None, server_port)
        for turn in range(rounds):
            for name in rotated(list(contenders), turn):
                tree, kind = contenders[name]
                results[name].append(run_child(tree, kind, client_port, requests))
    return results


def server_round(tree: str | None, requests: int) -> float:
    with benchlib.Children() as children:
        client_port, server_port = children.socat_pair()
        server = start_server(children, tree, server_port)
        cpu = benchlib.cpu_exact(server.pid)
        asyncio.run(pymodbus_reads(client_port, requests))
        return (benchlib.cpu_exact(server.pid) - cpu) / requests


def part_server(before: str, after: str, rounds: int, requests: int) -> dict[str, list[float]]:
    contenders: dict[str, str | None] = {"before": before, "after": after, PYMODBUS: None}
    results: dict[str, list[float]] = {name: [] for name in contenders}
    for turn in range(rounds):
        for name in rotated(list(contenders), turn):
            results[name].append(server_round(contenders[name], requests))
    return results


def part_calls(before: str, after: str, rounds: int, requests: int) -> dict[str, list[float]]:
    """Python calls per read of each tree's master and server (one run each: the count does
    not move with the load)."""
    count = min(requests, 1000)
    results: dict[str, list[float]] = {}
    for name, tree in (("before", before), ("after", after)):
        with benchlib.Children() as children:
            client_port, server_port = children.socat_pair()
            start_server(children, None, server_port)
            results[f"master {name}"] = [run_child(tree, "calls", client_port, count)]
        with benchlib.Children() as children:
            client_port, server_port = children.socat_pair()
            server = start_server(children, tree, server_port, calls=True)
            asyncio.run(pymodbus_reads(client_port, 20))
            server_calls(server)
            asyncio.run(pymodbus_reads(client_port, count))
            results[f"server {name}"] = [server_calls(server) / (count + 20)]
    return results


def instructions(tree: str, kind: str, port: str, requests: int) -> int:
    """User-space instructions of one client process of *kind* doing *requests* reads after
    its warm-up, counted by callgrind (valgrind), its own start-up included."""
    with tempfile.TemporaryDirectory() as directory:
        out = os.path.join(directory, "callgrind.out")
        argv = [
            "valgrind",
            "--tool=callgrind",
            f"--callgrind-out-file={out}",
            sys.executable,
            os.path.abspath(__file__),
            "--child",
            kind,
            port,
            str(requests),
        ]
        done = subprocess.run(argv, env=_env(tree), capture_output=True, text=True, check=False)
    found = re.search(r"refs:\s+([\d,]+)", done.stderr)
    if done.returncode != 0 or found is None:
        raise RuntimeError(f"callgrind of the {kind} client of {tree} failed:\n{done.stderr}")
    return int(found.group(1).replace(",", ""))


def part_instructions(
    before: str, after: str, rounds: int, requests: int
) -> dict[str, list[float]]:
    """Instructions per read of each tree's master and of pymodbus's client, all against
    pymodbus's server: the difference between 100 and 400 reads, over 300 (start-up cancels).
    The reference: AFTER's master in RTU, against pymodbus's RTU server."""
    contenders = {
        "before": (before, "aiortu"),
        "after": (after, "aiortu"),
        PYMODBUS: (after, PYMODBUS),
        "after, RTU (reference)": (after, "rtu"),
    }
    results: dict[str, list[float]] = {}
    with benchlib.Children() as children:
        ascii_port, server_port = children.socat_pair()
        start_server(children, None, server_port)
        rtu_port, server_port = children.socat_pair()
        children.server("pymodbus", server_port)
        for name, (tree, kind) in contenders.items():
            port = rtu_port if kind == "rtu" else ascii_port
            few = instructions(tree, kind, port, 100)
            many = instructions(tree, kind, port, 400)
            results[name] = [(many - few) / 300]
    return results


def report(title: str, results: dict[str, list[float]], unit: str) -> list[str]:
    middle = {name: benchlib.median(values) for name, values in results.items()}
    if unit in ("calls/read", "instructions/read"):
        rows = [[name, f"{value:.0f}"] for name, value in middle.items()]
        return [benchlib.table([title, unit], rows)]
    rows = [
        [
            name,
            f"{middle[name] * 1e6:.1f}",
            f"{min(values) * 1e6:.1f}..{max(values) * 1e6:.1f}",
            f"{middle[name] / middle['after']:.3f}x",
            f"{middle[name] / middle[PYMODBUS]:.2f}x",
        ]
        for name, values in results.items()
    ]
    per_round = " ".join(
        f"{a / b:.2f}" for a, b in zip(results["after"], results["before"], strict=True)
    )
    headers = [title, f"{unit} (median)", "min..max", "vs after", f"vs {PYMODBUS}"]
    return [
        benchlib.table(headers, rows),
        "",
        f"after / before: {middle['after'] / middle['before']:.3f}x (medians); round by round: "
        f"{per_round}",
    ]


PARTS: dict[str, tuple[str, Callable[..., dict[str, list[float]]], str]] = {
    "master": ("ASCII master (client process CPU)", part_master, "CPU us/read"),
    "server": ("ASCII server (server process CPU, schedstat)", part_server, "CPU us/read"),
    "calls": ("ASCII (Python calls)", part_calls, "calls/read"),
    "instructions": ("ASCII master (callgrind)", part_instructions, "instructions/read"),
}


def main() -> None:
    if len(sys.argv) > 1 and sys.argv[1] == "--child":
        child(sys.argv[2], sys.argv[3], int(sys.argv[4]))
        return
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("before", help="the checkout before (its src/ is put on PYTHONPATH)")
    parser.add_argument("after", help="the checkout after")
    parser.add_argument("--rounds", type=int, default=8)
    parser.add_argument("--requests", type=int, default=2000)
    parser.add_argument("--part", action="append", choices=list(PARTS))
    args = parser.parse_args()
    before, after = os.path.realpath(args.before), os.path.realpath(args.after)
    print("\n".join(benchlib.header()))
    print(f"before: {before} at {commit(before)}; after: {after} at {commit(after)}")
    for name in args.part or list(PARTS):
        title, run, unit = PARTS[name]
        started = load()
        results = run(before, after, args.rounds, args.requests)
        print()
        print(f"{name}: {args.rounds} rounds of {args.requests} reads of 10 holding registers")
        print(f"load average (1, 5, 15 min) before: {started}; after: {load()}")
        print()
        print("\n".join(report(title, results, unit)), flush=True)


if __name__ == "__main__":
    main()

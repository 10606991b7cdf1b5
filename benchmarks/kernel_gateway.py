"""User and system CPU, system calls and wake-ups per request of the line servers.

    python benchmarks/kernel_gateway.py [--mbusd PATH] [--baseline SRC] [--rounds 2]
        [--seconds 4] [--rate 115200:8N1] [--clients 8] [--no-trace]

The same set-up as `bench_gateway.py --section unpaced` (a socat pty pair, pymodbus's RTU
server, `--clients` Modbus TCP clients each reading 10 holding registers of its own block),
each gateway a process of its own. Two passes per gateway and round:

- untraced: user and system CPU (/proc/PID/stat) and context switches, voluntary (the
  process slept: a wake-up each) and not (/proc/PID/status), per request;
- traced (unless `--no-trace`): `perf trace -s` on the process counts its system calls by
  name, per request. Tracing slows the process, so its CPU is not read in this pass. An
  event loop that waits in `epoll_wait` once per iteration gives its loop iterations per
  request as the count of `epoll_wait`.

Contenders: mbusd (`--mbusd`, when there), the aiortu gateway of this tree with the line's
t3.5 and with `--frame-gap 0.001` (mbusd's `-R 1`), and with `--baseline SRC` the gateway of
another checkout's `src`, both ways. Rounds alternate the contenders; the tables give medians.
"""

from __future__ import annotations

import argparse
import collections
import os
import re
import signal
import subprocess
import sys
import tempfile
import time
from dataclasses import dataclass, field

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import bench_gateway
import benchlib

_TICKS = os.sysconf("SC_CLK_TCK")
_SYSCALL_ROW = re.compile(r"^\s+([a-z_0-9]+)\s+(\d+)\s+\d+\s")


@dataclass
class Sample:
    """What one gateway did per request in one round."""

    user_us: float = 0.0
    system_us: float = 0.0
    voluntary: float = 0.0
    involuntary: float = 0.0
    rate: float = 0.0
    syscalls: dict[str, float] = field(default_factory=dict)


def _proc(pid: int) -> tuple[float, float, int, int]:
    """User and system seconds, voluntary and involuntary context switches of `pid`."""
    with open(f"/proc/{pid}/stat", encoding="ascii") as stat:
        fields = stat.read().rsplit(")", 1)[1].split()
    user, system = int(fields[11]) / _TICKS, int(fields[12]) / _TICKS
    switches = {}
    with open(f"/proc/{pid}/status", encoding="ascii") as status:
        for line in status:
            if "ctxt_switches" in line:
                name, value = line.split(":")
                switches[name] = int(value)
    return user, system, switches["voluntary_ctxt_switches"], switches["nonvoluntary_ctxt_switches"]


def _untraced(pid: int, port: int, args: argparse.Namespace, sample: Sample) -> None:
    before = _proc(pid)
    load = bench_gateway.run_clients(port, args.clients, args.seconds)
    after = _proc(pid)
    requests = sum(load.counts) + load.errors
    deltas = [b - a for a, b in zip(before, after, strict=True)]
    sample.user_us = deltas[0] / requests * 1e6
    sample.system_us = deltas[1] / requests * 1e6
    sample.voluntary = deltas[2] / requests
    sample.involuntary = deltas[3] / requests
    sample.rate = load.rate


def _traced(pid: int, port: int, args: argparse.Namespace, sample: Sample) -> None:
    with tempfile.NamedTemporaryFile("r", suffix=".perf") as out:
        tracer = subprocess.Popen(
            ["perf", "trace", "-s", "-o", out.name, "-p", str(pid)],
            stdout=subprocess.DEVNULL,
            stderr=subprocess.DEVNULL,
        )
        time.sleep(0.5)  # perf attaches
        load = bench_gateway.run_clients(port, args.clients, args.seconds, warmup=0.0)
        tracer.send_signal(signal.SIGINT)
        tracer.wait(10)
        counts: collections.Counter[str] = collections.Counter()
        for line in out.read().splitlines():
            match = _SYSCALL_ROW.match(line)
            if match:
                counts[match.group(1)] += int(match.group(2))
    # perf counts the whole window (its attach and detach too): per request served then.
    requests = sum(load.counts) + load.errors
    sample.syscalls = {name: count / requests for name, count in counts.items()}


def one_round(
    children: benchlib.Children, name: str, serial: str, args: argparse.Namespace
) -> Sample:
    process, port = bench_gateway.start_gateway(children, name, serial, args, args.rate)
    sample = Sample()
    try:
        bench_gateway.run_clients(port, 1, 0.3, warmup=0.0)
        _untraced(process.pid, port, args, sample)
        if args.trace:
            _traced(process.pid, port, args, sample)
    finally:
        children.stop(process)
        children.processes.remove(process)
    return sample


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--mbusd", default=bench_gateway.MBUSD)
    parser.add_argument("--baseline", default=None, metavar="SRC")
    parser.add_argument("--rounds", type=int, default=2)
    parser.add_argument("--seconds", type=float, default=4.0)
    parser.add_argument("--rate", type=bench_gateway.Rate.parse, default="115200:8N1")
    parser.add_argument("--clients", type=int, default=8)
    parser.add_argument("--no-trace", dest="trace", action="store_false")
    args = parser.parse_args()
    names = [*bench_gateway.contenders(args), bench_gateway.GAP_1MS]
    if args.baseline:
        names += [bench_gateway.BASE, f"{bench_gateway.BASE}, 1 ms gap"]
    samples: dict[str, list[Sample]] = {name: [] for name in names}
    with bench_gateway.socat_line(rate=args.rate) as (children, serial):
        for _ in range(args.rounds):
            for name in names:
                samples[name].append(one_round(children, name, serial, args))
    print("\n".join(benchlib.header()))
    print(f"Load average at the end: {os.getloadavg()}")
    print()
    _report(names, samples, args.trace)


def _report(names: list[str], samples: dict[str, list[Sample]], traced: bool) -> None:
    rows = []
    for name in names:
        runs = samples[name]

        def med(attribute: str, runs: list[Sample] = runs) -> float:
            return benchlib.median([getattr(run, attribute) for run in runs])

        total = benchlib.median([run.user_us + run.system_us for run in runs])
        rows.append(
            [
                name, f"{med('rate'):.0f}", f"{total:.0f}", f"{med('user_us'):.0f}",
                f"{med('system_us'):.0f}", f"{med('voluntary'):.2f}", f"{med('involuntary'):.2f}",
            ]
        )  # fmt: skip
    headers = ["gateway", "requests/s", "CPU us/request", "user", "system",
               "voluntary switches/request", "involuntary"]  # fmt: skip
    print(benchlib.table(headers, rows))
    if not traced:
        return
    calls = sorted({call for runs in samples.values() for run in runs for call in run.syscalls})
    rows = []
    for call in [*calls, "all"]:
        row = [call]
        for name in names:
            runs = samples[name]
            if call == "all":
                row.append(f"{benchlib.median([sum(run.syscalls.values()) for run in runs]):.2f}")
            else:
                row.append(f"{benchlib.median([run.syscalls.get(call, 0.0) for run in runs]):.2f}")
        if call == "all" or any(float(cell) >= 0.05 for cell in row[1:]):
            rows.append(row)
    print()
    print(benchlib.table(["system calls per request", *names], rows))


if __name__ == "__main__":
    main()

"""Instructions per request of the line servers, counted by callgrind: a figure the load does
not move.

    python benchmarks/instructions_gateway.py [--baseline SRC] [--mbusd PATH] [--seconds 10]
        [--rate 115200:8N1] [--clients 8]

The set-up of `bench_gateway.py --section unpaced` (a socat pty pair, pymodbus's RTU server,
`--clients` Modbus TCP clients reading 10 holding registers of a block of their own), each
gateway a process of its own under `valgrind --tool=callgrind`, counting nothing until it has
served a warm-up; then the counts are zeroed, the clients run for `--seconds`, and the
process's instructions (user space only: callgrind sees no kernel) are divided by the requests
served. Callgrind slows the process about fifty times, so the figure counts what a request
costs, not how fast the line goes.
"""

from __future__ import annotations

import argparse
import os
import re
import subprocess
import sys
import tempfile
from pathlib import Path

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import bench_gateway
import benchlib

_TOTALS = re.compile(r"^(?:totals|summary):\s+(\d+)", re.MULTILINE)


def _count(children: benchlib.Children, name: str, serial: str, args: argparse.Namespace) -> float:
    """Instructions per request of gateway `name` under callgrind."""
    with tempfile.TemporaryDirectory() as folder:
        out = Path(folder, "callgrind.out")
        prefix = ["valgrind", "--tool=callgrind", "--instr-atstart=no"]
        prefix += [f"--callgrind-out-file={out}.%p"]
        process, port = bench_gateway.start_gateway(
            children, name, serial, args, args.rate, prefix=prefix, wait=180
        )
        try:
            bench_gateway.run_clients(port, args.clients, 2.0, warmup=0.0)
            _control("-i", "on", process.pid)
            _control("-z", process.pid)
            load = bench_gateway.run_clients(port, args.clients, args.seconds, warmup=0.0)
            _control("-d", process.pid)
        finally:
            children.stop(process)
            children.processes.remove(process)
        dump = Path(f"{out}.{process.pid}.1").read_text()
    instructions = max(int(match) for match in _TOTALS.findall(dump))
    return instructions / (sum(load.counts) + load.errors)


def _control(*arguments: object) -> None:
    subprocess.run(
        ["callgrind_control", *map(str, arguments)], check=True, stdout=subprocess.DEVNULL
    )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--mbusd", default=bench_gateway.MBUSD)
    parser.add_argument("--baseline", default=None, metavar="SRC")
    parser.add_argument("--seconds", type=float, default=10.0)
    parser.add_argument("--rate", type=bench_gateway.Rate.parse, default="115200:8N1")
    parser.add_argument("--clients", type=int, default=8)
    args = parser.parse_args()
    names = [*bench_gateway.contenders(args), bench_gateway.GAP_1MS]
    if args.baseline:
        names += [bench_gateway.BASE, f"{bench_gateway.BASE}, 1 ms gap"]
    rows = []
    with bench_gateway.socat_line(rate=args.rate) as (children, serial):
        for name in names:
            rows.append([name, f"{_count(children, name, serial, args):,.0f}"])
    print("\n".join(benchlib.header()))
    print()
    print(benchlib.table(["gateway", "instructions per request (user space)"], rows))


if __name__ == "__main__":
    main()

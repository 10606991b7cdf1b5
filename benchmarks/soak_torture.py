"""Concurrency torture soak: many seeds of the torture suite's scenarios, every invariant checked.

Run from the repository root::

    python benchmarks/soak_torture.py [--seeds 100] [--start 0] [--kind both]

Seed *s* runs the master scenario of *s* (1 to 200 callers with mixed reads, writes and
broadcasts, random timeouts, priorities and cancellations, against slow, late, dead,
noisy and confused devices, the port pulled and plugged back, 300 to 115200 baud, on a
VirtualBus or a PtyBus) and the slave scenario of *s* (other masters' garbage, requests
to other units, broadcasts, the serve task cancelled mid-request); see
``tests/torture/scenarios.py``. ``--kind`` runs only one of them.

Prints one line per scenario that broke an invariant (with the command that reruns it
alone), then a table: seeds, operations, calls by outcome, violations. Exit code 1 if
any invariant broke.
"""

from __future__ import annotations

import argparse
import sys
import time
from collections import Counter
from pathlib import Path

import anyio

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from tests.torture.checks import Report
from tests.torture.master_storm import run_master_scenario
from tests.torture.scenarios import master_scenario, slave_scenario
from tests.torture.slave_storm import run_slave_scenario


async def _run(kind: str, seed: int) -> Report:
    if kind == "master":
        return await run_master_scenario(master_scenario(seed))
    return await run_slave_scenario(slave_scenario(seed))


async def _soak(args: argparse.Namespace) -> tuple[list[Report], float]:
    kinds = ("master", "slave") if args.kind == "both" else (args.kind,)
    reports: list[Report] = []
    started = time.perf_counter()
    for number, seed in enumerate(range(args.start, args.start + args.seeds), 1):
        for kind in kinds:
            report = await _run(kind, seed)
            reports.append(report)
            if report.violations:
                print(report.message(), flush=True)
        if args.progress and number % args.progress == 0:
            print(f"... {number} seeds, {time.perf_counter() - started:.0f} s", flush=True)
    return reports, time.perf_counter() - started


def _table(args: argparse.Namespace, reports: list[Report], elapsed: float) -> str:
    master = [r for r in reports if r.kind == "master"]
    slave = [r for r in reports if r.kind == "slave"]
    lines = [
        f"seeds {args.start}..{args.start + args.seeds - 1} ({args.seeds}), kind {args.kind}, "
        f"{elapsed:.0f} s",
        f"{'':24}{'master':>10}{'slave':>10}{'total':>10}",
    ]

    def row(name: str, master_value: int, slave_value: int) -> None:
        lines.append(
            f"{name:24}{master_value:>10}{slave_value:>10}{master_value + slave_value:>10}"
        )

    row("scenarios", len(master), len(slave))
    row("operations", sum(r.operations for r in master), sum(r.operations for r in slave))
    outcomes_m: Counter[str] = sum((r.outcomes for r in master), Counter())
    outcomes_s: Counter[str] = sum((r.outcomes for r in slave), Counter())
    for name in sorted(set(outcomes_m) | set(outcomes_s)):
        row(f"  {name}", outcomes_m[name], outcomes_s[name])
    row(
        "scenarios with violations",
        sum(1 for r in master if r.violations),
        sum(1 for r in slave if r.violations),
    )
    row("violations", sum(len(r.violations) for r in master), sum(len(r.violations) for r in slave))
    return "\n".join(lines)


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", type=int, default=100, help="how many seeds (default 100)")
    parser.add_argument("--start", type=int, default=0, help="the first seed (default 0)")
    parser.add_argument("--kind", choices=("both", "master", "slave"), default="both")
    parser.add_argument("--progress", type=int, default=0, help="a progress line every N seeds")
    args = parser.parse_args()
    reports, elapsed = anyio.run(_soak, args)
    print(_table(args, reports, elapsed))
    return 1 if any(r.violations for r in reports) else 0


if __name__ == "__main__":
    sys.exit(main())

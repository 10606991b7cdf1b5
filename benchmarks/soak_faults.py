"""Fault soak: mixed faults against the master and the slave for minutes, every result checked.

Run from the repository root::

    nice -n 10 python benchmarks/soak_faults.py --minutes 30 [--seed 1]

Rounds of three kinds, drawn at random, each with a seed of its own (printed with any
violation, so that a round can be replayed with ``--only KIND --seed SEED --rounds 1``):

- ``slave``: requests with good CRCs and malformed PDUs, for every function code, to the
  slave's unit, to broadcast and to other units (``tests/faults/slave_scenarios.py``).
  Every answer must be a spec exception or a reply that answers the request, nothing may
  answer a broadcast or another unit, and the slave must answer a probe after each one.
- ``master``: a scripted device answers from another unit, with another function code,
  truncated, split, late, twice... (``tests/faults/master_scenarios.py``), with 0 to 2
  retries. The caller must get the right answer or a typed error, and the next call
  must be right.
- ``flood``: a burst of random garbage on a pty against a slave
  (``tests/faults/flood.py``): the resident set must not grow by more than 16 MB, the
  slave must use under 40 % of a core once the flood is over, and answer right after.

Prints a progress line a minute, then a table: operations, faults by kind, violations.
Exit code 1 if there is any violation.
"""

from __future__ import annotations

import argparse
import random
import sys
import time
from collections import Counter
from pathlib import Path

import anyio

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from tests.faults.flood import garbage_flood, rss_bytes
from tests.faults.master_scenarios import FAULTS, master_rig
from tests.faults.slave_scenarios import UNIT, draw_malformed, slave_under_test

KINDS = ("slave", "master", "flood")
WEIGHTS = (10, 10, 1)


class Soak:
    def __init__(self) -> None:
        self.operations: Counter[str] = Counter()
        self.faults: Counter[str] = Counter()
        self.violations: list[str] = []
        self.max_idle_cpu = 0.0
        self.max_rss_growth = 0

    async def slave_round(self, rng: random.Random, seed: int) -> None:
        async with slave_under_test() as under_test:
            for _ in range(rng.randrange(20, 80)):
                unit, pdu = draw_malformed(rng)
                target = "its unit" if unit == UNIT else "broadcast" if unit == 0 else "other unit"
                self.faults[f"slave: malformed request, {target}"] += 1
                self.operations["slave: frames"] += 1
                for problem in await under_test.exchange(unit, pdu):
                    self.violations.append(f"slave round, seed {seed}: {problem}")

    async def master_round(self, rng: random.Random, seed: int) -> None:
        async with master_rig(rng, retries=rng.randrange(3)) as rig:
            for _ in range(rng.randrange(10, 40)):
                fault = rng.choice(FAULTS)
                self.faults[f"master: {fault}"] += 1
                self.operations["master: calls"] += 2  # the faulted one and the next
                for problem in await rig.operation(fault):
                    self.violations.append(f"master round, seed {seed}: {problem}")
            self.operations.update({f"master outcome: {k}": v for k, v in rig.outcomes.items()})

    async def flood_round(self, rng: random.Random, seed: int) -> None:
        result = await garbage_flood(rng, rng.randrange(100_000, 1_000_000))
        self.faults["flood: garbage floods"] += 1
        self.operations["flood: garbage bytes written"] += result.garbage
        self.max_idle_cpu = max(self.max_idle_cpu, result.idle_cpu / result.idle)
        self.max_rss_growth = max(self.max_rss_growth, result.rss_growth)
        if not result.answered:
            self.violations.append(f"flood round, seed {seed}: no right answer after it")
        if result.idle_cpu > 0.4 * result.idle:
            self.violations.append(f"flood round, seed {seed}: spins after it: {result}")
        if result.rss_growth > 16 * 1024 * 1024:
            self.violations.append(f"flood round, seed {seed}: RSS grew: {result}")


async def soak(args: argparse.Namespace) -> int:
    state = Soak()
    rounds = {"slave": state.slave_round, "master": state.master_round, "flood": state.flood_round}
    chooser = random.Random(args.seed)
    started = time.monotonic()
    stop = started + args.minutes * 60
    next_report = started + 60
    rss_start = rss_bytes()
    count = reported = 0
    while time.monotonic() < stop and (args.rounds is None or count < args.rounds):
        kind = args.only or chooser.choices(KINDS, WEIGHTS)[0]
        seed = args.seed if args.rounds == 1 else chooser.randrange(1 << 32)
        count += 1
        state.operations[f"rounds: {kind}"] += 1
        try:
            with anyio.fail_after(300):
                await rounds[kind](random.Random(seed), seed)
        except Exception as error:  # a crash or a hang is a violation, with its seed
            state.violations.append(f"{kind} round, seed {seed}: {type(error).__name__}: {error}")
        for violation in state.violations[reported:]:
            print(f"VIOLATION {violation}", flush=True)
        reported = len(state.violations)
        if time.monotonic() >= next_report:
            next_report += 60
            print(
                f"{(time.monotonic() - started) / 60:5.1f} min: {count} rounds, "
                f"{sum(state.faults.values())} faults, {len(state.violations)} violations",
                flush=True,
            )
    elapsed = time.monotonic() - started
    print(f"\nfault soak: seed {args.seed}, {elapsed / 60:.1f} minutes, {count} rounds\n")
    print(f"{'operations':<56} {'count':>10}")
    for name, value in sorted(state.operations.items()):
        print(f"  {name:<54} {value:>10}")
    print(f"{'faults by kind':<56} {'count':>10}")
    for name, value in sorted(state.faults.items()):
        print(f"  {name:<54} {value:>10}")
    print(f"{'floods: worst idle CPU after (of a core)':<56} {state.max_idle_cpu:>10.1%}")
    print(f"{'floods: worst RSS growth (MB)':<56} {state.max_rss_growth / 2**20:>10.1f}")
    growth = (rss_bytes() - rss_start) / 2**20
    print(f"{'process RSS growth over the run (MB)':<56} {growth:>10.1f}")
    print(f"{'violations':<56} {len(state.violations):>10}")
    for violation in state.violations[:50]:
        print(f"  {violation}")
    return 1 if state.violations else 0


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--minutes", type=float, default=1.0)
    parser.add_argument("--seed", type=int, default=1)
    parser.add_argument("--only", choices=KINDS, help="run rounds of this kind only")
    parser.add_argument("--rounds", type=int, help="stop after this many rounds")
    args = parser.parse_args()
    sys.exit(anyio.run(soak, args))


if __name__ == "__main__":
    main()

"""Noise soak of the master: many transactions on a noisy virtual line, every result checked.

Run from the repository root::

    python benchmarks/soak_master.py [--transactions 20000] [--bit-error-rate 1e-4]
        [--baudrate 0] [--units 5] [--seed 1]

A :class:`aiortu.Slave` serves *units* simulated devices (a :class:`aiortu.MemoryStore`
each, register ``a`` of unit ``u`` holding ``(u * 1000 + a) & 0xFFFF``) on one end of a
:class:`aiortu.testing.VirtualBus` with a :class:`~aiortu.testing.FaultPlan` flipping
bits at the given rate; the master reads random ranges from the other end. Every result
must be either the right values or a typed :class:`aiortu.ModbusError`; a wrong value or
a hang (no progress for 10 s) ends the run with exit code 1. ``--baudrate 0`` (the
default) runs the line unpaced, as fast as the machine goes; a baud rate paces it.

Prints a summary table: transactions, outcomes by kind, the master's per-unit counters,
the faults injected, and the rate.
"""

from __future__ import annotations

import argparse
import random
import sys
import time
from collections import Counter

import anyio

import aiortu
from aiortu.core.serial import LineSettings
from aiortu.testing import FaultPlan, VirtualBus

REGISTERS = 2000


def expected(unit: int, address: int, count: int) -> list[int]:
    return [(unit * 1000 + address + i) & 0xFFFF for i in range(count)]


async def soak(args: argparse.Namespace) -> int:
    paced = LineSettings(args.baudrate, parity="E") if args.baudrate else None
    bus = VirtualBus(
        2, settings=paced, faults=FaultPlan(bit_error_rate=args.bit_error_rate, seed=args.seed)
    )
    units = {
        unit: aiortu.MemoryStore(holding_registers={0: expected(unit, 0, REGISTERS)})
        for unit in range(1, args.units + 1)
    }
    settings = paced or LineSettings(1_000_000)
    gap = None if paced else 0.0
    generator = random.Random(args.seed)
    outcomes: Counter[str] = Counter()
    wrong = 0
    started = time.perf_counter()
    async with (
        aiortu.Slave(bus.endpoints[1], units, settings, frame_gap=gap),
        aiortu.Master(
            bus.endpoints[0], settings, frame_gap=gap, timeout=args.timeout, late_reply_guard=0.02
        ) as master,
    ):
        await anyio.sleep(0.01)
        for _ in range(args.transactions):
            unit = generator.randint(1, args.units)
            count = generator.randint(1, 60)
            address = generator.randrange(0, REGISTERS - count)
            with anyio.fail_after(10):
                try:
                    values = await master.read_holding_registers(unit, address, count)
                except aiortu.ModbusError as error:
                    outcomes[type(error).__name__] += 1
                    continue
            if values == expected(unit, address, count):
                outcomes["ok"] += 1
            else:
                wrong += 1
                outcomes["WRONG VALUES"] += 1
        stats = dict(master.statistics)
    elapsed = time.perf_counter() - started

    print(f"aiortu master noise soak: {args.transactions} transactions, "
          f"bit error rate {args.bit_error_rate:g}, "
          f"{'unpaced' if paced is None else str(paced)}, {elapsed:.1f} s "
          f"({args.transactions / elapsed:.0f}/s)")  # fmt: skip
    print()
    print(f"{'outcome':<24}{'count':>10}{'share':>10}")
    for name, count in outcomes.most_common():
        print(f"{name:<24}{count:>10}{count / args.transactions:>10.2%}")
    print()
    print(f"{'unit':<6}{'requests':>10}{'timeouts':>10}{'crc':>8}{'frame':>8}{'retries':>9}"
          f"{'failures':>10}{'mean ms':>9}")  # fmt: skip
    for unit, s in sorted(stats.items()):
        mean = f"{s.mean_latency * 1000:.2f}" if s.mean_latency is not None else "-"
        print(f"{unit:<6}{s.requests:>10}{s.timeouts:>10}{s.crc_errors:>8}{s.frame_errors:>8}"
              f"{s.retries:>9}{s.failures:>10}{mean:>9}")  # fmt: skip
    if bus.injector is not None:
        faults = bus.injector.stats
        print()
        print(f"faults: {faults.bits_flipped} bits flipped in {faults.bytes} bytes "
              f"(seed {bus.injector.seed})")  # fmt: skip
    return 1 if wrong else 0


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n", 1)[0])
    parser.add_argument("--transactions", type=int, default=20_000)
    parser.add_argument("--bit-error-rate", type=float, default=1e-4)
    parser.add_argument("--baudrate", type=int, default=0, help="0: unpaced")
    parser.add_argument("--units", type=int, default=5)
    parser.add_argument("--timeout", type=float, default=0.05)
    parser.add_argument("--seed", type=int, default=1)
    args = parser.parse_args()
    try:
        return anyio.run(soak, args)
    except TimeoutError:
        print("HANG: a transaction made no progress for 10 s", file=sys.stderr)
        return 1


if __name__ == "__main__":
    sys.exit(main())

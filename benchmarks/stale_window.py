"""How much of the stale-reply window the master's causality rule closes, on a paced bus.

Run from the repository root::

    python benchmarks/stale_window.py [--trials 300] [--baudrate 19200] [--seed 1]

A paced three-port :class:`aiortu.testing.VirtualBus`: the master, a slave that keeps
the spec's t3.5 of silence before it answers, and a third port that plays a late reply
from an earlier request: the same unit, function code and count, other values. For each
trial the master reads three registers while the late reply goes on the wire at a
random moment between the request's first byte and the genuine reply's first byte (the
bus, like a transceiver, holds a transmission back while another is on the wire, so a
late reply sent during the request follows it). The table gives the fraction of trials
whose caller got the late reply's values (trials that failed are left out: the slave
hears the late reply, which carries its unit, as a malformed request and answers it
with an exception, which a later trial may get), with:

- ``old rule``: the rule before causality (a frame is stale if it ended before the
  request began to go out), what the master still does where the wire times are not
  real (``wire_timed=False``);
- ``causality, turnaround 0``: a frame is stale if it began before the request had left
  the wire (the default where the wire times are real);
- ``causality, turnaround t3.5``: ...plus the unit's minimum turnaround, here t3.5 (what
  a device that keeps the spec's silence allows: ``master.set_min_turnaround``).
"""

from __future__ import annotations

import argparse
import random
from collections import Counter
from dataclasses import dataclass, field

import anyio

import aiortu
from aiortu.core.frame import encode_frame
from aiortu.core.timing import LineSettings
from aiortu.testing import VirtualBus

UNIT = 1
GENUINE = [1, 2, 3]
STALE_PDU = bytes.fromhex("03 06 DE AD DE AD DE AD")


@dataclass
class Tally:
    """Trials whose late reply began before the genuine reply (the others cannot be
    taken: the genuine reply comes first), by where it began, and how many were taken."""

    counts: Counter[str] = field(default_factory=Counter)
    taken: Counter[str] = field(default_factory=Counter)
    failed: int = 0

    def rate(self, where: str | None = None) -> str:
        counts = self.counts[where] if where else self.counts.total()
        taken = self.taken[where] if where else self.taken.total()
        return f"{taken / counts:.0%} of {counts}" if counts else "-"


def _where(settings: LineSettings, late: float, request_end: float) -> str:
    if late <= request_end + 1.5 * settings.char_time:
        return "queued behind the request"
    return "within t3.5 after it" if late < request_end + settings.t3_5 else "after t3.5"


async def trials(
    settings: LineSettings, count: int, rng: random.Random, *, wire_timed: bool, turnaround: float
) -> Tally:
    """Run *count* trials and tally them."""
    bus = VirtualBus(3, settings=settings)
    store = aiortu.MemoryStore(holding_registers={0: GENUINE})
    stale_frame = encode_frame(UNIT, STALE_PDU)
    window = settings.wire_time(8) + settings.t3_5 + 0.001  # to the genuine reply, and on
    tally = Tally()
    async with (
        aiortu.Slave(bus.endpoints[1], {UNIT: store}, settings),
        aiortu.Master(
            bus.endpoints[0], settings, timeout=0.1, retries=0, wire_timed=wire_timed,
            min_turnaround=turnaround,
        ) as master,
    ):  # fmt: skip
        await anyio.sleep(0.05)
        for _ in range(count):
            offset = rng.uniform(0.0, window)

            async def inject(offset: float = offset) -> None:
                await anyio.sleep(offset)
                await bus.endpoints[2].send(stale_frame)

            bus.trace.clear()
            async with anyio.create_task_group() as tasks:
                tasks.start_soon(inject)
                try:
                    values: list[int] | None = await master.read_holding_registers(UNIT, 0, 3)
                except aiortu.ModbusError:
                    values = None
            await anyio.sleep(0.03)  # the line clears; the master drops what is left
            starts = {entry.sender: entry for entry in bus.trace}
            request, genuine, late = starts.get(0), starts.get(1), starts.get(2)
            if values is None:
                # The slave hears the late reply, which carries its own unit, as a
                # malformed request and answers it with an exception, which a later
                # trial may get: not the master's doing, left out.
                tally.failed += 1
                continue
            if request is None or late is None or late.start < request.start:
                continue  # the late reply went before the request: the old rule drops it
            if genuine and genuine.start < late.start:
                continue  # the genuine reply came first: nothing wrong to take
            where = _where(settings, late.start, request.end)
            tally.counts[where] += 1
            tally.taken[where] += values is not None and values != GENUINE
    return tally


async def main(args: argparse.Namespace) -> None:
    settings = LineSettings(args.baudrate)
    variants = (
        ("old rule", False, 0.0),
        ("causality, turnaround 0", True, 0.0),
        ("causality, turnaround t3.5", True, settings.t3_5),
    )
    print(
        f"{args.baudrate} baud, t3.5 = {settings.t3_5 * 1e3:.2f} ms, request on the wire "
        f"{settings.wire_time(8) * 1e3:.2f} ms, {args.trials} trials each, seed {args.seed}"
    )
    wheres = ("queued behind the request", "within t3.5 after it", "after t3.5")
    print(f"{'rule':<28} {'late reply taken':>16}  " + "  ".join(f"{w:>25}" for w in wheres))
    for name, wire_timed, turnaround in variants:
        tally = await trials(
            settings, args.trials, random.Random(args.seed), wire_timed=wire_timed,
            turnaround=turnaround,
        )  # fmt: skip
        detail = "  ".join(f"{tally.rate(where):>25}" for where in wheres)
        print(f"{name:<28} {tally.rate():>16}  {detail}   ({tally.failed} failed)")


if __name__ == "__main__":
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--trials", type=int, default=300)
    parser.add_argument("--baudrate", type=int, default=19200)
    parser.add_argument("--seed", type=int, default=1)
    anyio.run(main, parser.parse_args())

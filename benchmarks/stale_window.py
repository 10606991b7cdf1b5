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
from typing import Any

import anyio
import anyio.abc

import aiortu
from aiortu.core.rtu import encode_frame
from aiortu.core.serial import LineSettings
from aiortu.testing import TraceEntry, VirtualBus, VirtualEndpoint

UNIT = 1
GENUINE = [1, 2, 3]
STALE_PDU = bytes.fromhex("03 06 DE AD DE AD DE AD")


class FullDuplex(anyio.abc.ByteStream):
    """One end of a full-duplex line (RS-232, RS-422): it sends on one paced wire and
    receives from another, so a reply can arrive while a request is still going out."""

    def __init__(self, send: VirtualEndpoint, receive: VirtualEndpoint) -> None:
        self._send, self._receive = send, receive

    @property
    def wire_timed(self) -> bool:
        return True

    async def send(self, item: bytes) -> None:
        await self._send.send(item)

    async def receive(self, max_bytes: int = 65536) -> bytes:
        return await self._receive.receive(max_bytes)

    async def send_eof(self) -> None:
        await self._send.send_eof()

    async def aclose(self) -> None:
        await self._send.aclose()
        await self._receive.aclose()


def _line(settings: LineSettings, duplex: str) -> tuple[Any, Any, VirtualEndpoint, VirtualBus]:
    """The master's stream, the slave's, the late reply's sender, and the bus the
    replies travel on (its trace times them)."""
    if duplex == "half":
        bus = VirtualBus(3, settings=settings)
        return bus.endpoints[0], bus.endpoints[1], bus.endpoints[2], bus
    requests = VirtualBus(2, settings=settings)  # master -> slave
    replies = VirtualBus(3, settings=settings)  # slave and the late sender -> master
    master = FullDuplex(requests.endpoints[0], replies.endpoints[0])
    slave = FullDuplex(replies.endpoints[1], requests.endpoints[1])
    return master, slave, replies.endpoints[2], replies


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


WHERES = ("while the request went out", "up to t3.5 after it", "after t3.5")
"""Where a late reply began, from the request's end on the wire."""


def _where(settings: LineSettings, late: float, request_end: float) -> str:
    # A hundredth of a character: the bus's own arithmetic, not a real overlap.
    if late < request_end - settings.char_time / 100:
        return WHERES[0]
    return WHERES[1] if late < request_end + settings.t3_5 else WHERES[2]


async def trials(
    settings: LineSettings,
    count: int,
    rng: random.Random,
    *,
    wire_timed: bool,
    turnaround: float,
    duplex: str,
) -> Tally:
    """Run *count* trials and tally them."""
    master_end, slave_end, late_end, bus = _line(settings, duplex)
    store = aiortu.MemoryStore(holding_registers={0: GENUINE})
    stale_frame = encode_frame(UNIT, STALE_PDU)
    window = settings.wire_time(8) + settings.t3_5 + 0.001  # to the genuine reply, and on
    tally = Tally()
    async with (
        aiortu.Slave(slave_end, {UNIT: store}, settings),
        aiortu.Master(
            master_end, settings, timeout=0.1, retries=0, wire_timed=wire_timed,
            min_turnaround=turnaround,
        ) as master,
    ):  # fmt: skip
        await anyio.sleep(0.05)
        for _ in range(count):
            offset = rng.uniform(0.0, window)

            async def inject(offset: float = offset) -> None:
                await anyio.sleep(offset)
                await late_end.send(stale_frame)

            bus.trace.clear()
            request_start = anyio.current_time()
            async with anyio.create_task_group() as tasks:
                tasks.start_soon(inject)
                try:
                    values: list[int] | None = await master.read_holding_registers(UNIT, 0, 3)
                except aiortu.ModbusError:
                    values = None
            await anyio.sleep(0.03)  # the line clears; the master drops what is left
            starts = {entry.sender: entry for entry in bus.trace}
            genuine, late = starts.get(1), starts.get(2)
            # The request: from the trace on a half-duplex bus; on a full-duplex line it
            # went out at once on its own wire.
            request = starts.get(0) or TraceEntry(
                request_start, request_start + settings.wire_time(8), 0, b""
            )
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
        f"{settings.wire_time(8) * 1e3:.2f} ms, {args.trials} trials each, seed {args.seed}, "
        f"{args.duplex} duplex"
    )
    wheres = WHERES
    print(f"{'rule':<28} {'late reply taken':>16}  " + "  ".join(f"{w:>25}" for w in wheres))
    for name, wire_timed, turnaround in variants:
        tally = await trials(
            settings, args.trials, random.Random(args.seed), wire_timed=wire_timed,
            turnaround=turnaround, duplex=args.duplex,
        )  # fmt: skip
        detail = "  ".join(f"{tally.rate(where):>25}" for where in wheres)
        print(f"{name:<28} {tally.rate():>16}  {detail}   ({tally.failed} failed)")


if __name__ == "__main__":
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--trials", type=int, default=300)
    parser.add_argument("--baudrate", type=int, default=19200)
    parser.add_argument("--seed", type=int, default=1)
    parser.add_argument(
        "--duplex", choices=("half", "full"), default="half",
        help="one shared wire (RS-485), or one wire each way (RS-232, RS-422)",
    )  # fmt: skip
    anyio.run(main, parser.parse_args())

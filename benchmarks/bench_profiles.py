"""Benchmark of devices as data: read planning, decoding, and polling through profiles.

Run from the repository root::

    python benchmarks/bench_profiles.py [--quick]

(a) meter: the shipped Eastron SDM630 profile (85 float32 measurements over input registers
    0..0x17F): how many reads its measurements take.
(b) decode: 1,000 float32 points of one profile (mixed layouts, a scale on every tenth): the
    CPU of planning them once, and of decoding one poll's replies into named values
    (``BlockRead.decode`` then ``ReadPlan.values``), per poll.
(c) poll: the same 80 float32 points over input registers 0..0x17F read on an unpaced
    in-memory line (master and slave in this process, frame_gap=0) by the hand-written
    ``aiortu.Poller`` and by ``aiortu.ProfilePoller``, in interleaved rounds; this process's
    CPU per register read (master, slave and decoding).

CPU is ``time.process_time``: it does not move with the machine's load as wall time does.
"""

from __future__ import annotations

import argparse
import random
import sys
import time
from pathlib import Path

import anyio

sys.path.insert(0, __file__.rsplit("/", 1)[0])
import benchlib

import aiortu
from aiortu.core.model import (
    DeviceInfo,
    Layout,
    PointType,
    Profile,
    ProfilePoint,
    ReadPlan,
    Table,
    encode_value,
    load_profile,
)
from aiortu.testing import VirtualBus

ROOT = Path(__file__).parents[1]
SDM630 = ROOT / "src/aiortu/core/model/profiles/eastron-sdm630.toml"


def verdict(ok: bool) -> str:
    return "met" if ok else "NOT met"


def section_meter(args: argparse.Namespace) -> list[str]:
    profile = load_profile(SDM630)
    points = [p for p in profile.points if p.table is Table.INPUT_REGISTERS]
    reads = ReadPlan(profile, points).reads
    spans = ", ".join(f"{r.address:#x}..{r.address + r.count - 1:#x}" for r in reads)
    return [
        f"(a) meter: {len(points)} float32 points of the SDM630 profile in {len(reads)} reads "
        f"({spans})",
        "",
        f"Target: at most 4 requests: {verdict(len(reads) <= 4)} ({len(reads)}).",
    ]


def thousand_points() -> Profile:
    rng = random.Random(1)
    points = []
    address = 0
    for index in range(1000):
        table = Table.INPUT_REGISTERS if index % 2 else Table.HOLDING_REGISTERS
        points.append(
            ProfilePoint(
                f"p{index}",
                table,
                address,
                PointType.F32,
                2,
                layout=rng.choice(list(Layout)),
                scale=0.1 if index % 10 == 0 else None,
            )
        )
        address += 2 if index % 2 else 0  # both tables advance together
    return Profile("bench", DeviceInfo("bench", "1000"), tuple(points))


def section_decode(args: argparse.Namespace) -> list[str]:
    profile = thousand_points()
    polls = 200 if args.quick else 2000
    start = time.process_time()
    plans = 0
    while time.process_time() - start < 0.5:
        plan = ReadPlan(profile)
        plans += 1
    planning = (time.process_time() - start) / plans
    rng = random.Random(2)
    replies = [(read, [rng.randrange(0x10000) for _ in range(read.count)]) for read in plan.reads]
    start = time.process_time()
    for _ in range(polls):
        raws = {}
        for read, elements in replies:
            for point, raw in read.decode(elements):
                raws[point.name] = raw
        values = plan.values(raws)
    decoding = (time.process_time() - start) / polls
    assert len(values) == 1000
    rows = [
        ["plan 1,000 points (once)", f"{len(plan.reads)} reads", f"{planning * 1e3:.2f}"],
        ["decode one poll of 1,000 points", f"{polls} polls", f"{decoding * 1e3:.3f}"],
    ]
    return [
        "(b) decode: 1,000 float32 points, layouts mixed, a scale on every tenth",
        "",
        benchlib.table(["Step", "", "CPU ms"], rows),
        "",
        f"Target: decoding 1,000 points at most 1 ms CPU per poll: "
        f"{verdict(decoding <= 1e-3)} ({decoding * 1e3:.3f} ms); planning is done once "
        f"per plan ({planning * 1e3:.2f} ms).",
    ]


METER_POINTS = 80


def meter_store() -> aiortu.MemoryStore:
    registers = []
    for index in range(0x180 // 2):
        registers += encode_value(float(index), "float32")
    return aiortu.MemoryStore(input_registers={0: registers})


def meter_profile() -> Profile:
    # 80 points spread evenly over 0..0x17F (even addresses), with gaps, as a meter's map.
    addresses = [(i * (0x180 - 2) // (METER_POINTS - 1)) & ~1 for i in range(METER_POINTS)]
    points = tuple(
        ProfilePoint(f"v{i}", Table.INPUT_REGISTERS, a, PointType.F32, 2)
        for i, a in enumerate(addresses)
    )
    return Profile("bench", DeviceInfo("bench", "meter"), points)


async def poll_cpu(kind: str, cycles: int) -> tuple[float, int]:
    """CPU per register of `cycles` polls of the meter, and the reads per poll."""
    bus = VirtualBus(2)
    profile = meter_profile()
    async with (
        aiortu.Slave(bus.endpoints[1], {1: meter_store()}, frame_gap=0),
        aiortu.Master(bus.endpoints[0], timeout=1.0, frame_gap=0) as master,
    ):
        if kind == "Poller":
            points = [
                aiortu.Point("v" + p.name[1:], 1, "input_registers", p.address, "float32")
                for p in profile.points
            ]
            poller = aiortu.Poller(master, points, interval=1e-6, max_gap=10)
            reads = len(poller.reads)
            registers = sum(r.count for r in poller.reads)
            poll = poller.poll_once
        else:
            device = aiortu.Device(master, 1, profile)
            profile_poller = aiortu.ProfilePoller([device])
            reads = len(device.plan("normal").reads)
            registers = sum(r.count for r in device.plan("normal").reads)
            poll = profile_poller.poll_once
        await poll()  # warm up
        start = time.process_time()
        for _ in range(cycles):
            await poll()
        cpu = time.process_time() - start
    return cpu / (cycles * registers), reads


def section_poll(args: argparse.Namespace) -> list[str]:
    cycles = 100 if args.quick else 500
    rounds = 3 if args.quick else 7
    results: dict[str, list[float]] = {"Poller": [], "ProfilePoller": []}
    reads: dict[str, int] = {}
    for _ in range(rounds):
        for kind, cpus in results.items():
            cpu, reads[kind] = anyio.run(poll_cpu, kind, cycles)
            cpus.append(cpu)
    rows = [
        [
            kind,
            str(reads[kind]),
            f"{benchlib.median(cpus) * 1e6:.2f}",
            f"{min(cpus) * 1e6:.2f}..{max(cpus) * 1e6:.2f}",
        ]
        for kind, cpus in results.items()
    ]
    ratio = benchlib.median(results["ProfilePoller"]) / benchlib.median(results["Poller"])
    return [
        f"(c) poll: {METER_POINTS} float32 points over input registers 0..0x17F, unpaced "
        f"in-memory line; {rounds} interleaved rounds of {cycles} polls",
        "",
        benchlib.table(["Poller", "reads/poll", "CPU us/register (median)", "min..max"], rows),
        "",
        f"Target: at most 10 % more CPU per register through profiles: "
        f"{verdict(ratio <= 1.10)} ({(ratio - 1) * 100:+.1f} %).",
    ]


SECTIONS = {"meter": section_meter, "decode": section_decode, "poll": section_poll}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="fewer rounds")
    benchlib.add_section_argument(parser, SECTIONS)
    args = parser.parse_args()
    benchlib.run_sections(args, SECTIONS)


if __name__ == "__main__":
    main()

"""Benchmark of one serial line's moving parts.

Run from the repository root with aiortu installed::

    python benchmarks/bench_line.py [--rounds 15] [--frames 2000] [--rtts 1000] [--quick]
        [--section receiver|relay|flood]

Sections (each a function ``section_*`` returning the lines it prints; add a section by
writing one more and listing it in ``SECTIONS``):

(a) receiver: frames per second through the sans-IO receiver, for an 8-byte request
    (read holding registers, role SLAVE, addressed to the slave's unit) and a 25-byte reply
    (10 registers, role MASTER), fed whole (one ``feed()`` per frame, as a driver hands
    over a frame that arrived in one chunk) and fed byte by byte (one ``feed()`` per byte,
    the worst case of a driver that wakes per character). Frames are spaced by t3.5 at
    19200 baud, so every frame starts from IDLE; each frame is checked to come out.
    Contenders are timed interleaved round by round; the table gives the median.
(b) relay: the round trip of an 8-byte request and a 25-byte reply through the aiortu pty
    relay (:class:`aiortu.testing.PtyBus`, unpaced, 2 ports, run in a process of its own)
    against a socat pty pair (``socat pty,raw,echo=0 pty,raw,echo=0``). This process
    writes the request to one end and reads the reply from it; a responder process
    (``bench_servers.py bare``) reads the 8 bytes at the other end and writes
    the 25 back. The two lines take turns round by round; the table gives the median
    round trip of each round's *rtts* round trips, then the median over the rounds.
(c) flood: the sans-IO receiver's throughput on a continuous flood of random bytes (no
    silence, so every frame is found by the search after an overflow): 1 MiB of seeded
    random garbage with a frame the role wants glued in after every 4 KiB (a read request
    to unit 1 for a slave, its 25-byte reply for a master and a monitor), fed in chunks of
    seeded random sizes (1..1024 bytes). The table gives the median bytes per second over
    the rounds (contenders interleaved), the CPU per byte, and how many of the embedded
    frames came out, and how many other frames (a good CRC at a predicted length in random
    bytes: true frames, about one in 65536 per length checked).
"""

from __future__ import annotations

import argparse
import os
import statistics
import sys
import time
from collections.abc import Callable
from dataclasses import dataclass, field

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import benchlib

from aiortu.core.pdu import ReadHoldingRegistersRequest, ReadHoldingRegistersResponse
from aiortu.core.rtu import FrameReceived, Receiver, Role, encode_frame
from aiortu.core.serial import LineSettings

TARGET_FRAMES_PER_SECOND = 50_000
"""The issue's target for frames fed whole."""


# -- (a) the receiver ------------------------------------------------------------------------


@dataclass
class ReceiverCase:
    """One receiver workload: a frame, a role and how the frame is cut into chunks."""

    name: str
    frame: bytes
    role: Role
    units: tuple[int, ...]
    bytewise: bool
    rates: list[float] = field(default_factory=list)

    def run(self, frames: int, settings: LineSettings) -> float:
        """Feed *frames* copies; return frames per second (and check they all came out)."""
        receiver = Receiver(settings, role=self.role, units=self.units)
        frame = self.frame
        char = settings.char_time
        spacing = len(frame) * char + settings.t3_5
        feed = receiver.feed
        received = 0
        now = 1.0
        if self.bytewise:
            pieces = [frame[index : index + 1] for index in range(len(frame))]
            offsets = [index * char for index in range(len(frame))]
            start = time.perf_counter()
            for _ in range(frames):
                for piece, offset in zip(pieces, offsets, strict=True):
                    for event in feed(piece, now + offset):
                        received += type(event) is FrameReceived
                now += spacing
        else:
            start = time.perf_counter()
            for _ in range(frames):
                for event in feed(frame, now):
                    received += type(event) is FrameReceived
                now += spacing
        elapsed = time.perf_counter() - start
        if received != frames:
            raise AssertionError(f"{self.name}: {received} of {frames} frames received")
        return frames / elapsed


def receiver_cases() -> list[ReceiverCase]:
    request = encode_frame(17, ReadHoldingRegistersRequest(0x6B, 10).encode())
    reply = encode_frame(17, ReadHoldingRegistersResponse(tuple(range(10))).encode())
    assert (len(request), len(reply)) == (8, 25)
    return [
        ReceiverCase("8-byte request, SLAVE, whole", request, Role.SLAVE, (17,), False),
        ReceiverCase("25-byte reply, MASTER, whole", reply, Role.MASTER, (), False),
        ReceiverCase("8-byte request, SLAVE, byte by byte", request, Role.SLAVE, (17,), True),
        ReceiverCase("25-byte reply, MASTER, byte by byte", reply, Role.MASTER, (), True),
    ]


def section_receiver(args: argparse.Namespace) -> list[str]:
    settings = LineSettings(19200)
    cases = receiver_cases()
    for case in cases:  # warm up
        case.run(max(1, args.frames // 10), settings)
    for _ in range(args.rounds):
        for case in cases:
            case.rates.append(case.run(args.frames, settings))
    rows = [
        "| Receiver workload                   | frames/s (median) | us/frame |"
        " min..max frames/s |",
        "|-------------------------------------|-------------------|----------|"
        "-------------------|",
    ]
    for case in cases:
        median = statistics.median(case.rates)
        spread = f"{min(case.rates):,.0f}..{max(case.rates):,.0f}"
        rows.append(f"| {case.name:<35} | {median:>17,.0f} | {1e6 / median:>8.2f} | {spread:>17} |")
    whole = min(statistics.median(case.rates) for case in cases if not case.bytewise)
    verdict = "met" if whole >= TARGET_FRAMES_PER_SECOND else "MISSED"
    return [
        f"(a) receiver: {args.rounds} interleaved rounds of {args.frames} frames per workload",
        "",
        *rows,
        "",
        f"Target: {TARGET_FRAMES_PER_SECOND:,} frames/s fed whole: {verdict} "
        f"(slowest whole: {whole:,.0f}).",
    ]


# -- (b) the pty relay against socat ----------------------------------------------------------

TARGET_RELAY_RATIO = 1.5
"""The issue's target: the relay's round trip at most this many times socat's."""


def serve_relay() -> None:
    """Run an unpaced two-port PtyBus, print its paths, and run until killed."""
    import anyio

    from aiortu.testing import PtyBus

    async def main() -> None:
        async with PtyBus(2) as bus:
            print(" ".join(bus.paths), flush=True)
            await anyio.sleep_forever()

    anyio.run(main)


def round_trips(fd: int, count: int) -> list[float]:
    request = bytes(range(8))
    times = []
    for _ in range(count):
        start = time.perf_counter()
        os.write(fd, request)
        benchlib.read_exactly(fd, 25)
        times.append(time.perf_counter() - start)
    return times


def section_relay(args: argparse.Namespace) -> list[str]:
    import subprocess

    rounds = 3 if args.quick else args.rounds
    count = 200 if args.quick else args.rtts
    medians: dict[str, list[float]] = {"socat pty pair": [], "aiortu PtyBus relay": []}
    means: dict[str, list[float]] = {name: [] for name in medians}
    with benchlib.Children() as children:
        socat_a, socat_b = children.socat_pair()
        relay = children.start(
            [sys.executable, os.path.abspath(__file__), "--serve-relay"],
            stdout=subprocess.PIPE,
            stdin=subprocess.DEVNULL,
        )
        assert relay.stdout is not None
        relay_a, relay_b = relay.stdout.readline().decode().split()
        ends = {}
        for name, (near, far) in zip(
            medians, ((socat_a, socat_b), (relay_a, relay_b)), strict=True
        ):
            children.server("bare", far)  # answers each 8 bytes with 25
            ends[name] = benchlib.open_raw(near)
            round_trips(ends[name], 50)  # warm up
        try:
            for _ in range(rounds):
                for name, fd in ends.items():
                    times = round_trips(fd, count)
                    medians[name].append(statistics.median(times))
                    means[name].append(statistics.fmean(times))
        finally:
            for fd in ends.values():
                os.close(fd)
    socat = statistics.median(medians["socat pty pair"])
    rows = []
    for name, values in medians.items():
        rtt = statistics.median(values)
        spread = f"{min(values) * 1e6:.0f}..{max(values) * 1e6:.0f}"
        rows.append(
            f"| {name:<19} | {rtt * 1e6:>15.0f} | {spread:<12}"
            f" | {statistics.median(means[name]) * 1e6:>11.0f} | {rtt / socat:>7.2f}x |"
        )
    ratio = statistics.median(medians["aiortu PtyBus relay"]) / socat
    verdict = "met" if ratio <= TARGET_RELAY_RATIO else "MISSED"
    return [
        f"(b) relay: 8-byte request, 25-byte reply round trips; {rounds} interleaved rounds of "
        f"{count} round trips per line",
        "",
        "| Line                | RTT us (median) | min..max us  | mean RTT us | vs socat |",
        "|---------------------|-----------------|--------------|-------------|----------|",
        *rows,
        "",
        f"Target: the relay's round trip <= {TARGET_RELAY_RATIO}x socat's: {verdict} "
        f"({ratio:.2f}x).",
    ]


# -- (c) the receiver in a flood of garbage ---------------------------------------------------

FLOOD_BYTES = 1 << 20
FLOOD_SPACING = 4096


@dataclass
class FloodCase:
    """One flood workload: a role, its units and the frame embedded in the garbage."""

    name: str
    role: Role
    units: tuple[int, ...]
    frame: bytes
    rates: list[float] = field(default_factory=list)
    found: int = 0
    others: int = 0
    embedded: int = 0

    def run(self, total: int, settings: LineSettings, seed: int) -> float:
        """Feed the flood once; return bytes per second of CPU time."""
        import random

        rng = random.Random(seed)
        parts = []
        self.embedded = 0
        while sum(map(len, parts)) < total:
            parts.append(rng.randbytes(FLOOD_SPACING))
            parts.append(self.frame)
            self.embedded += 1
        parts.append(rng.randbytes(FLOOD_SPACING))
        stream = b"".join(parts)
        chunks = []
        position = 0
        while position < len(stream):
            size = rng.randint(1, 1024)
            chunks.append(stream[position : position + size])
            position += size
        char = settings.char_time
        times = []
        now = 1.0
        for chunk in chunks:
            now += len(chunk) * char
            times.append(now)
        receiver = Receiver(settings, role=self.role, units=self.units)
        feed = receiver.feed
        frames = []
        start = time.process_time()
        for chunk, when in zip(chunks, times, strict=True):
            for event in feed(chunk, when):
                if type(event) is FrameReceived:
                    frames.append(event.frame)
        elapsed = time.process_time() - start
        self.found = frames.count(self.frame)
        self.others = len(frames) - self.found
        return len(stream) / elapsed


def flood_cases() -> list[FloodCase]:
    request = encode_frame(1, ReadHoldingRegistersRequest(0, 10).encode())
    reply = encode_frame(1, ReadHoldingRegistersResponse(tuple(range(10))).encode())
    return [
        FloodCase("SLAVE, unit 1", Role.SLAVE, (1,), request),
        FloodCase("SLAVE, units 1..247", Role.SLAVE, tuple(range(1, 248)), request),
        FloodCase("MASTER", Role.MASTER, (), reply),
        FloodCase("MONITOR", Role.MONITOR, (), reply),
    ]


def section_flood(args: argparse.Namespace) -> list[str]:
    settings = LineSettings(19200, parity="N", stopbits=2)
    rounds = 3 if args.quick else max(3, args.rounds // 3)
    total = FLOOD_BYTES // 4 if args.quick else FLOOD_BYTES
    cases = flood_cases()
    for index in range(rounds):
        for case in cases:
            case.rates.append(case.run(total, settings, seed=index))
    rows = [
        "| Receiver in a flood  | garbage KiB/s (median) | us/byte | min..max KiB/s  |"
        " embedded frames received | other frames |",
        "|----------------------|------------------------|---------|-----------------|"
        "--------------------------|--------------|",
    ]
    for case in cases:
        median = statistics.median(case.rates)
        spread = f"{min(case.rates) / 1024:,.0f}..{max(case.rates) / 1024:,.0f}"
        rows.append(
            f"| {case.name:<20} | {median / 1024:>22,.0f} | {1e6 / median:>7.3f} | {spread:<15} |"
            f" {f'{case.found} / {case.embedded}':>24} | {case.others:>12} |"
        )
    return [
        f"(c) flood: {rounds} interleaved rounds of {total // 1024} KiB of random bytes, a frame "
        f"glued in after every {FLOOD_SPACING} bytes, random chunks of 1..1024 bytes; the "
        "frame counts are from the last round",
        "",
        *rows,
    ]


SECTIONS: dict[str, Callable[[argparse.Namespace], list[str]]] = {
    "receiver": section_receiver,
    "relay": section_relay,
    "flood": section_flood,
}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--rounds", type=int, default=15)
    parser.add_argument("--frames", type=int, default=2000)
    parser.add_argument("--rtts", type=int, default=1000, help="round trips per relay round")
    parser.add_argument("--quick", action="store_true", help="a short smoke run (relay)")
    parser.add_argument("--serve-relay", action="store_true", help=argparse.SUPPRESS)
    benchlib.add_section_argument(parser, SECTIONS)
    args = parser.parse_args()
    if args.serve_relay:
        serve_relay()
        return
    benchlib.run_sections(args, SECTIONS)


if __name__ == "__main__":
    main()

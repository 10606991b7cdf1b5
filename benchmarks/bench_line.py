"""Benchmark of one serial line's moving parts.

Run from the repository root with aiortu installed::

    python benchmarks/bench_line.py [--rounds 15] [--frames 2000]

Sections (each a function ``section_*`` returning the lines it prints; add a section by
writing one more and listing it in ``SECTIONS``):

(a) receiver: frames per second through the sans-IO receiver, for an 8-byte request
    (read holding registers, role SLAVE, addressed to the slave's unit) and a 25-byte reply
    (10 registers, role MASTER), fed whole (one ``feed()`` per frame, as a driver hands
    over a frame that arrived in one chunk) and fed byte by byte (one ``feed()`` per byte,
    the worst case of a driver that wakes per character). Frames are spaced by t3.5 at
    19200 baud, so every frame starts from IDLE; each frame is checked to come out.
    Contenders are timed interleaved round by round; the table gives the median.
"""

from __future__ import annotations

import argparse
import datetime
import os
import platform
import shlex
import statistics
import sys
import time
from collections.abc import Callable
from dataclasses import dataclass, field

from aiortu.core.frame import encode_frame
from aiortu.core.pdu_registers import ReadHoldingRegistersRequest, ReadHoldingRegistersResponse
from aiortu.core.receiver import FrameReceived, Receiver, Role
from aiortu.core.timing import LineSettings

TARGET_FRAMES_PER_SECOND = 50_000
"""The issue's target for frames fed whole."""


def cpu_model() -> str:
    try:
        with open("/proc/cpuinfo", encoding="utf-8") as cpuinfo:
            for line in cpuinfo:
                if line.startswith("model name"):
                    return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or "unknown CPU"


def header() -> list[str]:
    return [
        f"Date: {datetime.date.today().isoformat()}",
        f"Machine: {platform.platform()}; {cpu_model()}, {os.cpu_count()} logical CPUs",
        f"Python: {platform.python_implementation()} {platform.python_version()}",
        "Command: " + shlex.join(["python", *sys.argv]),
    ]


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


SECTIONS: dict[str, Callable[[argparse.Namespace], list[str]]] = {
    "receiver": section_receiver,
}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--rounds", type=int, default=15)
    parser.add_argument("--frames", type=int, default=2000)
    parser.add_argument(
        "--section", action="append", choices=sorted(SECTIONS), help="run only these sections"
    )
    args = parser.parse_args()
    print("\n".join(header()))
    for name in args.section or list(SECTIONS):
        print()
        print("\n".join(SECTIONS[name](args)))


if __name__ == "__main__":
    main()

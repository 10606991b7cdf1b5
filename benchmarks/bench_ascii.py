"""Benchmark of the sans-IO ASCII receiver, beside the RTU receiver on the same frames.

Run from the repository root with aiortu installed::

    python benchmarks/bench_ascii.py [--rounds 15] [--frames 5000]

Workloads: a read-holding-registers request (17 characters in ASCII, 8 bytes in RTU) and its
reply of 10 registers (51 characters, 25 bytes), fed whole (one ``feed()`` per frame, as a
driver hands over a frame that arrived in one chunk) and character by character (one
``feed()`` per character, the worst case). Frames are spaced by the time they take at 9600
baud plus a little, so each one starts from IDLE; each is checked to come out. The RTU rows
(the RTU receiver as a slave and a master) are the reference. Workloads are timed
interleaved round by round; the table gives the median frames per second of wall time and
the median CPU time per frame (``process_time``), which moves less with a shared machine's
load; the target is checked on CPU time.
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

from aiortu.core.ascii import AsciiFrameReceived, AsciiReceiver, encode_ascii_frame
from aiortu.core.pdu import ReadHoldingRegistersRequest, ReadHoldingRegistersResponse
from aiortu.core.rtu import FrameReceived, Receiver, Role, encode_frame
from aiortu.core.serial import LineSettings

TARGET_FRAMES_PER_SECOND = 50_000
"""The target for the ASCII receiver, frames fed whole."""


@dataclass
class Case:
    """One workload: a frame, a receiver factory, and whether it is fed character by character."""

    name: str
    frame: bytes
    make: Callable[[], Receiver | AsciiReceiver]
    bytewise: bool
    ascii: bool
    rates: list[float] = field(default_factory=list)
    cpu_us: list[float] = field(default_factory=list)

    def run(self, frames: int) -> None:
        """Feed `frames` copies; record frames per second and CPU per frame."""
        receiver = self.make()
        feed = receiver.feed
        char = receiver.char_time
        spacing = (len(self.frame) + 4) * char
        wanted = AsciiFrameReceived if self.ascii else FrameReceived
        pieces = (
            [self.frame[index : index + 1] for index in range(len(self.frame))]
            if self.bytewise
            else [self.frame]
        )
        offsets = [index * char for index in range(len(pieces))]
        received = 0
        now = 1.0
        start, cpu = time.perf_counter(), time.process_time()
        for _ in range(frames):
            for piece, offset in zip(pieces, offsets, strict=True):
                for event in feed(piece, now + offset):
                    received += type(event) is wanted
            now += spacing
        elapsed, cpu = time.perf_counter() - start, time.process_time() - cpu
        if received != frames:
            raise AssertionError(f"{self.name}: {received} of {frames} frames received")
        self.rates.append(frames / elapsed)
        self.cpu_us.append(cpu / frames * 1e6)


def cases() -> list[Case]:
    request = ReadHoldingRegistersRequest(0x6B, 10).encode()
    reply = ReadHoldingRegistersResponse(tuple(range(10))).encode()
    ascii_request, ascii_reply = encode_ascii_frame(17, request), encode_ascii_frame(17, reply)
    rtu_request, rtu_reply = encode_frame(17, request), encode_frame(17, reply)
    assert (len(ascii_request), len(ascii_reply)) == (17, 51)
    settings = LineSettings(9600)
    ascii_settings = LineSettings(9600, bytesize=7)

    def ascii_receiver() -> AsciiReceiver:
        return AsciiReceiver(ascii_settings)

    def rtu_slave() -> Receiver:
        return Receiver(settings, role=Role.SLAVE, units=(17,))

    def rtu_master() -> Receiver:
        return Receiver(settings, role=Role.MASTER)

    return [
        Case("ASCII request (17 chars), whole", ascii_request, ascii_receiver, False, True),
        Case("ASCII reply (51 chars), whole", ascii_reply, ascii_receiver, False, True),
        Case("ASCII request, char by char", ascii_request, ascii_receiver, True, True),
        Case("ASCII reply, char by char", ascii_reply, ascii_receiver, True, True),
        Case("RTU request (8 bytes), SLAVE, whole", rtu_request, rtu_slave, False, False),
        Case("RTU reply (25 bytes), MASTER, whole", rtu_reply, rtu_master, False, False),
    ]


def section_receiver(args: argparse.Namespace) -> list[str]:
    workloads = cases()
    for case in workloads:  # warm up, and drop the warm-up's figures
        case.run(max(1, args.frames // 10))
        case.rates.clear()
        case.cpu_us.clear()
    for _ in range(args.rounds):
        for case in workloads:
            case.run(args.frames)
    rows = [
        [
            case.name,
            f"{statistics.median(case.rates):,.0f}",
            f"{statistics.median(case.cpu_us):.2f}",
            f"{min(case.rates):,.0f}..{max(case.rates):,.0f}",
        ]
        for case in workloads
    ]
    # The verdict is on CPU time, which moves less with a shared machine's load than wall time.
    whole = min(
        1e6 / statistics.median(case.cpu_us)
        for case in workloads
        if case.ascii and not case.bytewise
    )
    verdict = "met" if whole >= TARGET_FRAMES_PER_SECOND else "MISSED"
    return [
        f"ASCII receiver: {args.rounds} interleaved rounds of {args.frames} frames per workload",
        "",
        benchlib.table(
            ["Workload", "frames/s (median)", "CPU us/frame", "min..max frames/s"], rows
        ),
        "",
        f"Target: {TARGET_FRAMES_PER_SECOND:,} ASCII frames/s fed whole: {verdict} "
        f"(slowest whole: {whole:,.0f} frames per CPU second).",
    ]


SECTIONS = {"receiver": section_receiver}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--rounds", type=int, default=15)
    parser.add_argument("--frames", type=int, default=5000)
    benchlib.add_section_argument(parser, SECTIONS)
    benchlib.run_sections(parser.parse_args(), SECTIONS)


if __name__ == "__main__":
    main()

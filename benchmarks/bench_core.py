"""Benchmark of the sans-IO core against pymodbus: CRC throughput and register PDU codec.

Run from the repository root with aiortu and pymodbus installed::

    python benchmarks/bench_core.py [--rounds 15] [--target-ms 20]

Every contender of a group is timed in the same run, interleaved round by round
(A B C A B C ...), so that drifts of a shared machine (frequency, other load) hit them all
alike. Each round runs a contender for about ``--target-ms`` of wall time; the table shows the
median over the rounds of the time per call (wall clock, ``perf_counter_ns``) and of the CPU
time per call (``process_time_ns``), and the ratio to pymodbus.

(a) CRC-16/MODBUS on 256-byte and 8-byte inputs: aiortu's ``crc16``, the plain byte loop
    over its 256-entry table (to show what the word table adds), pymodbus's
    ``FramerRTU.compute_CRC``, and the CRC packages from PyPI that happen to be installed
    (fastcrc, crcmod, anycrc, crc): they were the candidates for a compiled dependency.
    Also each one on a 23-byte input (a 10-register reply without its CRC), one call at a
    time right after 16 MB have been written through the CPU caches, as happens between
    two frames on a busy machine: the median of ``20 x --rounds`` such calls.
(b) A read-holding-registers response of 125 registers, bytes to a Python list of ints and
    back: aiortu's ``ReadHoldingRegistersResponse(values).encode()`` and
    ``decode_response(pdu)``, against pymodbus's ``ReadHoldingRegistersResponse`` encoded
    with ``.encode()`` (plus the function code byte that aiortu's PDU includes) and decoded
    through ``DecodePDU.decode`` (what its framer calls) and through the class's own
    ``.decode()`` (the least work pymodbus can do).
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

from aiortu.core.pdu import ReadHoldingRegistersResponse, decode_response
from aiortu.core.rtu import _crc as crc_module
from aiortu.core.rtu import crc16

Call = Callable[[], object]


@dataclass
class Contender:
    """One function timed in a group: its name and a zero-argument call."""

    name: str
    call: Call
    number: int = 0
    wall_ns: list[float] = field(default_factory=list)
    cpu_ns: list[float] = field(default_factory=list)
    cold_ns: list[float] = field(default_factory=list)

    @property
    def wall(self) -> float:
        return statistics.median(self.wall_ns)

    @property
    def cpu(self) -> float:
        return statistics.median(self.cpu_ns)


def calibrate(call: Call, target_ns: float) -> int:
    """How many calls make one round last about *target_ns*."""
    number = 1
    while True:
        start = time.perf_counter_ns()
        for _ in range(number):
            call()
        elapsed = time.perf_counter_ns() - start
        if elapsed >= target_ns / 4:
            return max(1, round(number * target_ns / elapsed))
        number *= 4


def run_group(contenders: list[Contender], rounds: int, target_ms: float) -> None:
    """Time every contender *rounds* times, interleaved, in calls per round set once."""
    for contender in contenders:
        contender.call()  # warm up: lazy tables, caches
        contender.number = calibrate(contender.call, target_ms * 1e6)
    for _ in range(rounds):
        for contender in contenders:
            call = contender.call
            loop = range(contender.number)
            cpu_start = time.process_time_ns()
            start = time.perf_counter_ns()
            for _ in loop:
                call()
            wall = time.perf_counter_ns() - start
            cpu = time.process_time_ns() - cpu_start
            contender.wall_ns.append(wall / contender.number)
            contender.cpu_ns.append(cpu / contender.number)


_FLUSHED = bytearray(16 * 1024 * 1024)


def flush_caches() -> None:
    """Write 16 MB a cache line at a time: what the other processes of a busy machine do
    to the CPU caches between two frames of a master or a slave."""
    _FLUSHED[::64] = bytes(len(_FLUSHED) // 64)


def run_cold(contenders: list[Contender], samples: int) -> None:
    """Time single calls, each right after :func:`flush_caches`, interleaved."""
    for _ in range(samples):
        for contender in contenders:
            flush_caches()
            start = time.perf_counter_ns()
            contender.call()
            contender.cold_ns.append(time.perf_counter_ns() - start)


# (a) CRC


def byte_loop_crc16(data: bytes) -> int:
    """aiortu's CRC without the word table: what the 65536-entry table saves."""
    table = crc_module._TABLE
    crc = 0xFFFF
    for byte in data:
        crc = (crc >> 8) ^ table[(crc ^ byte) & 0xFF]
    return crc


def crc_contenders(data: bytes) -> list[Contender]:
    """aiortu, pymodbus, and every CRC package installed; each checked on *data* first."""
    from pymodbus.framer.rtu import FramerRTU

    expected = crc16(data)
    found: list[tuple[str, Callable[[bytes], int]]] = [
        ("aiortu crc16", crc16),
        ("aiortu byte loop only (reference)", byte_loop_crc16),
        # pymodbus returns the CRC byte-swapped, ready to write big-endian.
        ("pymodbus FramerRTU.compute_CRC", FramerRTU.compute_CRC),
    ]
    try:
        import fastcrc

        found.append(("fastcrc (Rust)", fastcrc.crc16.modbus))
    except ImportError:
        pass
    try:
        import crcmod.predefined
        from crcmod import crcmod as crcmod_impl

        kind = "C" if crcmod_impl._usingExtension else "pure Python"
        found.append((f"crcmod ({kind})", crcmod.predefined.mkPredefinedCrcFun("modbus")))
    except ImportError:
        pass
    try:
        import anycrc  # type: ignore[import-untyped]

        found.append(("anycrc (C)", anycrc.Model("CRC16-MODBUS").calc))
    except ImportError:
        pass
    try:
        import crc as crc_package

        found.append(
            ("crc (pure Python)", crc_package.Calculator(crc_package.Crc16.MODBUS.value).checksum)
        )
    except ImportError:
        pass
    contenders = []
    for name, function in found:
        result = function(data)
        if name.startswith("pymodbus"):
            result = (result & 0xFF) << 8 | result >> 8
        if result != expected:
            raise SystemExit(f"{name} gives 0x{result:04X}, expected 0x{expected:04X}")
        contenders.append(Contender(name, lambda function=function: function(data)))  # type: ignore[misc]
    return contenders


def bench_crc(rounds: int, target_ms: float) -> str:
    frames = {
        256: bytes((37 * i + 11) & 0xFF for i in range(256)),
        8: bytes.fromhex("11 03 00 6B 00 03 76 87"),
    }
    results = {}
    for size, data in frames.items():
        group = crc_contenders(data)
        run_group(group, rounds, target_ms)
        results[size] = {contender.name: contender for contender in group}
    # A 10-register reply without its CRC, one call at a time with cold caches.
    reply = bytes.fromhex("01 03 14") + bytes(range(20))
    cold = crc_contenders(reply)
    run_cold(cold, 20 * rounds)
    cold_us = {contender.name: statistics.median(contender.cold_ns) / 1000 for contender in cold}
    pymodbus = "pymodbus FramerRTU.compute_CRC"
    rows = []
    for name in results[256]:
        large, small = results[256][name], results[8][name]
        rows.append(
            [
                name,
                f"{large.wall / 1000:.2f}",
                f"{256 * 1000 / large.wall:.1f}",
                f"{results[256][pymodbus].wall / large.wall:.2f}x",
                f"{small.wall:.0f}",
                f"{results[8][pymodbus].wall / small.wall:.2f}x",
                f"{cold_us[name]:.1f}",
                f"{cold_us[pymodbus] / cold_us[name]:.2f}x",
            ]
        )
    headers = [
        "CRC-16/MODBUS",
        "256 B: us/frame",
        "256 B: MB/s",
        "vs pymodbus",
        "8 B: ns/frame",
        "vs pymodbus",
        "23 B, caches flushed: us",
        "vs pymodbus",
    ]
    return benchlib.table(headers, rows)


# (b) Read holding registers response, 125 registers


def register_contenders(values: list[int]) -> tuple[list[Contender], list[Contender]]:
    """Encode contenders and decode contenders, each checked against the other side first."""
    from pymodbus.pdu import DecodePDU
    from pymodbus.pdu.register_message import ReadHoldingRegistersResponse as PymodbusResponse

    function_code = bytes((PymodbusResponse.function_code,))
    decoder = DecodePDU(is_server=False)

    def aiortu_encode() -> bytes:
        return ReadHoldingRegistersResponse(values).encode()  # type: ignore[arg-type]

    def pymodbus_encode() -> bytes:
        return function_code + PymodbusResponse(registers=values).encode()

    pdu = aiortu_encode()
    if pdu != pymodbus_encode():
        raise SystemExit("aiortu and pymodbus encode the response differently")

    def aiortu_decode() -> list[int]:
        response = decode_response(pdu)
        assert isinstance(response, ReadHoldingRegistersResponse)
        return list(response.values)

    def pymodbus_decode() -> list[int]:
        response = decoder.decode(pdu)
        assert response is not None
        return list(response.registers)

    def pymodbus_class_decode() -> list[int]:
        response = PymodbusResponse()
        response.decode(pdu[1:])
        return list(response.registers)

    for decode in (aiortu_decode, pymodbus_decode, pymodbus_class_decode):
        if decode() != values:
            raise SystemExit(f"{decode.__name__} does not give the values back")
    encoders = [Contender("aiortu", aiortu_encode), Contender("pymodbus", pymodbus_encode)]
    decoders = [
        Contender("aiortu decode_response", aiortu_decode),
        Contender("pymodbus DecodePDU.decode", pymodbus_decode),
        Contender("pymodbus class .decode()", pymodbus_class_decode),
    ]
    return encoders, decoders


def bench_registers(rounds: int, target_ms: float) -> str:
    values = [(40503 * i + 7) & 0xFFFF for i in range(125)]
    encoders, decoders = register_contenders(values)
    run_group(encoders + decoders, rounds, target_ms)
    aiortu_encode, pymodbus_encode = encoders
    aiortu_decode = decoders[0]
    rows = [
        [
            "encode: list -> PDU bytes",
            f"{aiortu_encode.wall / 1000:.2f}",
            "pymodbus",
            f"{pymodbus_encode.wall / 1000:.2f}",
            f"{pymodbus_encode.wall / aiortu_encode.wall:.2f}x",
            f"{pymodbus_encode.cpu / aiortu_encode.cpu:.2f}x",
        ]
    ]
    for other in decoders[1:]:
        rows.append(
            [
                "decode: PDU bytes -> list",
                f"{aiortu_decode.wall / 1000:.2f}",
                other.name,
                f"{other.wall / 1000:.2f}",
                f"{other.wall / aiortu_decode.wall:.2f}x",
                f"{other.cpu / aiortu_decode.cpu:.2f}x",
            ]
        )
    for other in decoders[1:]:
        encode_decode = aiortu_encode.wall + aiortu_decode.wall
        theirs = pymodbus_encode.wall + other.wall
        encode_decode_cpu = aiortu_encode.cpu + aiortu_decode.cpu
        theirs_cpu = pymodbus_encode.cpu + other.cpu
        rows.append(
            [
                "encode + decode",
                f"{encode_decode / 1000:.2f}",
                f"pymodbus encode + {other.name.removeprefix('pymodbus ')}",
                f"{theirs / 1000:.2f}",
                f"{theirs / encode_decode:.2f}x",
                f"{theirs_cpu / encode_decode_cpu:.2f}x",
            ]
        )
    headers = [
        "125 registers (FC 03 response)",
        "aiortu us",
        "pymodbus way",
        "pymodbus us",
        "aiortu faster (wall)",
        "(CPU)",
    ]
    return benchlib.table(headers, rows)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n", 1)[0])
    parser.add_argument("--rounds", type=int, default=15, help="interleaved rounds (default 15)")
    parser.add_argument(
        "--target-ms", type=float, default=20.0, help="wall time of one contender's round"
    )
    args = parser.parse_args()
    print("\n".join(benchlib.header()))
    print(f"rounds:   {args.rounds}, interleaved; medians of per-call time\n")
    print(bench_crc(args.rounds, args.target_ms))
    print()
    print(bench_registers(args.rounds, args.target_ms))


if __name__ == "__main__":
    main()

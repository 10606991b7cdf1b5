"""Benchmark of the slave: CPU and throughput against pymodbus's server, and a garbage flood.

Run from the repository root with aiortu, pymodbus and socat installed::

    python benchmarks/bench_slave.py [--quick] [--flood-seconds 60] [--section NAME ...]

Each slave runs in a process of its own (``bench_servers.py``: ``aiortu.serve`` with
``frame_gap=0``, or pymodbus's ``ModbusSerialServer``) on one end of a socat pty pair at
19200 8N2 (ptys keep no parity); its CPU time (user + system) and resident memory are read
from /proc.

(a) throughput: reading 10 holding registers in a loop, interleaved round by round:
    pymodbus's ``AsyncModbusSerialClient`` (the fastest pymodbus client over a pty; its
    sync client waits a timer per request) against the aiortu slave and against pymodbus's
    server, and aiortu's ``Master`` (``frame_gap=0``) against the aiortu slave; and, as the
    reference for what the link allows, a pair with no Modbus logic (a bare asyncio client
    and a blocking responder that sends a fixed reply). The table gives requests/s at the
    client and the slave process's CPU per request (medians).
(b) flood: random bytes written to an aiortu slave as fast as the pty takes them, for
    ``--flood-seconds``; every 4 KiB of garbage a valid read request follows, alternately
    glued to the garbage and after 5 ms of silence. The slave's VmRSS is sampled every
    second; the replies read back are counted.
"""

from __future__ import annotations

import argparse
import asyncio
import os
import statistics
import sys
import threading
import time
from collections.abc import Callable

sys.path.insert(0, __file__.rsplit("/", 1)[0])
import benchlib

import aiortu
from aiortu.core.pdu import (
    ReadHoldingRegistersRequest,
    ReadHoldingRegistersResponse,
)
from aiortu.core.rtu import encode_frame

EXPECTED = list(range(10))
REQUEST = encode_frame(1, ReadHoldingRegistersRequest(0, 10).encode())
REPLY = encode_frame(1, ReadHoldingRegistersResponse(tuple(EXPECTED)).encode())
REFERENCE = "reference: bare asyncio client -> bare responder"
"""No Modbus logic at either end: what the pty pair allows any pair of programs."""
PTY = {"baudrate": 19200, "parity": "N", "stopbits": 2}


def verdict(met: bool) -> str:
    return "met" if met else "MISSED"


def quiet_pymodbus() -> None:
    import logging
    import warnings

    warnings.filterwarnings("ignore")
    logging.getLogger("pymodbus").setLevel(logging.CRITICAL)


async def pymodbus_client(port: str, requests: int) -> float:
    from pymodbus.client import AsyncModbusSerialClient

    client = AsyncModbusSerialClient(port, timeout=1.0, retries=0, **PTY)
    await client.connect()
    try:
        for _ in range(20):
            await client.read_holding_registers(0, count=10, device_id=1)
        start = time.perf_counter()
        for _ in range(requests):
            reply = await client.read_holding_registers(0, count=10, device_id=1)
            if reply.registers != EXPECTED:
                raise AssertionError("wrong registers")
        return time.perf_counter() - start
    finally:
        client.close()


async def aiortu_client(port: str, requests: int) -> float:
    async with aiortu.open_master(port, frame_gap=0, timeout=1.0, **PTY) as master:
        for _ in range(20):
            await master.read_holding_registers(1, 0, 10)
        start = time.perf_counter()
        for _ in range(requests):
            if await master.read_holding_registers(1, 0, 10) != EXPECTED:
                raise AssertionError("wrong registers")
        return time.perf_counter() - start


async def reference_client(port: str, requests: int) -> float:
    rate, _ = await benchlib.bare_asyncio_reads(port, REQUEST, REPLY, requests)
    return requests / rate


def timed(run: Callable[[], float], pid: int, requests: int) -> tuple[float, float]:
    """Return (requests/s, slave CPU seconds per request) of one round."""
    before = benchlib.cpu_seconds(pid)
    wall = run()
    return requests / wall, (benchlib.cpu_seconds(pid) - before) / requests


def section_throughput(args: argparse.Namespace) -> list[str]:
    quiet_pymodbus()
    requests = 300 if args.quick else 2000
    rounds = 2 if args.quick else 9
    results: dict[str, list[tuple[float, float]]] = {}
    with benchlib.Children() as children:
        ours_client, ours_server = children.socat_pair()
        theirs_client, theirs_server = children.socat_pair()
        bare_client, bare_server = children.socat_pair()
        ours = children.server("aiortu", ours_server, "--frame-gap", "0")
        theirs = children.server("pymodbus", theirs_server)
        bare = children.server("bare", bare_server)
        contenders = {
            "pymodbus client -> aiortu slave": (
                lambda: asyncio.run(pymodbus_client(ours_client, requests)),
                ours.pid,
            ),
            "pymodbus client -> pymodbus server": (
                lambda: asyncio.run(pymodbus_client(theirs_client, requests)),
                theirs.pid,
            ),
            "aiortu master -> aiortu slave": (
                lambda: asyncio.run(aiortu_client(ours_client, requests)),
                ours.pid,
            ),
            REFERENCE: (lambda: asyncio.run(reference_client(bare_client, requests)), bare.pid),
        }
        for _ in range(rounds):
            for name, (run, pid) in contenders.items():
                results.setdefault(name, []).append(timed(run, pid, requests))
    rate = {name: statistics.median(r for r, _ in rs) for name, rs in results.items()}
    cpu = {name: statistics.median(c for _, c in rs) for name, rs in results.items()}
    reference = "pymodbus client -> pymodbus server"
    rows = [
        [
            name,
            f"{rate[name]:,.0f}",
            f"{min(r for r, _ in rs):,.0f}..{max(r for r, _ in rs):,.0f}",
            f"{rate[name] / rate[reference]:.2f}x",
            f"{cpu[name] * 1e6:.0f}",
            f"{cpu[name] / cpu[reference]:.2f}x",
        ]
        for name, rs in results.items()
    ]
    slave = "pymodbus client -> aiortu slave"
    both = "aiortu master -> aiortu slave"
    cpu_ratio = cpu[slave] / cpu[reference]
    rate_ratio = rate[slave] / rate[reference]
    pair_ratio = rate[both] / rate[reference]
    ceiling = rate[REFERENCE] / rate[reference]
    return [
        f"(a) throughput: 10 holding registers over socat pty pairs, slaves in their own "
        f"processes (aiortu with frame_gap=0); {rounds} interleaved rounds of {requests} reads",
        "",
        benchlib.table(
            [
                "Client -> slave",
                "requests/s (median)",
                "min..max",
                "vs pymodbus pair",
                "slave CPU us/request",
                "slave CPU vs pymodbus server",
            ],
            rows,
        ),
        "",
        f"Targets: aiortu slave CPU per request <= 0.5x pymodbus's: {verdict(cpu_ratio <= 0.5)} "
        f"({cpu_ratio:.2f}x); its requests/s >= 1.2x: {verdict(rate_ratio >= 1.2)} "
        f"({rate_ratio:.2f}x); aiortu master + slave >= 2x the pymodbus pair's requests/s: "
        f"{verdict(pair_ratio >= 2)} ({pair_ratio:.2f}x). The reference pair with no Modbus "
        f"logic reaches {ceiling:.2f}x on the same link.",
    ]


# -- (b) garbage flood --------------------------------------------------------------------------


def request_and_reply(address: int) -> tuple[bytes, bytes]:
    request = encode_frame(1, ReadHoldingRegistersRequest(address, 10).encode())
    values = tuple(range(address, address + 10))
    return request, encode_frame(1, ReadHoldingRegistersResponse(values).encode())


def section_flood(args: argparse.Namespace) -> list[str]:
    seconds = args.flood_seconds if args.flood_seconds is not None else (5 if args.quick else 60)
    glued_request, glued_reply = request_and_reply(0)
    paused_request, paused_reply = request_and_reply(20)
    sent = {"glued": 0, "paused": 0, "garbage": 0}
    received = bytearray()
    stop = threading.Event()
    rss: list[tuple[float, int]] = []
    with benchlib.Children() as children:
        client_port, server_port = children.socat_pair()
        slave = children.server("aiortu", server_port, "--frame-gap", "0")
        fd = benchlib.open_raw(client_port)

        def reader() -> None:
            while not stop.is_set():
                try:
                    chunk = os.read(fd, 65536)
                except OSError:
                    return
                received.extend(chunk)

        def writer() -> None:
            turn = 0
            while not stop.is_set():
                garbage = os.urandom(4096)
                os.write(fd, garbage)
                sent["garbage"] += len(garbage)
                if turn % 2 == 0:
                    os.write(fd, glued_request)
                    sent["glued"] += 1
                else:
                    time.sleep(0.005)
                    os.write(fd, paused_request)
                    sent["paused"] += 1
                    time.sleep(0.005)
                turn += 1

        threads = [threading.Thread(target=reader, daemon=True)]
        threads.append(threading.Thread(target=writer, daemon=True))
        try:
            os.write(fd, paused_request)  # the slave is up and answering
            time.sleep(0.5)
            baseline = benchlib.rss_kib(slave.pid)
            cpu_before = benchlib.cpu_seconds(slave.pid)
            start = time.monotonic()
            rss.append((0.0, baseline))
            for thread in threads:
                thread.start()
            while (elapsed := time.monotonic() - start) < seconds:
                time.sleep(min(1.0, seconds - elapsed))
                rss.append((time.monotonic() - start, benchlib.rss_kib(slave.pid)))
            stop.set()
            threads[1].join(5)
            elapsed = time.monotonic() - start
            cpu = benchlib.cpu_seconds(slave.pid) - cpu_before
            time.sleep(0.5)  # the last replies
            after = benchlib.rss_kib(slave.pid)
            rss.append((time.monotonic() - start, after))
        finally:
            stop.set()
            os.close(fd)
            children.stop_all()
            threads[0].join(5)
    data = bytes(received)
    glued_answered = data.count(glued_reply)
    paused_answered = data.count(paused_reply) - 1  # minus the one before the flood
    peak = max(kib for _, kib in rss)
    growth_mib = (peak - baseline) / 1024
    rows = [
        [
            f"{seconds:g} s",
            f"{sent['garbage'] / elapsed / 1024:,.0f}",
            f"{cpu / elapsed:.0%}",
            f"{baseline / 1024:.1f}",
            f"{rss[len(rss) // 2][1] / 1024:.1f}",
            f"{after / 1024:.1f}",
            f"{peak / 1024:.1f}",
            f"{growth_mib:+.2f}",
            f"{glued_answered} / {sent['glued']}",
            f"{paused_answered} / {sent['paused']}",
        ]
    ]
    answered = glued_answered + paused_answered
    return [
        "(b) flood: random bytes at an aiortu slave process as fast as the pty takes them; "
        "a valid request after every 4 KiB, alternately glued to the garbage and after 5 ms "
        "of silence",
        "",
        benchlib.table(
            [
                "Duration",
                "garbage KiB/s",
                "slave CPU",
                "VmRSS start MiB",
                "middle",
                "end",
                "peak",
                "growth MiB",
                "glued requests answered",
                "after silence answered",
            ],
            rows,
        ),
        "",
        f"Targets: VmRSS grows by less than 5 MB: {verdict(growth_mib * 1.048576 < 5)} "
        f"({growth_mib * 1.048576:+.2f} MB); valid requests mixed in are still answered: "
        f"{verdict(answered > 0)} ({answered} of {sent['glued'] + sent['paused']}).",
    ]


SECTIONS: dict[str, Callable[[argparse.Namespace], list[str]]] = {
    "throughput": section_throughput,
    "flood": section_flood,
}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--quick", action="store_true", help="a short smoke run")
    parser.add_argument(
        "--flood-seconds", type=float, default=None, help="flood duration (default 60, quick 5)"
    )
    benchlib.add_section_argument(parser, SECTIONS)
    benchlib.run_sections(parser.parse_args(), SECTIONS)


if __name__ == "__main__":
    main()

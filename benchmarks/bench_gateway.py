"""The line server (`aiortu gateway`) against mbusd, a C Modbus TCP to RTU gateway.

    python benchmarks/bench_gateway.py [--mbusd PATH] [--rounds 3] [--seconds 4]
        [--section unpaced|paced|coalescing|dead-unit] [--rates 19200:8N2,115200:8N1]
        [--clients 1,8,32] [--baseline SRC]

Both gateways run as processes of their own (so that their CPU time can be read from
/proc) and forward to the same pymodbus RTU server (`bench_servers.py pymodbus`, unit 1,
or units 1..N) at 19200 8N2. mbusd runs with `-R 1` (its shortest pause between requests),
`-N 0` (no retries) and `-W 500`; the aiortu gateway with `--retries 0 --timeout 0.5`.
The clients are Modbus TCP connections of this process (asyncio, raw sockets), each sending
a read of 10 holding registers and waiting for its reply, for `--seconds` per run; the
contenders alternate (A B A B ...) for `--rounds` rounds and the tables give medians.

Sections:

- `unpaced`: a socat pty pair (no pacing), 1, 8 and 32 clients (`--clients`), at each of
  `--rates` (the line settings both gateways and the server are given: 19200 8N2, and 115200
  8N1, where mbusd's own per-request cost is not hidden by its waits): requests/s, the
  gateway's CPU per request, p99 latency, and fairness (the largest deviation of a client's
  request count from the mean of all clients); the aiortu gateway also with `--frame-gap
  0.001`, the same 1 ms of silence before a request as mbusd's `-R 1`. With `--baseline SRC`
  (the `src` folder of another checkout), that tree's gateway runs too, as `base` rows, in
  the same interleaved rounds: before and after a change in one table.
- `paced`: an [`aiortu.testing.PtyBus`] paced at 19200 8N2, 8 clients: the share of the
  wire limit, and the silences before each request on the bus trace against t3.5.
- `coalescing`: the paced bus, 32 clients reading the same block: requests/s served
  against transactions/s on the wire (from the bus trace).
- `dead-unit`: the socat pair to aiortu's slave (`bench_servers.py aiortu`: pymodbus's
  server answers an absent unit with exception 04 instead of silence), 8 clients polling
  units 1..10 in turn, unit 10 absent or present: the other units' requests/s after the
  first cycles.

mbusd is built by `../shared/peers/build-mbusd.sh` (the default `--mbusd` path is where
it puts it); without it the mbusd rows are left out.
"""

from __future__ import annotations

import argparse
import asyncio
import contextlib
import itertools
import os
import socket
import struct
import subprocess
import sys
import time
from collections.abc import Iterator, Sequence
from dataclasses import dataclass, field

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import benchlib

BAUDRATE = 19200
CHAR_BITS = 11  # 8N2: start, 8 data, 2 stop
T35 = 3.5 * CHAR_BITS / BAUDRATE
REQUEST_BYTES = 8  # read of 10 holding registers
REPLY_BYTES = 5 + 20
WIRE_LIMIT = 1 / ((REQUEST_BYTES + REPLY_BYTES) * CHAR_BITS / BAUDRATE + 2 * T35)
"""Transactions/s a 19200 8N2 line carries: both frames' characters and t3.5 before each."""
MBUSD = "/tmp/mbusd-build/mbusd"
GAP_1MS = "aiortu, 1 ms gap"
"""The gateway keeping 1 ms of silence before each request (mbusd's `-R 1`), not t3.5."""
BASE = "base"
"""The gateway of the `--baseline` tree (rows named `base`, `base, 1 ms gap`)."""


@dataclass(frozen=True)
class Rate:
    """Line settings for the unpaced runs: a baud rate and 8N1 or 8N2."""

    baudrate: int
    stopbits: int

    @classmethod
    def parse(cls, text: str) -> Rate:
        baudrate, _, form = text.partition(":")
        if form not in ("8N1", "8N2"):
            raise argparse.ArgumentTypeError(f"{text!r}: expected BAUD:8N1 or BAUD:8N2")
        return cls(int(baudrate), int(form[2]))

    def __str__(self) -> str:
        return f"{self.baudrate} 8N{self.stopbits}"


SLOW = Rate(BAUDRATE, 2)


def free_port() -> int:
    with socket.socket() as probe:
        probe.bind(("127.0.0.1", 0))
        return int(probe.getsockname()[1])


def wait_listening(port: int, process: subprocess.Popen[bytes], seconds: float = 20) -> None:
    deadline = time.monotonic() + seconds
    while time.monotonic() < deadline:
        if process.poll() is not None:
            raise RuntimeError(f"{process.args!r} exited with {process.returncode}")
        with contextlib.suppress(OSError), socket.create_connection(("127.0.0.1", port), 0.2):
            return
        time.sleep(0.05)
    raise RuntimeError(f"nothing listens on port {port}")


def start_gateway(
    children: benchlib.Children, name: str, serial: str, args: argparse.Namespace,
    rate: Rate = SLOW, prefix: Sequence[str] = (), wait: float = 20,
) -> tuple[subprocess.Popen[bytes], int]:  # fmt: skip
    """Start gateway *name* (`aiortu`, `GAP_1MS`, `mbusd`, or `BASE`...) on *serial*, its
    command after *prefix* (a tool that runs it); return it and its TCP port once it listens
    (within *wait* seconds)."""
    port = free_port()
    env = None
    if name == "mbusd":
        argv = [args.mbusd, "-d", "-L", "/dev/null", "-v", "0", "-p", serial]
        argv += ["-s", str(rate.baudrate), "-m", f"8N{rate.stopbits}", "-A", "127.0.0.1"]
        argv += ["-P", str(port), "-R", "1", "-N", "0", "-W", "500", "-T", "0", "-C", "64"]
    else:
        argv = [sys.executable, "-m", "aiortu", "gateway", serial]
        argv += ["--listen", f"tcp://127.0.0.1:{port}", "--baudrate", str(rate.baudrate)]
        argv += ["--parity", "N", "--stopbits", str(rate.stopbits), "--retries", "0"]
        argv += ["--timeout", "0.5", "--max-connections", "64"]
        if name.endswith("1 ms gap"):
            argv += ["--frame-gap", "0.001"]
        if name.startswith(BASE):
            env = {**os.environ, "PYTHONPATH": args.baseline}
    process = children.start(
        [*prefix, *argv], stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, env=env
    )
    wait_listening(port, process, wait)
    return process, port


# -- the clients --------------------------------------------------------------------------


@dataclass
class Load:
    """What the clients of one run saw."""

    seconds: float
    counts: list[int]
    latencies: list[float] = field(default_factory=list)
    per_unit: dict[int, int] = field(default_factory=dict)
    errors: int = 0

    @property
    def rate(self) -> float:
        return sum(self.counts) / self.seconds

    @property
    def p99_ms(self) -> float:
        ordered = sorted(self.latencies)
        return ordered[int(0.99 * (len(ordered) - 1))] * 1000 if ordered else float("nan")

    @property
    def unfairness(self) -> float:
        """The largest deviation of a client's count from the mean, as a fraction of it."""
        mean = sum(self.counts) / len(self.counts)
        return max(abs(count - mean) for count in self.counts) / mean if mean else float("nan")


def read_request(transaction: int, unit: int, address: int = 0) -> bytes:
    return struct.pack(">HHHBBHH", transaction, 0, 6, unit, 3, address, 10)


async def _client(
    port: int, units: Sequence[int], stop_at: float, warmup_at: float, load: Load, index: int,
    address: int,
) -> None:  # fmt: skip
    reader, writer = await asyncio.open_connection("127.0.0.1", port)
    transaction = 0
    try:
        while (now := time.perf_counter()) < stop_at:
            unit = units[transaction % len(units)]
            transaction = (transaction + 1) & 0xFFFF
            writer.write(read_request(transaction, unit, address))
            try:
                header = await asyncio.wait_for(reader.readexactly(7), 5)
            except TimeoutError:
                load.errors += 1  # no reply at all: the gateway dropped the request
                break
            body = await reader.readexactly(struct.unpack(">H", header[4:6])[0] - 1)
            if struct.unpack(">H", header[:2])[0] != transaction:
                raise AssertionError("a reply with another transaction id")
            if now < warmup_at:
                continue
            if body[0] & 0x80:
                load.errors += 1
                continue
            load.counts[index] += 1
            load.latencies.append(time.perf_counter() - now)
            load.per_unit[unit] = load.per_unit.get(unit, 0) + 1
    finally:
        writer.close()


def run_clients(
    port: int, clients: int, seconds: float, units: Sequence[int] = (1,), warmup: float = 0.5,
    same_block: bool = False,
) -> Load:  # fmt: skip
    """*clients* connections reading for *warmup* + *seconds*; counts after the warm-up.

    Each client reads a block of its own (addresses 2 * index ...), so that no two requests
    in flight are the same and the gateway cannot coalesce them, or all read the same block.
    """
    load = Load(seconds, [0] * clients)

    async def main() -> None:
        start = time.perf_counter()
        await asyncio.gather(
            *(
                _client(
                    port,
                    units,
                    start + warmup + seconds,
                    start + warmup,
                    load,
                    index,
                    0 if same_block else 2 * index,
                )
                for index in range(clients)
            )
        )

    asyncio.run(main())
    return load


def measure(
    children: benchlib.Children,
    name: str,
    serial: str,
    args: argparse.Namespace,
    clients: int,
    units: Sequence[int] = (1,),
    warmup: float = 0.5,
    same_block: bool = False,
    rate: Rate = SLOW,
) -> tuple[Load, float]:
    """One run: start gateway *name*, load it, stop it. Returns the load and CPU s/request."""
    process, port = start_gateway(children, name, serial, args, rate)
    try:
        run_clients(port, 1, 0.3, units, warmup=0.0)  # the line and the slave warmed up
        cpu = benchlib.cpu_seconds(process.pid)
        load = run_clients(port, clients, args.seconds, units, warmup, same_block)
        cpu = benchlib.cpu_seconds(process.pid) - cpu
    finally:
        children.stop(process)
        children.processes.remove(process)
    total = sum(load.counts) + load.errors
    return load, cpu / total if total else float("nan")


def contenders(args: argparse.Namespace) -> list[str]:
    return ["mbusd", "aiortu"] if os.access(args.mbusd, os.X_OK) else ["aiortu"]


@contextlib.contextmanager
def socat_line(
    units: int = 1, slave: str = "pymodbus", rate: Rate = SLOW
) -> Iterator[tuple[benchlib.Children, str]]:
    """A socat pty pair with pymodbus's RTU server (or aiortu's) on one end, at `rate`; yield
    the other end."""
    with benchlib.Children() as children:
        near, far = children.socat_pair()
        children.server(
            slave, far, "--units", str(units), "--baudrate", str(rate.baudrate),
            "--stopbits", str(rate.stopbits),
        )  # fmt: skip
        yield children, near


@contextlib.contextmanager
def paced_line() -> Iterator[tuple[benchlib.Children, str, object]]:
    """A PtyBus paced at 19200 8N2 with pymodbus's RTU server on port 1."""
    from aiortu.core.serial import LineSettings
    from aiortu.testing import PtyBus

    bus = PtyBus(2, settings=LineSettings(BAUDRATE, 8, "N", 2), trace_size=200_000)
    with bus.running_in_thread(), benchlib.Children() as children:
        children.server("pymodbus", bus.paths[1])
        yield children, bus.paths[0], bus


# -- sections -----------------------------------------------------------------------------


def section_unpaced(args: argparse.Namespace) -> list[str]:
    names = [*contenders(args), GAP_1MS]
    if args.baseline:
        names += [BASE, f"{BASE}, 1 ms gap"]
    rows = []
    for rate in args.rates:
        with socat_line(rate=rate) as (children, serial):
            for clients in args.clients:
                runs: dict[str, list[tuple[Load, float]]] = {name: [] for name in names}
                for _ in range(args.rounds):
                    for name in names:
                        runs[name].append(measure(children, name, serial, args, clients, rate=rate))
                rows += _unpaced_rows(rate, clients, names, runs)
    headers = [
        "line", "clients", "gateway", "requests/s", "vs mbusd", "CPU us/request", "vs mbusd",
        "p99 ms", "vs mbusd", "worst client off mean %",
    ]  # fmt: skip
    return ["### Unpaced (socat pty pair)", "", benchlib.table(headers, rows)]


def _unpaced_rows(
    rate: Rate, clients: int, names: list[str], runs: dict[str, list[tuple[Load, float]]]
) -> list[list[str]]:
    base: dict[str, float] = {}
    rows = []
    for name in names:
        rate_ = benchlib.median([load.rate for load, _ in runs[name]])
        cpu = benchlib.median([cpu for _, cpu in runs[name]]) * 1e6
        p99 = benchlib.median([load.p99_ms for load, _ in runs[name]])
        unfair = max(load.unfairness for load, _ in runs[name]) * 100
        base.setdefault("rate", rate_)
        base.setdefault("cpu", cpu)
        base.setdefault("p99", p99)
        rows.append(
            [
                str(rate), f"{clients}", name, f"{rate_:.0f}", f"{rate_ / base['rate']:.2f}x",
                f"{cpu:.0f}", f"{cpu / base['cpu']:.2f}x", f"{p99:.1f}",
                f"{p99 / base['p99']:.2f}x", f"{unfair:.1f}",
            ]
        )  # fmt: skip
    return rows


def gaps_before(trace: Sequence[object], since: float, sender: int) -> list[float]:
    """The silences on the wire before each burst *sender* started (0: the gateway, 1: the
    slave)."""
    gaps = []
    for before, entry in itertools.pairwise(trace):
        if entry.sender == sender and entry.start >= since:  # type: ignore[attr-defined]
            gaps.append(entry.start - before.end)  # type: ignore[attr-defined]
    return gaps


def wire_transactions(trace: Sequence[object], since: float, until: float) -> float:
    """Requests the gateway put on the wire between *since* and *until*, from its bytes
    (a gateway may write one frame in several bursts)."""
    sent = sum(
        len(entry.data)  # type: ignore[attr-defined]
        for entry in trace
        if entry.sender == 0 and since <= entry.start < until  # type: ignore[attr-defined]
    )
    return sent / REQUEST_BYTES


def _paced_run(
    children: benchlib.Children, serial: str, bus: object, name: str, args: argparse.Namespace,
    clients: int, same_block: bool,
) -> tuple[Load, float, list[float], list[float]]:  # fmt: skip
    """One run on the paced bus: the load, the gateway's frames on the wire, their gaps."""
    import anyio.lowlevel  # noqa: F401  (the bus clock is anyio's: the loop's monotonic)

    process, port = start_gateway(children, name, serial, args)
    try:
        run_clients(port, 1, 0.3, warmup=0.0)
        since = time.monotonic() + 0.5
        load = run_clients(port, clients, args.seconds, warmup=0.5, same_block=same_block)
        until = time.monotonic()
    finally:
        children.stop(process)
        children.processes.remove(process)
    trace = bus.trace  # type: ignore[attr-defined]
    wire = wire_transactions(trace, since, until)
    return load, wire, gaps_before(trace, since, 0), gaps_before(trace, since, 1)


def section_paced(args: argparse.Namespace) -> list[str]:
    names = contenders(args)
    runs: dict[str, list[tuple[Load, float, list[float], list[float]]]] = {
        name: [] for name in names
    }
    with paced_line() as (children, serial, bus):
        for _ in range(args.rounds):
            for name in names:
                runs[name].append(_paced_run(children, serial, bus, name, args, 8, False))
    rows = []
    for name in names:
        rate = benchlib.median([run[0].rate for run in runs[name]])
        gaps = [gap for run in runs[name] for gap in run[2]]
        turnarounds = [gap for run in runs[name] for gap in run[3]]
        short = sum(1 for gap in gaps if gap < T35)
        rows.append(
            [
                name, f"{rate:.1f}", f"{rate / WIRE_LIMIT * 100:.1f}",
                f"{min(gaps) * 1000:.2f}", f"{benchlib.median(gaps) * 1000:.2f}",
                f"{short} of {len(gaps)}", f"{benchlib.median(turnarounds) * 1000:.2f}",
            ]
        )  # fmt: skip
    headers = ["gateway", "requests/s", "% of wire limit", "shortest gap before a request ms",
               "median gap before a request ms", "requests after less than t3.5",
               "median slave turnaround ms"]  # fmt: skip
    return [
        f"### Paced 19200 8N2 line, 8 clients (wire limit {WIRE_LIMIT:.1f} transactions/s, "
        f"t3.5 {T35 * 1000:.2f} ms)",
        "",
        benchlib.table(headers, rows),
    ]


def section_coalescing(args: argparse.Namespace) -> list[str]:
    names = contenders(args)
    runs: dict[str, list[tuple[Load, float]]] = {name: [] for name in names}
    with paced_line() as (children, serial, bus):
        for _ in range(args.rounds):
            for name in names:
                load, wire, _, _ = _paced_run(children, serial, bus, name, args, 32, True)
                runs[name].append((load, wire))
    rows = []
    for name in names:
        served = benchlib.median([load.rate for load, _ in runs[name]])
        wire = benchlib.median([count / load.seconds for load, count in runs[name]])
        rows.append([name, f"{served:.1f}", f"{wire:.1f}", f"{served / wire:.2f}x"])
    headers = ["gateway", "requests/s served", "transactions/s on the wire", "served / wire"]
    return [
        "### Coalescing: 32 clients reading the same block, paced 19200 8N2 line",
        "",
        benchlib.table(headers, rows),
    ]


def section_dead_unit(args: argparse.Namespace) -> list[str]:
    names = contenders(args)
    units = tuple(range(1, 11))
    results: dict[tuple[str, str], list[float]] = {}
    for case, served in (("all alive", 10), ("unit 10 dead", 9)):
        # aiortu's slave: pymodbus's server answers a unit it does not serve with exception
        # 04 where a switched-off device is silent.
        with socat_line(served, "aiortu") as (children, serial):
            for _ in range(args.rounds):
                for name in names:
                    # The first cycles are the warm-up: the 2 s cover the dead unit's first
                    # timeouts (0.5 s each) until the aiortu master takes it offline (3).
                    load, _ = measure(children, name, serial, args, 8, units, warmup=2.0)
                    alive = sum(load.per_unit.get(unit, 0) for unit in units[:9])
                    results.setdefault((name, case), []).append(alive / load.seconds)
    rows = []
    for name in names:
        alive = benchlib.median(results[(name, "all alive")])
        dead = benchlib.median(results[(name, "unit 10 dead")])
        rows.append([name, f"{alive:.0f}", f"{dead:.0f}", f"{dead / alive * 100:.1f}"])
    headers = ["gateway", "units 1-9 requests/s, all alive", "with unit 10 dead", "% of alive"]
    return [
        "### One dead unit among 10, 8 clients, socat pty pair",
        "",
        benchlib.table(headers, rows),
    ]


SECTIONS = {
    "unpaced": section_unpaced,
    "paced": section_paced,
    "coalescing": section_coalescing,
    "dead-unit": section_dead_unit,
}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--mbusd", default=MBUSD, help=f"the mbusd binary ({MBUSD})")
    parser.add_argument("--rounds", type=int, default=3)
    parser.add_argument("--seconds", type=float, default=4.0)
    parser.add_argument(
        "--rates", type=lambda text: [Rate.parse(item) for item in text.split(",")],
        default=[SLOW], help="line settings of the unpaced runs (19200:8N2)",
    )  # fmt: skip
    parser.add_argument(
        "--clients", type=lambda text: [int(item) for item in text.split(",")],
        default=[1, 8, 32], help="client counts of the unpaced runs (1,8,32)",
    )  # fmt: skip
    parser.add_argument(
        "--baseline", default=None, metavar="SRC",
        help="the src folder of another checkout whose gateway runs too (rows 'base')",
    )  # fmt: skip
    benchlib.add_section_argument(parser, SECTIONS)
    args = parser.parse_args()
    benchlib.run_sections(args, SECTIONS)


if __name__ == "__main__":
    main()

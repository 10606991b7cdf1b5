"""Benchmark of the transports against pymodbus: CPU per request over Modbus UDP, Modbus/TCP
Security and Modbus ASCII, for the master and for the server, and TLS handshakes per second.

Run from the repository root with aiortu, pymodbus and cryptography installed::

    python benchmarks/bench_transports.py [--rounds 5] [--requests 1000]
        [--section udp|tls|ascii|handshakes|calls]

Each section runs aiortu's server and pymodbus's in processes of their own (unit 1, holding
registers from 0), on loopback or, for ASCII, on a socat pty pair at 19200 8N2.

- master: aiortu's master and pymodbus's async client take turns, round by round, each sending
  `--requests` reads of 10 holding registers to aiortu's server; the figure is this process's
  CPU time (``process_time``) per request, which moves less with the machine's load than
  wall time.
- master, each client in a process of its own (UDP): the same, but each round starts a process
  per client, which reads and reports its own CPU time. One process alternating between two
  clients shares its memory allocator between them: asyncio's datagram transport (pymodbus's)
  takes a 256 KiB buffer per datagram, whose cost depends on what else the process allocated,
  and moved pymodbus's figure between about 60 and 110 us from one run to the next.
- server: aiortu's master sends the same reads to aiortu's server and to pymodbus's, in turns;
  the figure is the server process's CPU time per request (the nanoseconds of
  /proc/PID/task/*/schedstat).
- calls: Python calls (function and C calls, by ``sys.setprofile``) per read of aiortu's master
  over TLS and plain TCP and of pymodbus's TLS client, all to aiortu's server: a figure that does
  not move with the machine's load.
- handshakes: mutual-TLS handshakes per second to aiortu's TLS server (each a connection, a
  handshake and a close), and the CPU per request on an open TLS connection against plain
  Modbus TCP (the master's side).

The tables give medians over the rounds and aiortu's CPU as a share of pymodbus's (the issue's
target: at most 0.5).
"""

from __future__ import annotations

import argparse
import os
import ssl
import statistics
import subprocess
import sys
import tempfile
import time
from collections.abc import Awaitable, Callable
from pathlib import Path
from typing import Any

import anyio

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
import benchlib
from tests.transport.certificates import Authority

import aiortu

PEERS = str(Path(__file__).resolve().parents[1] / "tests" / "transport" / "pymodbus_peers.py")
LINE: dict[str, Any] = {"baudrate": 19200, "bytesize": 8, "parity": "N", "stopbits": 2}


def _serve_aiortu(argv: list[str]) -> None:
    """`--serve-aiortu KIND ...`: aiortu's server for unit 1, printing `ready PORT`."""
    store = aiortu.MemoryStore(holding_registers={0: list(range(40))})

    async def main() -> None:
        kind = argv[0]
        if kind == "ascii":
            async with aiortu.serve(argv[1], {1: store}, framing="ascii", **LINE):
                print("ready 0", flush=True)
                await anyio.sleep_forever()
        options: dict[str, Any] = {}
        if kind == "tls":
            rules = aiortu.transport.RoleRules(
                {"operator": aiortu.transport.AccessRule(frozenset({3}))}
            )
            options = {"certfile": argv[1], "keyfile": argv[2], "cafile": argv[3], "rules": rules}
        async with aiortu.serve(f"{kind}://127.0.0.1:0", {1: store}, **options) as server:
            print(f"ready {server.port}", flush=True)
            await anyio.sleep_forever()

    anyio.run(main)


def _start(children: benchlib.Children, argv: list[str]) -> tuple[subprocess.Popen[bytes], int]:
    process = children.start(argv, stdout=subprocess.PIPE, stdin=subprocess.DEVNULL)
    assert process.stdout is not None
    words = process.stdout.readline().decode().split()
    if not words or words[0] != "ready":
        raise RuntimeError(f"{argv} did not start")
    return process, int(words[1])


class Pki:
    """A CA, the server's certificate and an operator's, in a temporary directory."""

    def __init__(self, directory: Path) -> None:
        ca = Authority(directory)
        self.cafile = ca.cafile
        self.server = ca.issue("server", server=True)
        self.client = ca.issue("operator", role="operator")

    def client_context(self) -> ssl.SSLContext:
        context = ssl.create_default_context(cafile=str(self.cafile))
        context.load_cert_chain(self.client.certfile, self.client.keyfile)
        return context

    def master_options(self) -> dict[str, Any]:
        return {
            "certfile": self.client.certfile,
            "keyfile": self.client.keyfile,
            "cafile": self.cafile,
        }


def aiortu_reads(url: str, **options: Any) -> Callable[[], Any]:
    """An opener of aiortu's master on `url` whose run does `count` reads."""
    return lambda: aiortu.open_master(url, timeout=2.0, retries=0, **options)


Clock = Callable[[], float]


async def _aiortu_run(opener: Callable[[], Any], count: int, clock: Clock) -> float:
    """CPU seconds by `clock` over `count` reads, once connected and warm."""
    async with opener() as master:
        for _ in range(10):
            await master.read_holding_registers(1, 0, 10)
        before = clock()
        for _ in range(count):
            await master.read_holding_registers(1, 0, 10)
        return clock() - before


async def _pymodbus_run(make: Callable[[], Any], count: int, clock: Clock) -> float:
    client = make()
    await client.connect()
    try:
        for _ in range(10):
            await client.read_holding_registers(0, count=10, device_id=1)
        before = clock()
        for _ in range(count):
            reply = await client.read_holding_registers(0, count=10, device_id=1)
            assert not reply.isError()
        return clock() - before
    finally:
        client.close()


Contender = tuple[Callable[[int, Clock], Awaitable[float]], int | None]


def ours(opener: Callable[[], Any], pid: int | None = None) -> Contender:
    """aiortu's master on `opener`; its CPU counted, or process `pid`'s."""
    return (lambda count, clock: _aiortu_run(opener, count, clock)), pid


def pymodbus_side(make: Callable[[], Any]) -> Contender:
    """pymodbus's client made by `make`; this process's CPU counted."""
    return (lambda count, clock: _pymodbus_run(make, count, clock)), None


def _cpu_per_request(run: Callable[..., Awaitable[float]], count: int, pid: int | None) -> float:
    """Microseconds of CPU per request: this process's, or process `pid`'s."""

    def clock() -> float:
        return time.process_time() if pid is None else benchlib.cpu_exact(pid)

    return anyio.run(run, count, clock) / count * 1e6


def _compare(
    args: argparse.Namespace, title: str, runs: dict[str, tuple[Any, int | None]]
) -> list[str]:
    """Run each contender of `runs` (name: (an async function of count, a pid to watch or
    None for this process)) in turns; a table row per contender."""
    samples: dict[str, list[float]] = {name: [] for name in runs}
    for _ in range(args.rounds):
        for name, (run, pid) in runs.items():
            samples[name].append(_cpu_per_request(run, args.requests, pid))
    return [
        f"| {title} | {name} | {statistics.median(values):.0f} |"
        for name, values in samples.items()
    ]


def _section(
    args: argparse.Namespace,
    label: str,
    aiortu_url: Callable[[int], str],
    pymodbus_client: Callable[[int], Any],
    serve_argv: list[str],
    master_options: dict[str, Any],
) -> list[str]:
    import pymodbus.client as pm  # noqa: F401 - fails early without pymodbus

    with benchlib.Children() as children:
        our_server, our_port = _start(
            children, [sys.executable, __file__, "--serve-aiortu", *serve_argv]
        )
        their_server, their_port = _start(
            children, [sys.executable, "-W", "ignore", PEERS, *serve_argv]
        )
        to_ours = aiortu_reads(aiortu_url(our_port), **master_options)
        to_theirs = aiortu_reads(aiortu_url(their_port), **master_options)
        master_rows = _compare(
            args,
            f"{label}: master",
            {
                "aiortu": ours(to_ours),
                "pymodbus": pymodbus_side(lambda: pymodbus_client(our_port)),
            },
        )
        server_rows = _compare(
            args,
            f"{label}: server",
            {
                "aiortu": ours(to_ours, our_server.pid),
                "pymodbus": ours(to_theirs, their_server.pid),
            },
        )
    return [*master_rows, *server_rows]


def _udp_client(port: int) -> Any:
    import pymodbus.client as pm

    return pm.AsyncModbusUdpClient("127.0.0.1", port=port, timeout=2, retries=0)


def section_udp(args: argparse.Namespace) -> list[str]:
    rows = _section(args, "UDP", lambda port: f"udp://127.0.0.1:{port}", _udp_client, ["udp"], {})
    with benchlib.Children() as children:
        _, port = _start(children, [sys.executable, __file__, "--serve-aiortu", "udp"])
        samples: dict[str, list[float]] = {"aiortu": [], "pymodbus": []}
        for _ in range(args.rounds):
            for client, values in samples.items():
                argv = [__file__, "--read-udp", client, str(port), str(args.requests)]
                done = subprocess.run(
                    [sys.executable, "-W", "ignore", *argv], capture_output=True, check=True
                )
                values.append(float(done.stdout.split()[-1]))
    solo = [
        f"| UDP: master, a process per client | {name} | {statistics.median(values):.0f} |"
        for name, values in samples.items()
    ]
    return [*rows, *solo]


def _read_udp(argv: list[str]) -> None:
    """`--read-udp aiortu|pymodbus PORT COUNT`: this process's CPU us per read, printed."""
    client, port, count = argv[0], int(argv[1]), int(argv[2])
    if client == "aiortu":
        seconds = anyio.run(
            _aiortu_run, aiortu_reads(f"udp://127.0.0.1:{port}"), count, time.process_time
        )
    else:
        seconds = anyio.run(_pymodbus_run, lambda: _udp_client(port), count, time.process_time)
    print(f"{seconds / count * 1e6:.1f}")


def section_tls(args: argparse.Namespace) -> list[str]:
    import pymodbus.client as pm

    with tempfile.TemporaryDirectory() as directory:
        pki = Pki(Path(directory))
        files = [str(pki.server.certfile), str(pki.server.keyfile), str(pki.cafile)]
        return _section(
            args,
            "TLS",
            lambda port: f"tls://127.0.0.1:{port}",
            lambda port: pm.AsyncModbusTlsClient(
                "127.0.0.1", port=port, sslctx=pki.client_context(), timeout=2, retries=0
            ),
            ["tls", *files],
            pki.master_options(),
        )


def section_ascii(args: argparse.Namespace) -> list[str]:
    import pymodbus
    import pymodbus.client as pm

    with benchlib.Children() as children:
        # Two socat pairs: one line to each server.
        our_master, our_slave = children.socat_pair()
        their_master, their_slave = children.socat_pair()
        our_server, _ = _start(
            children, [sys.executable, __file__, "--serve-aiortu", "ascii", our_slave]
        )
        their_server, _ = _start(
            children, [sys.executable, "-W", "ignore", PEERS, "ascii", their_slave]
        )

        def aiortu_on(path: str) -> Callable[[], Any]:
            return lambda: aiortu.open_master(path, framing="ascii", timeout=2.0, retries=0, **LINE)

        def pymodbus_on(path: str) -> Any:
            return pm.AsyncModbusSerialClient(
                path, framer=pymodbus.FramerType.ASCII, timeout=2, retries=0, **LINE
            )

        master_rows = _compare(
            args,
            "ASCII: master",
            {
                "aiortu": ours(aiortu_on(our_master)),
                "pymodbus": pymodbus_side(lambda: pymodbus_on(our_master)),
            },
        )
        server_rows = _compare(
            args,
            "ASCII: server",
            {
                "aiortu": ours(aiortu_on(our_master), our_server.pid),
                "pymodbus": ours(aiortu_on(their_master), their_server.pid),
            },
        )
    return [*master_rows, *server_rows]


def section_handshakes(args: argparse.Namespace) -> list[str]:
    with tempfile.TemporaryDirectory() as directory, benchlib.Children() as children:
        pki = Pki(Path(directory))
        files = [str(pki.server.certfile), str(pki.server.keyfile), str(pki.cafile)]
        _, tls_port = _start(children, [sys.executable, __file__, "--serve-aiortu", "tls", *files])
        _, tcp_port = _start(children, [sys.executable, __file__, "--serve-aiortu", "tcp"])
        context = pki.client_context()

        async def handshakes(count: int) -> float:
            start = time.perf_counter()
            for _ in range(count):
                stream = await anyio.connect_tcp("127.0.0.1", tls_port)
                tls = await anyio.streams.tls.TLSStream.wrap(
                    stream, hostname="127.0.0.1", ssl_context=context, standard_compatible=False
                )
                await tls.aclose()
            return count / (time.perf_counter() - start)

        rates = [anyio.run(handshakes, max(args.requests // 10, 20)) for _ in range(args.rounds)]
        options = pki.master_options()
        rows = _compare(
            args,
            "request on an open connection",
            {
                "TLS": ours(aiortu_reads(f"tls://127.0.0.1:{tls_port}", **options)),
                "plain TCP": ours(aiortu_reads(f"tcp://127.0.0.1:{tcp_port}")),
            },
        )
    return [
        f"Mutual-TLS handshakes per second to aiortu's server (connect, handshake, close): "
        f"{statistics.median(rates):,.0f} (median of {args.rounds} rounds)",
        "",
        "| measure | transport | master CPU us/request |",
        "|---|---|---|",
        *rows,
    ]


async def _calls(run: Callable[[int, Clock], Awaitable[float]], count: int) -> float:
    """Python calls per request of `run` over `count` requests, counted by `sys.setprofile`."""
    calls = 0

    def profile(frame: object, event: str, arg: object) -> None:
        nonlocal calls
        if event in ("call", "c_call"):
            calls += 1

    def clock() -> float:
        sys.setprofile(profile if sys.getprofile() is None else None)
        return 0.0

    await run(count, clock)  # the clock turns counting on, then off, around the measured reads
    return calls / count


def section_calls(args: argparse.Namespace) -> list[str]:
    import pymodbus.client as pm

    with tempfile.TemporaryDirectory() as directory, benchlib.Children() as children:
        pki = Pki(Path(directory))
        files = [str(pki.server.certfile), str(pki.server.keyfile), str(pki.cafile)]
        _, tls_port = _start(children, [sys.executable, __file__, "--serve-aiortu", "tls", *files])
        _, tcp_port = _start(children, [sys.executable, __file__, "--serve-aiortu", "tcp"])
        options = pki.master_options()
        runs = {
            "aiortu, TLS": ours(aiortu_reads(f"tls://127.0.0.1:{tls_port}", **options))[0],
            "aiortu, plain TCP": ours(aiortu_reads(f"tcp://127.0.0.1:{tcp_port}"))[0],
            "pymodbus, TLS": pymodbus_side(
                lambda: pm.AsyncModbusTlsClient(
                    "127.0.0.1", port=tls_port, sslctx=pki.client_context(), timeout=2, retries=0
                )
            )[0],
        }
        count = min(args.requests, 200)
        rows = [f"| {name} | {anyio.run(_calls, run, count):.0f} |" for name, run in runs.items()]
    return ["| master | Python calls per read |", "|---|---|", *rows]


def _ratios(lines: list[str]) -> list[str]:
    """The rows of a section as a table, with aiortu's CPU as a share of pymodbus's."""
    out = [
        "| transport: side | aiortu CPU us/request | pymodbus CPU us/request | aiortu / pymodbus |",
        "|---|---|---|---|",
    ]
    for ours, theirs in zip(lines[0::2], lines[1::2], strict=True):
        title = ours.split("|")[1].strip()
        mine, other = float(ours.split("|")[3]), float(theirs.split("|")[3])
        ratio = f"{mine / other:.2f}" if other else "n/a"
        out.append(f"| {title} | {mine:.0f} | {other:.0f} | {ratio} |")
    return out


SECTIONS: dict[str, Callable[[argparse.Namespace], list[str]]] = {
    "udp": lambda args: _ratios(section_udp(args)),
    "tls": lambda args: _ratios(section_tls(args)),
    "ascii": lambda args: _ratios(section_ascii(args)),
    "handshakes": section_handshakes,
    "calls": section_calls,
}


def main() -> None:
    if sys.argv[1:2] == ["--serve-aiortu"]:
        _serve_aiortu(sys.argv[2:])
        return
    if sys.argv[1:2] == ["--read-udp"]:
        _read_udp(sys.argv[2:])
        return
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--rounds", type=int, default=5)
    parser.add_argument("--requests", type=int, default=1000)
    benchlib.add_section_argument(parser, SECTIONS)
    benchlib.run_sections(parser.parse_args(), SECTIONS)


if __name__ == "__main__":
    main()

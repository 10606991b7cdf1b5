"""The floor of a Modbus/TCP Security client's CPU per read on asyncio: how much of the CPU a
read costs before a library does any Modbus work, against aiortu's master and pymodbus's.

Run from the repository root with aiortu, pymodbus and cryptography installed::

    python benchmarks/floor_tls.py [--rounds 9] [--requests 10000] [--callgrind]

aiortu's TLS server (unit 1, holding registers from 0) runs in a process of its own on
loopback. Each contender reads 10 holding registers `--requests` times, after 20 reads of
warm-up, in a fresh process of its own; the contenders take turns, round by round (A B C ...
A B C ...), and the table gives the medians of their CPU per read (user + system, and each
apart, by `getrusage`) and the ratio to pymodbus's:

- `aiortu`: aiortu's master (`open_master("tls://...")`);
- `pymodbus`: pymodbus's `AsyncModbusTlsClient`;
- `bare, asyncio's TLS`: the cheapest asyncio client there is, on asyncio's own TLS
  transport (`loop.create_connection(ssl=...)`): one MBAP request written, one future
  completed by `data_received`, the reply's transaction id checked, no Modbus logic;
- `bare, aiortu's TLS`: the same bare client on aiortu's TLS layer
  (`transport._tls_bio.TlsBioTransport`, what the master's TLS stream uses);
- `bare, socket and BIOs`: the same again with no asyncio transport at all: the socket read
  by the loop's reader callback, TLS by an `ssl.SSLObject` over memory BIOs.

The bare clients' system CPU is the kernel's part of a read (a send, a receive, the loop's
`epoll_wait`s), which every asyncio client pays. `--callgrind` also counts each contender's
instructions per read under `valgrind --tool=callgrind` (100 and 1000 reads, the difference
over 900): a figure the machine's load does not move (user space only).
"""

from __future__ import annotations

import argparse
import asyncio
import contextlib
import os
import resource
import socket
import ssl
import statistics
import struct
import subprocess
import sys
import tempfile
from collections.abc import Awaitable, Callable
from pathlib import Path

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

Read = Callable[[int], Awaitable[object]]

_KEEP: list[object] = []
"""What must outlive `_open`: aiortu's master's context manager (its generator would close
the master once collected)."""

CONTENDERS = {
    "aiortu": "aiortu's master",
    "pymodbus": "pymodbus's client",
    "asyncio": "bare, asyncio's TLS",
    "bio": "bare, aiortu's TLS",
    "socket": "bare, socket and BIOs",
}


def _request(tid: int) -> bytes:
    """An MBAP read of 10 holding registers from 0, unit 1."""
    return struct.pack(">HHHBBHH", tid, 0, 6, 1, 3, 0, 10)


def _checked(tid: int, reply: bytes) -> bytes:
    if len(reply) != 29 or reply[:2] != struct.pack(">H", tid):
        raise AssertionError(f"a bare client read a wrong reply: {reply!r}")
    return reply


class _Waiter(asyncio.Protocol):
    """The bare client's protocol: each chunk completes the future of the read under way."""

    future: asyncio.Future[bytes]

    def data_received(self, data: bytes) -> None:
        self.future.set_result(data)


def _bare(loop: asyncio.AbstractEventLoop, write: Callable[[bytes], object], app: _Waiter) -> Read:
    async def read(tid: int) -> bytes:
        app.future = loop.create_future()
        write(_request(tid))
        return _checked(tid, await app.future)

    return read


async def _open(kind: str, port: int, files: _Files) -> Read:
    loop = asyncio.get_running_loop()
    if kind == "aiortu":
        import aiortu

        opener = aiortu.open_master(
            f"tls://127.0.0.1:{port}", timeout=2.0, retries=0,
            certfile=files.certfile, keyfile=files.keyfile, cafile=files.cafile,
        )  # fmt: skip
        master = await opener.__aenter__()
        _KEEP.append(opener)
        return lambda tid: master.read_holding_registers(1, 0, 10)
    if kind == "pymodbus":
        import pymodbus.client as pm

        client = pm.AsyncModbusTlsClient(
            "127.0.0.1", port=port, sslctx=files.context(), timeout=2, retries=0
        )
        await client.connect()
        return lambda tid: client.read_holding_registers(0, count=10, device_id=1)
    app = _Waiter()
    if kind == "asyncio":
        transport, _ = await loop.create_connection(
            lambda: app, "127.0.0.1", port, ssl=files.context(), server_hostname="localhost"
        )
        return _bare(loop, transport.write, app)
    if kind == "bio":
        from aiortu.transport._tls_bio import TlsBioTransport

        tls = TlsBioTransport(files.context(), app, server_hostname="localhost")
        await loop.create_connection(lambda: tls, "127.0.0.1", port)
        await tls.handshake()
        return _bare(loop, tls.write, app)
    return _socket_and_bios(loop, port, files, app)


def _socket_and_bios(
    loop: asyncio.AbstractEventLoop, port: int, files: _Files, app: _Waiter
) -> Read:
    """The bare client with no asyncio transport (the handshake done blocking, beforehand)."""
    sock = socket.create_connection(("127.0.0.1", port))
    sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
    incoming, outgoing = ssl.MemoryBIO(), ssl.MemoryBIO()
    tls = files.context().wrap_bio(incoming, outgoing, server_hostname="localhost")
    while True:
        try:
            tls.do_handshake()
            break
        except ssl.SSLWantReadError:
            sock.sendall(outgoing.read())
            incoming.write(sock.recv(65536))
    sock.sendall(outgoing.read())
    sock.setblocking(False)
    buffer = memoryview(bytearray(17000))

    def on_readable() -> None:
        incoming.write(buffer[: sock.recv_into(buffer)])
        with contextlib.suppress(ssl.SSLWantReadError):  # a session ticket, or half a record
            app.data_received(tls.read(16384))

    def write(data: bytes) -> None:
        tls.write(data)
        sock.send(outgoing.read())

    loop.add_reader(sock.fileno(), on_readable)
    return _bare(loop, write, app)


class _Files:
    """The CA, the server's certificate and an operator's, in `directory`."""

    def __init__(self, directory: Path, *, make: bool) -> None:
        self.cafile, self.certfile, self.keyfile = (
            str(directory / "ca.pem"), str(directory / "operator.crt"),
            str(directory / "operator.key"),
        )  # fmt: skip
        self.server = [str(directory / "server.crt"), str(directory / "server.key"), self.cafile]
        if make:
            from tests.transport.certificates import Authority

            authority = Authority(directory, name="ca")
            authority.issue("server", server=True)
            authority.issue("operator", role="operator")

    def context(self) -> ssl.SSLContext:
        context = ssl.create_default_context(cafile=self.cafile)
        context.load_cert_chain(self.certfile, self.keyfile)
        return context


def _client(argv: list[str]) -> None:
    """`--client KIND COUNT PORT DIR`: one contender's reads; prints `cpu user system` (us)."""
    kind, count, port, directory = argv[0], int(argv[1]), int(argv[2]), Path(argv[3])

    async def main() -> None:
        read = await _open(kind, port, _Files(directory, make=False))
        for tid in range(20):
            await read(tid)
        before = resource.getrusage(resource.RUSAGE_SELF)
        for n in range(count):
            await read(n & 0xFFFF)
        after = resource.getrusage(resource.RUSAGE_SELF)
        user = (after.ru_utime - before.ru_utime) / count * 1e6
        system = (after.ru_stime - before.ru_stime) / count * 1e6
        print(f"{user + system} {user} {system}", flush=True)
        os._exit(0)  # no goodbyes: only the reads are measured

    asyncio.run(main())


def _run(kind: str, count: int, port: int, directory: str) -> list[float]:
    argv = [sys.executable, __file__, "--client", kind, str(count), str(port), directory]
    done = subprocess.run(argv, capture_output=True, text=True, check=True, timeout=600)
    return [float(word) for word in done.stdout.split()]


def _instructions(kind: str, port: int, directory: str) -> int:
    """User-space instructions per read, under callgrind (1000 reads less 100, over 900)."""
    totals = []
    for count in (100, 1000):
        with tempfile.NamedTemporaryFile(suffix=".cg") as out:
            subprocess.run(
                ["valgrind", "--tool=callgrind", f"--callgrind-out-file={out.name}",
                 sys.executable, __file__, "--client", kind, str(count), str(port), directory],
                capture_output=True, check=True, timeout=1800,
            )  # fmt: skip
            summary = [line for line in Path(out.name).read_text().splitlines()
                       if line.startswith("summary:")]  # fmt: skip
            totals.append(int(summary[0].split()[1]))
    return (totals[1] - totals[0]) // 900


def main() -> None:
    if sys.argv[1:2] == ["--client"]:
        _client(sys.argv[2:])
        return
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--rounds", type=int, default=9)
    parser.add_argument("--requests", type=int, default=10000)
    parser.add_argument("--callgrind", action="store_true")
    args = parser.parse_args()
    import benchlib

    print("\n".join(benchlib.header()))
    with tempfile.TemporaryDirectory() as directory, benchlib.Children() as children:
        files = _Files(Path(directory), make=True)
        bench = str(Path(__file__).with_name("bench_transports.py"))
        server = children.start(
            [sys.executable, bench, "--serve-aiortu", "tls", *files.server],
            stdout=subprocess.PIPE, stdin=subprocess.DEVNULL,
        )  # fmt: skip
        assert server.stdout is not None
        port = int(server.stdout.readline().split()[1])
        samples: dict[str, list[list[float]]] = {kind: [] for kind in CONTENDERS}
        for _ in range(args.rounds):
            for kind in CONTENDERS:
                samples[kind].append(_run(kind, args.requests, port, directory))
        counts = {k: _instructions(k, port, directory) for k in CONTENDERS if args.callgrind}
    print(_table(samples, counts, args))


def _table(
    samples: dict[str, list[list[float]]], counts: dict[str, int], args: argparse.Namespace
) -> str:
    import benchlib

    medians = {
        k: [statistics.median(run[i] for run in v) for i in range(3)] for k, v in samples.items()
    }
    reference = medians["pymodbus"]
    rows = []
    for kind, figures in medians.items():
        row = [CONTENDERS[kind]]
        row += [f"{us:.1f} ({us / of:.2f}x)" for us, of in zip(figures, reference, strict=True)]
        if counts:
            row.append(f"{counts[kind]:,} ({counts[kind] / counts['pymodbus']:.2f}x)")
        rows.append(row)
    headers = ["TLS client, per read", "CPU us", "user us", "system us"]
    if counts:
        headers.append("instructions")
    title = f"Medians of {args.rounds} interleaved rounds of {args.requests} reads, fresh processes"
    return f"{title}\n\n{benchlib.table(headers, rows)}"


if __name__ == "__main__":
    main()

"""Gateway soak: honest clients whose every answer is checked, among hostile ones, for minutes.

Run from the repository root::

    nice -n 10 python benchmarks/soak_gateway.py --minutes 30 [--seed 1]

One process: an aiortu slave listening for RTU over TCP is the line (unit 1 answers at once,
unit 2 is slow, answering after 0 to 0.6 s, so often after the gateway's 0.3 s timeout, unit 3
is missing), and `aiortu.gateway` opens it as `rtu+tcp://` with its defaults. Around it:

- **honest clients** (8): each writes its own registers of unit 1 (FC 06, FC 10) and reads
  them back (FC 03), reads unit 2 (known values) and unit 3. Every answer must carry its
  request's transaction and unit ids and be right: the value written, the known values, or
  exception 0B/0A (0A while the line is down). A write answered with an exception may have
  been done or not: it is written again before it is checked.
- **hostile clients**, drawn at random: pipeliners that send 2,000 requests and never read,
  slowloris (a header byte every 0.2 s), connection floods past the limit, random bytes,
  clients that reset their connection right after a write to the slow unit.
- **bus kills**: every 60 s the line's listener and its connections are closed for 1 s.

The resident set is sampled every 10 s; after a 2-minute warm-up it must stay within 10 % of
its first sample. Prints a progress line a minute, then operations, wrong answers and RSS
(start, end, max); exit code 1 on a wrong answer or RSS past the bound.
"""

from __future__ import annotations

import argparse
import contextlib
import random
import socket
import struct
import sys
import time
from collections import Counter
from collections.abc import Sequence
from pathlib import Path

import anyio
import anyio.abc

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from tests.faults.flood import rss_bytes

from aiortu.core.model import Table
from aiortu.gateway import gateway
from aiortu.slave import MemoryStore, serve

HONEST = 8
SLOW_VALUES = [1000 + index for index in range(10)]
WARM_UP = 120.0
RSS_BOUND = 1.10


class SlowStore:
    """Unit 2: known values, answered after 0 to 0.6 s (the gateway's timeout is 0.3 s)."""

    def __init__(self, rng: random.Random) -> None:
        self.rng = rng

    async def read(self, table: Table, address: int, count: int) -> Sequence[int]:
        await anyio.sleep(self.rng.uniform(0.0, 0.6))
        return [1000 + address + index for index in range(count)]

    async def write(self, table: Table, address: int, values: Sequence[int]) -> None:
        await anyio.sleep(self.rng.uniform(0.0, 0.6))


class Soak:
    def __init__(self, seed: int, minutes: float) -> None:
        self.rng = random.Random(seed)
        self.seed = seed
        self.deadline = time.monotonic() + minutes * 60
        self.operations: Counter[str] = Counter()
        self.wrong: list[str] = []
        self.rss: list[int] = []
        self.line_down = False
        self.gateway_port = 0

    def over(self) -> bool:
        return time.monotonic() >= self.deadline

    # -- the line, killed now and then ------------------------------------------------------

    async def line(self, port: int, task_status: anyio.abc.TaskStatus[None]) -> None:
        units = {1: MemoryStore(holding_registers={0: [0] * 100}), 2: SlowStore(self.rng)}
        started = False
        while not self.over():
            async with serve(f"rtu+tcp://127.0.0.1:{port}", units, listen=True):  # type: ignore[arg-type]
                self.line_down = False
                if not started:
                    started = True
                    task_status.started()
                with anyio.move_on_after(60):
                    while not self.over():  # noqa: ASYNC110
                        await anyio.sleep(1)
            self.line_down = True
            self.operations["bus kills"] += 1
            await anyio.sleep(1)

    # -- honest clients ---------------------------------------------------------------------

    async def honest(self, index: int) -> None:
        rng = random.Random(self.seed * 100 + index)
        address = index * 4
        while not self.over():
            try:
                stream = await anyio.connect_tcp("127.0.0.1", self.gateway_port)
            except OSError:
                await anyio.sleep(0.1)
                continue
            async with stream:
                client = _Client(stream, self)
                with contextlib.suppress(*_GONE):
                    for _ in range(rng.randrange(20, 200)):
                        if self.over():
                            break
                        await self.honest_step(client, rng, address)

    async def honest_step(self, client: _Client, rng: random.Random, address: int) -> None:
        values = [rng.randrange(0x10000) for _ in range(rng.choice((1, 3)))]
        if len(values) == 1:
            pdu = struct.pack(">BHH", 6, address, values[0])
        else:
            pdu = struct.pack(">BHHB", 16, address, 3, 6) + struct.pack(">3H", *values)
        while True:  # a write answered with an exception may or may not have been done
            reply = await client.ask(1, pdu)
            if not reply[0] & 0x80:
                self.check(reply == pdu[:5], "write", pdu, reply)
                break
            self.check(reply[1] in (0x0A, 0x0B), "write exception", pdu, reply)
            if self.over():
                return
            await anyio.sleep(0.05)
        count = len(values)
        read = struct.pack(">BHH", 3, address, count)
        reply = await client.ask(1, read)
        if not self._exception(reply, read):
            expected = bytes((3, 2 * count)) + struct.pack(f">{count}H", *values)
            self.check(reply == expected, "read back", read, reply)
        self.operations["honest unit 1"] += 2
        slow = struct.pack(">BHH", 3, 0, 3)
        reply = await client.ask(2, slow)
        if not self._exception(reply, slow):
            expected = bytes((3, 6)) + struct.pack(">3H", *SLOW_VALUES[:3])
            self.check(reply == expected, "slow unit", slow, reply)
        missing = await client.ask(3, read)
        self.check(missing in (b"\x83\x0b", b"\x83\x0a"), "missing unit", read, missing)
        self.operations["honest slow and missing units"] += 2

    def _exception(self, reply: bytes, request: bytes) -> bool:
        if reply[:1] == bytes((request[0] | 0x80,)):
            self.check(reply[1:] in (b"\x0a", b"\x0b"), "exception", request, reply)
            return True
        return False

    def check(self, ok: bool, what: str, request: bytes, reply: bytes) -> None:
        if not ok:
            self.wrong.append(f"{what}: request {request.hex(' ')} got {reply.hex(' ')}")
            print(f"WRONG ({self.seed}): {self.wrong[-1]}", flush=True)

    # -- hostile clients --------------------------------------------------------------------

    async def hostile(self, seed: int) -> None:
        rng = random.Random(seed)
        kinds = [self.pipeliner, self.slowloris, self.flood, self.garbage, self.leaver]
        while not self.over():
            attack = rng.choice(kinds)
            with contextlib.suppress(OSError, *_GONE), anyio.move_on_after(10):
                await attack(rng)
            self.operations[f"hostile {attack.__name__}"] += 1

    async def pipeliner(self, rng: random.Random) -> None:
        request = _adu(1, 1, struct.pack(">BHH", 3, 0, 10))
        sock = await anyio.connect_tcp("127.0.0.1", self.gateway_port)
        async with sock:
            with anyio.move_on_after(0.5):
                for _ in range(2000):
                    await sock.send(request)
            await anyio.sleep(rng.uniform(0, 1))

    async def slowloris(self, rng: random.Random) -> None:
        sock = await anyio.connect_tcp("127.0.0.1", self.gateway_port)
        async with sock:
            for byte in _adu(1, 1, struct.pack(">BHH", 3, 0, 1))[:6]:
                await sock.send(bytes((byte,)))
                await anyio.sleep(0.2)

    async def flood(self, rng: random.Random) -> None:
        socks = []
        try:
            for _ in range(80):
                with contextlib.suppress(OSError):
                    socks.append(await anyio.connect_tcp("127.0.0.1", self.gateway_port))
            await anyio.sleep(rng.uniform(0, 0.5))
        finally:
            for sock in socks:
                await sock.aclose()

    async def garbage(self, rng: random.Random) -> None:
        sock = await anyio.connect_tcp("127.0.0.1", self.gateway_port)
        async with sock:
            await sock.send(rng.randbytes(rng.randrange(1, 300)))
            await anyio.sleep(0.05)

    async def leaver(self, rng: random.Random) -> None:
        raw = socket.create_connection(("127.0.0.1", self.gateway_port))
        with raw:
            raw.sendall(_adu(9, 2, struct.pack(">BHH", 6, 50, rng.randrange(0x10000))))
            raw.setsockopt(socket.SOL_SOCKET, socket.SO_LINGER, struct.pack("ii", 1, 0))
        await anyio.sleep(0.01)

    # -- the run ----------------------------------------------------------------------------

    async def watch(self, started: float) -> None:
        minute = started
        while not self.over():
            await anyio.sleep(10)
            if time.monotonic() - started >= WARM_UP:
                self.rss.append(rss_bytes())
            if time.monotonic() - minute >= 60:
                minute = time.monotonic()
                done = sum(self.operations.values())
                print(
                    f"{(minute - started) / 60:5.1f} min: {done} operations, "
                    f"{len(self.wrong)} wrong, RSS {rss_bytes() / 2**20:.1f} MB",
                    flush=True,
                )

    async def run(self) -> None:
        with socket.socket() as probe:
            probe.bind(("127.0.0.1", 0))
            line_port = probe.getsockname()[1]
        started = time.monotonic()
        async with anyio.create_task_group() as tasks:
            await tasks.start(self.line, line_port)
            url = f"rtu+tcp://127.0.0.1:{line_port}"
            async with gateway(
                url, ["tcp://127.0.0.1:0"], frame_gap=0, max_connections=64, idle_timeout=2.0
            ) as server:
                self.gateway_port = server.port
                async with anyio.create_task_group() as clients:
                    clients.start_soon(self.watch, started)
                    for index in range(HONEST):
                        clients.start_soon(self.honest, index)
                    for index in range(4):
                        clients.start_soon(self.hostile, self.seed * 1000 + index)
            tasks.cancel_scope.cancel()


_GONE = (anyio.EndOfStream, anyio.BrokenResourceError, anyio.ClosedResourceError, TimeoutError)


def _adu(transaction: int, unit: int, pdu: bytes) -> bytes:
    return struct.pack(">HHHB", transaction, 0, len(pdu) + 1, unit) + pdu


class _Client:
    """A Modbus TCP client that checks the ids of every reply."""

    def __init__(self, stream: anyio.abc.SocketStream, soak: Soak) -> None:
        self.stream = stream
        self.soak = soak
        self.transaction = 0
        self.buffer = b""

    async def ask(self, unit: int, pdu: bytes) -> bytes:
        self.transaction = (self.transaction + 1) & 0xFFFF
        await self.stream.send(_adu(self.transaction, unit, pdu))
        with anyio.fail_after(5):
            while len(self.buffer) < 7 or len(self.buffer) < 6 + self.buffer[5]:
                self.buffer += await self.stream.receive()
        length = 6 + struct.unpack(">H", self.buffer[4:6])[0]
        adu, self.buffer = self.buffer[:length], self.buffer[length:]
        transaction, _, _, got_unit = struct.unpack(">HHHB", adu[:7])
        ids = transaction == self.transaction and got_unit == unit
        self.soak.check(ids, "ids", pdu, adu)
        return adu[7:]


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--minutes", type=float, default=30.0)
    parser.add_argument("--seed", type=int, default=1)
    args = parser.parse_args()
    soak = Soak(args.seed, args.minutes)
    anyio.run(soak.run)
    total = sum(soak.operations.values())
    print(f"seed {args.seed}, {args.minutes:g} minutes: {total} operations")
    for kind, count in sorted(soak.operations.items()):
        print(f"  {kind}: {count}")
    print(f"wrong answers: {len(soak.wrong)}")
    ok = not soak.wrong
    if soak.rss:
        start, end, peak = soak.rss[0], soak.rss[-1], max(soak.rss)
        print(
            f"RSS after warm-up: start {start / 2**20:.1f} MB, end {end / 2**20:.1f} MB, "
            f"max {peak / 2**20:.1f} MB (bound {RSS_BOUND:.2f}x start)"
        )
        ok = ok and peak <= start * RSS_BOUND
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())

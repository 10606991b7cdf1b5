"""The gateway's byte shortcut (a register read forwarded as its bytes, its reply returned as
the device's bytes) against the general route (decoded, encoded again), differentially.

Seeded random sessions of two clients, each reading registers (03 and 04) of a unit of its
own through a gateway in front of a master on a serial port over a pty (where the master's
fast path runs), run with the shortcut's predicate on and off. A device on the pty plays
each read's plan, reacting to what it sees (the request, the master's retry), not to the
clock: the usual reply, an exception, silence, a reply too short, of another count or whose
byte count lies, a bad CRC, noise first, another unit's or function's frame first, a reply
come late. Every client must get the same bytes for each transaction id, the master the same
per-unit statistics, and each unit the same requests on the wire, in the same order.
"""

from __future__ import annotations

import dataclasses
import os
import random
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import anyio
import pytest

from aiortu.core.pdu import RawRegisterRead, decode_request
from aiortu.core.rtu import encode_frame
from aiortu.gateway import gateway
from aiortu.gateway._as_bytes import ReadsAsBytes
from aiortu.master import Master
from aiortu.testing import MockLine, VirtualBus
from aiortu.transport import open_serial
from tests.gateway.helpers import memory_client
from tests.master.fakes import standard_reply
from tests.transport.ptys import LINE, Pty, open_pty, read_master

SEED = int(os.environ.get("AIORTU_AS_BYTES_SEED", "1126"))
TIMEOUT = 0.25
GUARD = 0.15
NOISE = b"\x00\xff\x13"
UNITS = (1, 2)
"""One unit per client: each unit's sequence of exchanges is the same in every run."""

# What the device does with each request frame of a read, in order (one retry).
PLANS: dict[str, tuple[str, ...]] = {
    "ok": ("answer",),
    "exception": ("exception",),
    "silent, then ok": ("silent", "answer"),
    "silent twice": ("silent", "silent"),
    "too short, then ok": ("short", "answer"),
    "another count, then ok": ("another_count", "answer"),
    "a byte count that lies, then ok": ("lying_byte_count", "answer"),
    "bad CRC, then ok": ("bad_crc", "answer"),
    "noise before the reply": ("noise_answer",),
    "another unit first": ("other_unit_answer",),
    "another function first": ("other_function_answer",),
    "late, then ok": ("late", "answer"),
}
WEIGHTS = {"ok": 8}  # the rest weigh 1
LENGTH = len(PLANS) + 4
"""Every plan once, and a few more drawn by weight: the silent plans cost a timeout each."""


@dataclass(frozen=True)
class Read:
    client: int
    code: int
    address: int
    count: int
    plan: str

    @property
    def unit(self) -> int:
        return UNITS[self.client]

    @property
    def pdu(self) -> str:
        return f"{self.code:02X} {self.address:04X} {self.count:04X}"


def scenario(seed: int, length: int) -> list[Read]:
    """`length` reads, each plan at least once, each read of an address of its own."""
    rng = random.Random(seed)
    plans = list(PLANS)
    chosen = plans + rng.choices(plans, [WEIGHTS.get(p, 1) for p in plans], k=length - len(plans))
    rng.shuffle(chosen)
    return [
        Read(rng.randrange(2), rng.choice((3, 4)), 10 * index, rng.randint(1, 4), plan)
        for index, plan in enumerate(chosen)
    ]


class Device:
    """The units on the pty: each read's plan, by the address it reads."""

    def __init__(self, pty: Pty, master: Master, reads: list[Read]) -> None:
        self.pty = pty
        self.master = master
        self.reads = {read.address: read for read in reads}
        self.seen: list[bytes] = []

    async def serve(self) -> None:
        while True:
            frame = await read_master(self.pty, 8, limit=30)
            self.seen.append(frame)
            read = self.reads[int.from_bytes(frame[2:4])]
            attempt = sum(1 for seen in self.seen if seen == frame) - 1
            await self.act(PLANS[read.plan][attempt], frame)

    async def act(self, action: str, frame: bytes) -> None:
        unit = frame[0]
        pdu = standard_reply(unit, decode_request(frame[1:-2]))
        reply = encode_frame(unit, pdu)
        retries = self.master.unit_stats(unit).retries
        await anyio.sleep(0.002)  # a real device hears the request's end a wire time later
        write = self.pty.write
        if action == "answer":
            write(reply)
        elif action == "exception":
            write(encode_frame(unit, bytes((pdu[0] | 0x80, 0x02))))
        elif action == "short":
            write(encode_frame(unit, pdu[:-1]))
        elif action == "another_count":
            write(encode_frame(unit, bytes((pdu[0], pdu[1] - 2)) + pdu[2:-2]))
        elif action == "lying_byte_count":
            write(encode_frame(unit, bytes((pdu[0], pdu[1] - 2)) + pdu[2:]))
        elif action == "bad_crc":
            write(reply[:-1] + bytes((reply[-1] ^ 0xFF,)))
        elif action == "noise_answer":
            write(NOISE + reply)
        elif action == "other_unit_answer":
            write(encode_frame(unit % 2 + 1, pdu))
            await anyio.sleep(0.01)
            write(reply)
        elif action == "other_function_answer":
            write(encode_frame(unit, bytes((pdu[0] ^ 7,)) + pdu[1:]))
            await anyio.sleep(0.01)
            write(reply)
        elif action == "late":
            # Sent once the master has decided to retry: it lands in the guard.
            await _until(lambda: self.master.unit_stats(unit).retries > retries)
            write(reply)


async def _until(condition: Callable[[], bool]) -> None:
    with anyio.fail_after(5):
        while not condition():  # noqa: ASYNC110
            await anyio.sleep(0.001)


async def _run(reads: list[Read], shortcut: bool, monkeypatch: pytest.MonkeyPatch) -> Any:
    forwards = ReadsAsBytes.forwards
    taken = 0

    def counted(self: ReadsAsBytes, pdu: bytes) -> bool:
        nonlocal taken
        allowed = shortcut and forwards(self, pdu)
        taken += allowed
        return allowed

    monkeypatch.setattr(ReadsAsBytes, "forwards", counted)
    replies: list[list[tuple[int, str]]] = [[], []]
    with open_pty() as pty:
        stream = await open_serial(pty.path, LINE)
        options = {"timeout": TIMEOUT, "retries": 1, "frame_gap": 0, "late_reply_guard": GUARD}
        async with Master(stream, LINE, **options) as master:  # type: ignore[arg-type]
            await anyio.sleep(0.05)  # past the receiver's first silence
            device = Device(pty, master, reads)
            async with gateway(master) as server, anyio.create_task_group() as tasks:
                tasks.start_soon(device.serve)

                async def play(client: int) -> None:
                    async with memory_client(server) as tcp:
                        for transaction_id, read in enumerate(reads):
                            if read.client == client:
                                await tcp.send(read.pdu, read.unit, transaction_id)
                                reply = await tcp.receive(wait=5)
                                assert reply is not None
                                assert reply.transaction_id == transaction_id
                                replies[client].append((transaction_id, reply.pdu.hex(" ")))

                with anyio.fail_after(60):
                    async with anyio.create_task_group() as clients:
                        clients.start_soon(play, 0)
                        clients.start_soon(play, 1)
                await _until(lambda: not master.engine.busy)
                tasks.cancel_scope.cancel()
            stats = {
                unit: {
                    key: value
                    for key, value in dataclasses.asdict(each).items()
                    if key not in ("last_latency", "mean_latency", "last_probe")
                }
                for unit, each in sorted(master.engine.stats.items())
            }
    monkeypatch.undo()
    assert taken > 0 if shortcut else taken == 0
    wire = {unit: [frame for frame in device.seen if frame[0] == unit] for unit in UNITS}
    return replies, stats, wire


@pytest.mark.parametrize("offset", range(2))
async def test_reads_forwarded_as_bytes_agree_with_reads_decoded(
    offset: int, monkeypatch: pytest.MonkeyPatch
) -> None:
    seed = SEED + offset
    reads = scenario(seed, LENGTH)
    try:
        as_bytes = await _run(reads, True, monkeypatch)
        decoded = await _run(reads, False, monkeypatch)
        for name, ours, theirs in zip(
            ("replies", "statistics", "requests on the wire"), as_bytes, decoded, strict=True
        ):
            assert ours == theirs, f"{name} differ"
    except BaseException:
        print(f"byte shortcut differential seed {seed} (AIORTU_AS_BYTES_SEED={seed})")
        for read in reads:
            print(f"  {read}")
        raise


@pytest.mark.parametrize(
    ("pdu", "forwarded"),
    [
        ("03 0000 0001", True),
        ("04 FF83 007D", True),  # 125 registers, up to the last address
        ("03 0000 0000", False),  # no register: the device says what it makes of it
        ("03 0000 007E", False),  # 126 registers
        ("04 FF84 007D", False),  # past the last address
        ("03 0000 0001 00", False),  # a byte too many
        ("02 0000 0001", False),  # a bit read: its reply's padding bits are the device's
        ("06 0000 0001", False),
    ],
)
def test_the_predicate_takes_exactly_the_register_reads_the_spec_allows(
    pdu: str, forwarded: bool
) -> None:
    master = Master(VirtualBus(2).endpoints[0], LINE)
    shortcut = ReadsAsBytes(master)
    data = bytes.fromhex(pdu)
    assert shortcut.forwards(data) is forwarded
    request = shortcut.request(data)
    assert isinstance(request, RawRegisterRead) is forwarded
    assert request.encode() == data  # as it came, on either route
    assert (shortcut.request(data) is request) is forwarded  # made once


def test_a_seam_given_in_place_of_a_line_gets_the_decoded_read() -> None:
    shortcut = ReadsAsBytes(Master(MockLine(lambda unit, request: None)))
    assert not shortcut.forwards(bytes.fromhex("03 0000 0001"))

"""The slave's answer-at-once changes nothing but its cost: a differential test.

Seeded random sequences of requests (every function code, broadcasts, other units, a
unit whose store takes no fast path, malformed PDUs, garbage and bad CRCs, listen-only
mode entered with 08/04 and left with 08/01, and bursts of two requests in one write
whose first takes the general route) go to the same slave with the shortcut on and off,
on a pty serial port (the push path, where whole requests are answered from the read
callback) and on a virtual line (on the virtual clock of tests/virtual_clock.py). Every
run must give the same bytes on the wire for each request, the same stores, diagnostic
counters and comm event log.

A failure names its seed; ``AIORTU_DIFFERENTIAL_SEED=N`` runs that seed alone.
"""

from __future__ import annotations

import contextlib
import dataclasses
import functools
import os
import random
import tty
from collections.abc import AsyncIterator, Callable
from typing import Any

import anyio
import pytest

from aiortu.core.machines import SlaveState
from aiortu.core.rtu import CANNOT_KNOW, ReceiverState, encode_frame, expected_response_length
from aiortu.core.serial import LineSettings
from aiortu.slave import Block, MemoryStore, Slave, Table
from aiortu.testing import virtual_pair
from aiortu.transport import open_stream
from tests.virtual_clock import VirtualTimeLoop

FAST = 17
"""A unit whose MemoryStore the fast paths serve."""
SLOW = 18
"""A unit whose store (a MemoryStore subclass) always takes the general route."""
OTHER = 5
"""A unit nobody on this line serves."""
STEPS = 150
SEEDS = (
    [int(os.environ["AIORTU_DIFFERENTIAL_SEED"])]
    if "AIORTU_DIFFERENTIAL_SEED" in os.environ
    else [1, 2, 3]
)


class _SlowStore(MemoryStore):
    """The same store, but not the built-in class: no fast path takes it."""


def _store(kind: type[MemoryStore] = MemoryStore) -> MemoryStore:
    return kind(
        coils=[Block(0, 40, [1, 0, 0, 1, 1] * 8), Block(100, 20)],
        discrete_inputs=Block(0, 30, [0, 1, 1] * 10),
        holding_registers=[Block(0, 60, range(60)), Block(200, 10)],
        input_registers={0: list(range(100, 120))},
        read_only={Table.HOLDING_REGISTERS: [range(50, 60)]},
        fifo_queues={0x04DE: [0x01B8, 0x1284]},
        files={4: 10},
        device_identification={0: "aiortu", 1: "test", 2: "1.0"},
        exception_status=0x6D,
    )


_DIAGNOSTICS = (0x00, 0x02, 0x03, 0x0A, 0x0B, 0x0C, 0x0D, 0x0E, 0x0F, 0x10, 0x11, 0x12, 0x14, 0x99)
"""Diagnostics sub-functions asked at random (04 and 01 come on their own)."""


def _h(value: int) -> str:
    return f"{value:04X}"


def _pdu(rng: random.Random) -> str:
    """A request PDU in hex: every function code, mostly well-formed."""
    address = rng.choice((0, 1, 5, 30, 38, 45, 55, 59, 60, 100, 118, 200, 205, 0xFFFF))
    count = rng.choice((0, 1, 2, 3, 10, 125, 126, 2000, 2001))
    values = rng.randrange(0x10000)
    makers: list[Callable[[], str]] = [
        lambda: f"{rng.choice((1, 2, 3, 4)):02X}{_h(address)}{_h(count)}",
        lambda: f"03{_h(address)}{_h(rng.choice((1, 3, 10)))}",
        lambda: f"05{_h(address)}{rng.choice(('FF00', '0000', '1234'))}",
        lambda: f"06{_h(address)}{_h(values)}",
        lambda: _write_registers(rng, address),
        lambda: _write_coils(rng, address),
        lambda: "07",
        lambda: f"08{_h(rng.choice(_DIAGNOSTICS))}{_h(values)}",
        lambda: "0B",
        lambda: "0C",
        lambda: "11",
        lambda: f"14 07 06 0004 {_h(rng.choice((0, 1, 9)))} 0002",
        lambda: f"15 09 06 0004 {_h(rng.choice((0, 7, 9)))} 0001 {_h(values)}",
        lambda: f"16 {_h(address)} 00F2 0025",
        lambda: f"17 {_h(address)} 0003 {_h(rng.choice((0, 14, 55)))} 0002 04 {_h(values)} 0001",
        lambda: f"18 {rng.choice(('04DE', '0001'))}",
        lambda: f"2B 0E 0{rng.choice((1, 4))} 00",
        lambda: f"{rng.choice((0x41, 0x64, 0x09)):02X} 01 02",
    ]
    weights = [12, 10, 3, 6, 5, 3, 2, 5, 2, 2, 1, 1, 1, 2, 2, 1, 1, 1]
    return rng.choices(makers, weights)[0]().replace(" ", "")


def _write_registers(rng: random.Random, address: int) -> str:
    count = rng.choice((1, 2, 3, 122))
    data = "".join(_h(rng.randrange(0x10000)) for _ in range(count))
    byte_count = 2 * count if rng.random() < 0.9 else 2 * count + 2
    return f"10{_h(address)}{_h(count)}{byte_count % 256:02X}{data}"


def _write_coils(rng: random.Random, address: int) -> str:
    count = rng.choice((1, 9, 17))
    data = rng.randbytes((count + 7) // 8).hex()
    return f"0F{_h(address)}{_h(count)}{(count + 7) // 8:02X}{data}"


def _burst(rng: random.Random) -> tuple[bytes, bytes]:
    """Two requests written at once: the first takes the general route, the second has a
    fast path, so it arrives while the first still waits in the serve loop's queue."""
    first, second = rng.choice(
        (
            ("07", f"03{_h(rng.choice((0, 5, 30)))}{_h(rng.choice((1, 3, 10)))}"),
            (f"10{_h(rng.choice((0, 5, 200)))}000204{_h(rng.randrange(9))}0007", "0600010009"),
            (f"03{_h(0)}{_h(2)}", f"03{_h(4)}{_h(2)}"),  # the first to the slow unit
        )
    )
    unit = SLOW if first == f"03{_h(0)}{_h(2)}" else FAST
    return encode_frame(unit, bytes.fromhex(first)), encode_frame(FAST, bytes.fromhex(second))


def _step(rng: random.Random) -> tuple[bytes, ...]:
    """One item the master puts on the line in one write: one or two frames, or garbage."""
    roll = rng.random()
    if roll > 0.92:
        return _burst(rng)
    return (_single(rng, roll),)


def _single(rng: random.Random, roll: float) -> bytes:
    """A request, or garbage."""
    if roll < 0.04:
        return encode_frame(FAST, bytes.fromhex("08 0004 0000"))  # listen-only
    if roll < 0.10:
        data = rng.choice(("0000", "FF00"))
        return encode_frame(rng.choice((FAST, SLOW)), bytes.fromhex(f"08 0001 {data}"))
    if roll < 0.13:
        return rng.randbytes(rng.randrange(1, 12))  # garbage
    unit = rng.choices((FAST, SLOW, 0, OTHER), (70, 15, 8, 7))[0]
    pdu = bytes.fromhex(_pdu(rng))
    frame = encode_frame(unit, pdu)
    if roll < 0.16:
        return frame[:-1] + bytes((frame[-1] ^ 0x20,))  # bad CRC
    if roll < 0.19:
        return encode_frame(unit, pdu[:-1] if rng.random() < 0.5 else (pdu + b"\x00")[:253])
    return frame


@dataclasses.dataclass
class _Run:
    """What one run gave: each item's reply bytes, and the slave's state at the end."""

    replies: list[bytes]
    frames_sent: int
    answered_at_once: int
    counters: dict[str, int]
    events: bytes
    event_count: int
    listen_only: bool
    stores: dict[int, Any]


def _contents(store: Any) -> Any:
    tables = {table.value: [list(b.values) for b in store.blocks(table)] for table in Table}
    return tables, {n: list(q) for n, q in store.fifo_queues.items()}, store.files


@contextlib.asynccontextmanager
async def _pty_line(
    fast: bool, frame_gap: float = 0.0
) -> AsyncIterator[tuple[Slave, Callable[[bytes], object], Any]]:
    master_fd, port_fd = os.openpty()
    tty.setraw(port_fd)
    os.set_blocking(master_fd, False)
    settings = LineSettings(19200, 8, "N", 2)
    try:
        stream = await open_stream(os.ttyname(port_fd), settings)
        units = {FAST: _store(), SLOW: _store(_SlowStore)}
        slave = Slave(stream, units, settings, frame_gap=frame_gap)
        slave._at_once.enabled = fast

        async def read() -> bytes:
            await anyio.wait_readable(master_fd)
            with contextlib.suppress(BlockingIOError):
                return os.read(master_fd, 512)
            return b""

        async with slave:
            await anyio.sleep(0.03)  # the receiver first waits for silence
            yield slave, functools.partial(os.write, master_fd), read
    finally:
        for fd in (master_fd, port_fd):
            with contextlib.suppress(OSError):
                os.close(fd)


def _gapped_pty_line(fast: bool) -> Any:
    return _pty_line(fast, frame_gap=0.002)


@contextlib.asynccontextmanager
async def _virtual_line(fast: bool) -> AsyncIterator[tuple[Slave, Callable[[bytes], object], Any]]:
    master_end, slave_end = virtual_pair()
    units = {FAST: _store(), SLOW: _store(_SlowStore)}
    slave = Slave(slave_end, units, frame_gap=0, frame_silence=0.003)
    slave._at_once.enabled = fast
    async with anyio.create_task_group() as group, slave:
        send, receive = anyio.create_memory_object_stream[bytes](100)
        group.start_soon(_forward_sends, master_end, receive)
        await anyio.sleep(0.02)  # the receiver first waits for silence
        yield slave, send.send_nowait, master_end.receive
        group.cancel_scope.cancel()
    await master_end.aclose()


async def _forward_sends(endpoint: Any, frames: Any) -> None:
    async for frame in frames:
        await endpoint.send(frame)


def _seen(slave: Slave) -> int:
    return slave.link.frames_received + sum(slave.link.discarded.values())


async def _settle(slave: Slave, seen_before: int, frames: int) -> None:
    """Wait until the slave has taken the item's *frames* and finished with them."""
    with anyio.fail_after(5):
        while not (  # noqa: ASYNC110 - polls the slave's state: no event tells it
            _seen(slave) >= seen_before + frames
            and slave.link.receiver.state is ReceiverState.IDLE
            and slave.machine.state is SlaveState.IDLE
            and not slave._queue
        ):
            await anyio.sleep(0.001)


async def _reply(read: Any, sent: int) -> bytes:
    """The *sent* reply frames the slave put on the wire for one item (after a burst, one
    read may bring both)."""
    data = b""
    start = 0
    with anyio.fail_after(5):
        for _ in range(sent):
            while (length := expected_response_length(data[start:])) <= 0 or (
                len(data) - start < length
            ):
                assert length != CANNOT_KNOW, data[start:].hex(" ")
                data += await read()
            start += length
    assert start == len(data), data.hex(" ")
    return data


async def _run(line: Any, fast: bool, items: list[tuple[bytes, ...]]) -> _Run:
    replies = []
    async with line(fast) as (slave, write, read):
        for item in items:
            seen, sent = _seen(slave), slave.link.frames_sent
            write(b"".join(item))  # a burst: no silence between its frames
            await _settle(slave, seen, len(item))
            replies.append(await _reply(read, slave.link.frames_sent - sent))
        # Nothing more can come: _settle left the slave idle with nothing queued, and every
        # frame it sent was read.
        machine = slave.machine
        return _Run(
            replies,
            slave.link.frames_sent,
            slave._at_once.answered,
            dataclasses.asdict(slave.counters),
            machine.event_log.events(),
            machine.event_log.event_count,
            machine.listen_only,
            {unit: _contents(store) for unit, store in slave.units.items()},
        )


def _differences(seed: int, items: list[tuple[bytes, ...]], runs: dict[str, _Run]) -> list[str]:
    first_name, first = next(iter(runs.items()))
    found = []
    for name, run in runs.items():
        for index, (a, b) in enumerate(zip(first.replies, run.replies, strict=True)):
            if a != b:
                what = "the end"
                if index < len(items):
                    what = " | ".join(frame.hex(" ") for frame in items[index])
                found.append(
                    f"seed {seed}: item {index} ({what}): "
                    f"{first_name} replied {a.hex(' ')!r}, {name} {b.hex(' ')!r}"
                )
                break
        fields = ("frames_sent", "counters", "events", "event_count", "listen_only", "stores")
        for field in fields:
            if getattr(first, field) != getattr(run, field):
                found.append(f"seed {seed}: {field} differ between {first_name} and {name}")
    return found


def _on_the_virtual_clock(fast: bool, items: list[tuple[bytes, ...]]) -> _Run:
    """A run on the virtual line, on the virtual clock: its silences take no real time."""
    options = {"loop_factory": VirtualTimeLoop}
    return anyio.run(_run, _virtual_line, fast, items, backend_options=options)


@pytest.mark.parametrize("seed", SEEDS)
def test_the_shortcut_on_and_off_on_a_pty_and_a_virtual_line(seed: int) -> None:
    rng = random.Random(seed)
    items = [_step(rng) for _ in range(STEPS)]
    runs = {
        "pty, shortcut on": anyio.run(_run, _pty_line, True, items),
        "pty, shortcut off": anyio.run(_run, _pty_line, False, items),
        # With a frame gap to keep, a reply computed at once waits in the serve loop.
        "pty with a frame gap, shortcut on": anyio.run(_run, _gapped_pty_line, True, items),
        "virtual line, shortcut on": _on_the_virtual_clock(True, items),
        "virtual line, shortcut off": _on_the_virtual_clock(False, items),
    }
    differences = _differences(seed, items, runs)
    assert not differences, "\n".join(differences)
    replies = runs["pty, shortcut on"].replies
    assert sum(1 for reply in replies if reply) > STEPS // 3, f"seed {seed}: too few replies"
    # The shortcut ran where it was on, and only there.
    assert runs["pty, shortcut on"].answered_at_once > STEPS // 10, f"seed {seed}"
    assert runs["virtual line, shortcut on"].answered_at_once > STEPS // 10, f"seed {seed}"
    assert runs["pty with a frame gap, shortcut on"].answered_at_once > STEPS // 10
    assert runs["pty, shortcut off"].answered_at_once == 0
    assert runs["virtual line, shortcut off"].answered_at_once == 0

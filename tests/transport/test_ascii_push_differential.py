"""Modbus ASCII pushed against ASCII read by a task, differentially.

The master: the plans of the master's own differential test (silent devices, noise, another
unit's reply, misshapen and late replies, exceptions, cancelled callers, queued callers) play
over ASCII, on a pty serial port and on a virtual line, with the ASCII stream pushed (the
master's fast path on and off) and read by the link's task. The slave: seeded random requests
(every function code, broadcasts, other units, a unit no fast path serves) and ASCII faults
(noise, a wrong LRC, malformed hex, a ':' that restarts a frame, a character after CR that is
not the delimiter, lower case, frames split across writes, a frame stalled past the
inter-character timeout) go to a slave on a pty, pushed and read by a task, answer-at-once on
and off. Every run must give the same results, statistics, stores, counters, event logs, ASCII
counters and bytes on the wire.

A failure names its seed; ``AIORTU_DIFFERENTIAL_SEED=N`` runs that seed alone.
"""

from __future__ import annotations

import contextlib
import dataclasses
import os
import random
import tty
from collections.abc import AsyncIterator, Iterator
from typing import Any

import anyio
import pytest

from aiortu.core.ascii import AsciiReceiver, decode_ascii_frame, encode_ascii_frame
from aiortu.core.machines import SlaveState
from aiortu.core.rtu import encode_frame
from aiortu.core.serial import LineSettings
from aiortu.master import Master
from aiortu.slave import Slave
from aiortu.testing import VirtualBus
from aiortu.transport import AsciiStream, PushAsciiStream, ascii_stream, open_serial
from aiortu.transport import _ascii_push as push_module
from tests.master import test_fast_path_differential as rtu_master
from tests.slave import test_fast_path_differential as rtu_slave
from tests.transport.ptys import LINE, open_pty
from tests.virtual_clock import VirtualTimeLoop

pytestmark = pytest.mark.timeout(120)

SEED = int(os.environ.get("AIORTU_DIFFERENTIAL_SEED", "2111"))
STALL_TIMEOUT = 0.15
"""The slave's inter-character timeout: a stalled frame waits until it has passed and the frame
is discarded, the parts of a split frame 2 ms."""


@contextlib.contextmanager
def pushed(on: bool) -> Iterator[None]:
    """ASCII streams made in the block are pushed where they can be (`on`), or never."""
    with pytest.MonkeyPatch.context() as patch:
        if not on:
            patch.setattr(push_module, "pushes_ascii", lambda stream: False)
        yield


def _ascii(data: bytes) -> bytes:
    """What the master's differential device writes, in ASCII: its noise as it is, then each
    RTU frame as an ASCII frame."""
    noise = rtu_master.NOISE if data.startswith(rtu_master.NOISE) else b""
    frame = data[len(noise) :]
    return noise + encode_ascii_frame(frame[0], frame[1:-2])


class AsciiDevice(rtu_master.Device):
    """The master's differential device, speaking ASCII: requests are read as ASCII frames and
    handed over as RTU frames, replies written as ASCII frames."""

    def __init__(self, read_some: Any, write: Any) -> None:
        super().__init__(self._read_rtu, write)
        self._read_some = read_some
        self._text = bytearray()
        self._frames = bytearray()

    async def _read_rtu(self, count: int) -> bytes:
        while len(self._frames) < count:
            end = self._text.find(b"\n")
            if end < 0:
                self._text += await self._read_some()
                continue
            frame = decode_ascii_frame(bytes(self._text[: end + 1]))
            del self._text[: end + 1]
            self._frames += encode_frame(frame.unit, frame.pdu)
        data = bytes(self._frames[:count])
        del self._frames[:count]
        return data


def _master_options(fast: bool) -> dict[str, Any]:
    return {
        "timeout": rtu_master.TIMEOUT,
        "retries": 1,
        "late_reply_guard": rtu_master.GUARD,
        "fast_path": fast,
    }


def _ascii_counters(stream: AsciiStream) -> tuple[int, dict[str, int]]:
    return stream.frames_received, {str(reason): n for reason, n in stream.discarded.items()}


async def master_on_a_pty(
    push: bool, fast: bool, ops: list[rtu_master.Op], player: rtu_master.Player
) -> tuple[object, ...]:
    with open_pty() as pty, pushed(push):
        stream = ascii_stream(await open_serial(pty.path, LINE), LINE)
        assert isinstance(stream, PushAsciiStream) == push
        async with Master(stream, LINE, **_master_options(fast)) as master:  # type: ignore[arg-type]

            async def read_some() -> bytes:
                await anyio.wait_readable(pty.master)
                with contextlib.suppress(BlockingIOError):
                    return os.read(pty.master, 512)
                return b""

            async def write(data: bytes) -> None:
                pty.write(_ascii(data))

            device = AsciiDevice(read_some, write)
            results = await player(master, device, ops)
            return (
                results,
                rtu_master.summary(master),
                device.seen,
                master.engine.transactions,
                _ascii_counters(stream),
            )


async def master_on_a_virtual_bus(
    push: bool, fast: bool, ops: list[rtu_master.Op], player: rtu_master.Player
) -> tuple[object, ...]:
    bus = VirtualBus(2)
    end = bus.endpoints[1]
    with pushed(push):
        stream = ascii_stream(bus.endpoints[0])
    assert isinstance(stream, PushAsciiStream) == push

    async def write(data: bytes) -> None:
        await end.send(_ascii(data))

    async with Master(stream, LineSettings(19200), **_master_options(fast)) as master:  # type: ignore[arg-type]
        device = AsciiDevice(end.receive, write)
        results = await player(master, device, ops)
        return (
            results,
            rtu_master.summary(master),
            device.seen,
            master.engine.transactions,
            _ascii_counters(stream),
        )


def _compare_masters(ops: list[rtu_master.Op], player: rtu_master.Player) -> None:
    runs = {}
    for push, fast in ((True, True), (True, False), (False, True)):
        runs["pty", push, fast] = anyio.run(master_on_a_pty, push, fast, ops, player)
    # The virtual bus on the virtual clock: its timeouts and guards take no real time.
    runs["virtual bus", True, True] = anyio.run(
        master_on_a_virtual_bus,
        True,
        True,
        ops,
        player,
        backend_options={"loop_factory": VirtualTimeLoop},
    )
    reference = runs["pty", False, True]
    names = ("results", "statistics", "requests on the wire", "transactions", "ASCII counters")
    for key, run in runs.items():
        for name, ours, theirs in zip(names, run, reference, strict=True):
            assert ours == theirs, f"{name} differ: {key} against ASCII read by a task on a pty"


@pytest.mark.parametrize("half", [0, 1])
def test_the_master_over_ascii_pushed_and_read_by_a_task_agree(half: int) -> None:
    seed = SEED + half
    ops = rtu_master.scenario(seed, 8, rtu_master.FAULTS[half::2])
    try:
        _compare_masters(ops, rtu_master.play)
    except BaseException:
        rtu_master.print_failing(seed, ops)
        raise


def test_many_callers_at_once_over_ascii_agree() -> None:
    seed = SEED + 2
    rng = random.Random(seed)
    ops = [
        rtu_master.Op(
            rng.choice(rtu_master.KINDS),
            rng.choice(rtu_master.UNITS),
            rng.randrange(0, 200),
            rng.randint(1, 4),
            rng.choices(rtu_master.BURST_PLANS, [12, 1, 1, 1, 1, 1])[0],
        )
        for _ in range(10)
    ]
    try:
        _compare_masters(ops, rtu_master.play_burst)
    except BaseException:
        rtu_master.print_failing(seed, ops)
        raise


# -- the slave ------------------------------------------------------------------------------


@dataclasses.dataclass(frozen=True)
class Item:
    """What the master side writes in one go (`parts`, written a few milliseconds apart),
    and whether the frame under way then stalls past the inter-character timeout."""

    parts: tuple[bytes, ...]
    stalls: bool = False


def _request(rng: random.Random) -> tuple[int, bytes]:
    unit = rng.choices((rtu_slave.FAST, rtu_slave.SLOW, 0, rtu_slave.OTHER), (70, 15, 8, 7))[0]
    return unit, bytes.fromhex(rtu_slave._pdu(rng))


def _item(rng: random.Random) -> Item:
    """A request, mostly well-formed, sometimes with an ASCII fault around or in it."""
    unit, pdu = _request(rng)
    frame = encode_ascii_frame(unit, pdu)
    roll = rng.random()
    if roll < 0.05:
        return Item((b"junk \x00\xff" + frame,))  # noise, then the request
    if roll < 0.09:
        lrc = b"00" if frame[-4:-2] != b"00" else b"01"
        return Item((frame[:-4] + lrc + frame[-2:],))  # a wrong LRC
    if roll < 0.12:
        return Item((frame[:5] + b"G" + frame[6:],))  # not a hex digit
    if roll < 0.15:
        return Item((frame[:-3] + frame[-2:],))  # an odd number of hex digits
    if roll < 0.18:
        return Item((frame[: rng.randrange(2, 9)] + frame,))  # ':' restarts the frame
    if roll < 0.21:
        return Item((frame[:-1] + b"x" + frame,))  # CR, then not the delimiter
    if roll < 0.26:
        return Item((frame.lower(),))
    if roll < 0.36:
        cut = rng.randrange(1, len(frame))
        return Item((frame[:cut], frame[cut:]))  # one frame in two writes
    if roll < 0.39:
        return Item((frame[: rng.randrange(1, len(frame) - 2)],), stalls=True)
    if roll < 0.44:
        second_unit, second_pdu = _request(rng)
        return Item((frame + encode_ascii_frame(second_unit, second_pdu),))  # two at once
    return Item((frame,))


def _outputs(item: Item) -> int:
    """How many frames and discards the receiver gives for `item` (it starts and ends idle)."""
    receiver = AsciiReceiver(timeout=STALL_TIMEOUT)
    count = sum(len(receiver.feed(part, 0.0)) for part in item.parts)
    return count + len(receiver.expire(1.0))


@dataclasses.dataclass
class SlaveRun:
    replies: list[bytes]
    frames_sent: int
    answered_at_once: int
    counters: dict[str, int]
    events: bytes
    event_count: int
    stores: dict[int, Any]
    ascii: tuple[int, dict[str, int]]


@contextlib.asynccontextmanager
async def _slave_on_a_pty(push: bool, fast: bool) -> AsyncIterator[tuple[Slave, int]]:
    master_fd, port_fd = os.openpty()
    tty.setraw(port_fd)
    os.set_blocking(master_fd, False)
    settings = LineSettings(19200, 8, "N", 2)
    try:
        with pushed(push):
            stream = ascii_stream(
                await open_serial(os.ttyname(port_fd), settings), settings, timeout=STALL_TIMEOUT
            )
        assert isinstance(stream, PushAsciiStream) == push
        units = {
            rtu_slave.FAST: rtu_slave._store(),
            rtu_slave.SLOW: rtu_slave._store(rtu_slave._SlowStore),
        }
        slave = Slave(stream, units, settings)
        slave._at_once.enabled = fast
        async with slave:
            yield slave, master_fd
    finally:
        for fd in (master_fd, port_fd):
            with contextlib.suppress(OSError):
                os.close(fd)


def _seen(stream: AsciiStream) -> int:
    return stream.frames_received + sum(stream.discarded.values())


async def _settle(slave: Slave, stream: AsciiStream, seen_before: int, outputs: int) -> None:
    with anyio.fail_after(5):
        while not (  # noqa: ASYNC110 - polls the slave's state: no event tells it
            _seen(stream) >= seen_before + outputs
            and slave.machine.state is SlaveState.IDLE
            and not slave._queue
        ):
            await anyio.sleep(0.001)


async def _replies(master_fd: int, count: int) -> bytes:
    data = b""
    with anyio.fail_after(5):
        while data.count(b"\n") < count:
            await anyio.wait_readable(master_fd)
            with contextlib.suppress(BlockingIOError):
                data += os.read(master_fd, 1024)
    return data


async def _slave_run(push: bool, fast: bool, items: list[Item]) -> SlaveRun:
    replies = []
    async with _slave_on_a_pty(push, fast) as (slave, master_fd):
        stream = slave.link.stream
        assert isinstance(stream, AsciiStream)
        for item in items:
            seen, sent = _seen(stream), slave.link.frames_sent
            for index, part in enumerate(item.parts):
                if index:
                    await anyio.sleep(0.002)
                os.write(master_fd, part)
            # A stalled frame: nothing more is written until its timeout has discarded it
            # (the discard is one of the item's outputs that _settle waits for).
            await _settle(slave, stream, seen, _outputs(item))
            replies.append(await _replies(master_fd, slave.link.frames_sent - sent))
        machine = slave.machine
        return SlaveRun(
            replies,
            slave.link.frames_sent,
            slave._at_once.answered,
            dataclasses.asdict(slave.counters),
            machine.event_log.events(),
            machine.event_log.event_count,
            {unit: rtu_slave._contents(store) for unit, store in slave.units.items()},
            _ascii_counters(stream),
        )


@pytest.mark.parametrize("seed", [SEED, SEED + 1])
async def test_the_slave_over_ascii_pushed_and_read_by_a_task_agree(seed: int) -> None:
    rng = random.Random(seed)
    items = [_item(rng) for _ in range(120)]
    runs = {
        (push, fast): await _slave_run(push, fast, items)
        for push, fast in ((True, True), (True, False), (False, True))
    }
    reference = runs[False, True]
    for key, run in runs.items():
        for index, (ours, theirs) in enumerate(zip(run.replies, reference.replies, strict=True)):
            assert ours == theirs, f"seed {seed}: item {index} {items[index]}: replies differ"
        for field in dataclasses.fields(SlaveRun):
            if field.name not in ("replies", "answered_at_once"):
                ours, theirs = getattr(run, field.name), getattr(reference, field.name)
                assert ours == theirs, f"seed {seed}: {field.name} differ: {key}"
    # The shortcut ran where it could, and only there; the faults came up.
    assert runs[True, True].answered_at_once > 20, f"seed {seed}"
    assert runs[True, False].answered_at_once == 0, f"seed {seed}"
    discards = reference.ascii[1]
    assert set(discards) >= {"noise", "lrc", "malformed", "restart", "no end", "timeout"}
    assert sum(1 for reply in reference.replies if reply) > 40, f"seed {seed}"

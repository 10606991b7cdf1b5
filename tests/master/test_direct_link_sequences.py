"""The direct link's reply tap (`PushReader.on_frame`) against the link's general route
(`PushReader.on_chunk`), differentially, on a virtual clock.

On a direct link the stream calls `on_frame`, which takes the reply the master expects with the
receiver's check alone and never touches the receiver's silence timer; anything else goes to
`on_chunk`, which arms it. What makes that safe: the receiver takes an expected frame only while it
is IDLE, and an IDLE receiver has no deadline, so `on_frame` never takes a frame while a timer is
armed. A frame the receiver leaves mid-frame (a bad CRC, a short or split frame, garbage) arms a
timer at once (a stream of whole frames ends a frame on no silence at all); the expected reply
that comes right behind it, in the same read, before that timer fires, finds the receiver
mid-frame and goes to `on_chunk`, where the next chunk closes the pending frame first.

Seeded scripts of register reads to a device that answers each request by a plan drawn for it
run twice: with the direct route, and with the predicate forced off. The device pushes whole
frames from event-loop callbacks, several in one callback where the plan says "one read" (as
one TCP read holds several ADUs), and may end the stream right behind a malformed frame, before
the receiver's timer fires. Both runs must give the same results, unit statistics, link counters
and requests, and the direct run must have met the sequences it is about.
"""

from __future__ import annotations

import asyncio
import dataclasses
import random
from typing import Any

import anyio
import pytest

from aiortu.core.rtu import encode_frame
from aiortu.errors import ConnectionLost, ModbusError
from aiortu.line import Link
from aiortu.line import _link as link_module
from aiortu.master import Master
from tests.line.fakes import PushedFrames, silence_timer
from tests.virtual_clock import VirtualTimeLoop

SEEDS = range(8)
OPERATIONS = 60
SHAPES = ((1, 0, 2), (1, 4, 3), (2, 0, 2))
"""(unit, address, count) of the reads: replies of two lengths, from two units."""
TIMEOUT = 0.05
STEP = 0.001
"""The device's pace: a reply comes 0 or 1 STEP after its request, a second read 1 STEP later."""

PLANS: dict[str, tuple[tuple[str, ...], ...]] = {
    # Each plan: the reads the device's replies come in, each a tuple of frames pushed in one
    # callback. "end" ends the stream there (after the frames before it in the same read).
    "usual": (("usual",),),
    "other values": (("other values",),),
    "exception": (("exception",),),
    "silent": (),
    "bad CRC, then usual, one read": (("bad CRC", "usual"),),
    "bad CRC, then usual, two reads": (("bad CRC",), ("usual",)),
    "short, then usual, one read": (("short", "usual"),),
    "short, then usual, two reads": (("short",), ("usual",)),
    "garbage, then usual, one read": (("garbage", "usual"),),
    "another unit, then usual, one read": (("another unit", "usual"),),
    "late, then usual, one read": (("late", "usual"),),
    "split, one read": (("head", "tail"),),
    "split, two reads": (("head",), ("tail",)),
    "joined with a stray": (("usual+stray",),),
    "usual twice, one read": (("usual", "usual"),),
    "misshapen": (("misshapen",),),
    "bad CRC, then the end": (("bad CRC", "end"),),
    "short, then the end, then usual": (("short", "end", "usual"),),
    "usual, then the end": (("usual", "end"),),
}
WEIGHTS = {"usual": 8, "other values": 2}  # the rest weigh 1


def _reply(unit: int, values: list[int]) -> bytes:
    data = b"".join(value.to_bytes(2, "big") for value in values)
    return encode_frame(unit, bytes((0x03, len(data))) + data)


@dataclasses.dataclass
class _Script:
    """The device's draws and what it saw, shared by the streams of one run."""

    rng: random.Random
    seen: list[bytes] = dataclasses.field(default_factory=list)
    plans: list[str] = dataclasses.field(default_factory=list)
    before: bytes | None = None
    """The usual reply to the request before (for a late one)."""
    armed: int = 0
    """Frames of the expected reply's shape pushed into an armed silence timer."""
    taken: int = 0
    """Frames the reply tap took, by the direct route's own path or the general one."""
    ends: int = 0

    def frames(self, request: bytes, name: str) -> list[bytes]:
        unit, count = request[0], request[5]
        usual = _reply(unit, list(range(7, 7 + count)))
        if name == "usual":
            return [usual]
        if name == "other values":
            return [_reply(unit, [self.rng.randrange(65536) for _ in range(count)])]
        if name == "exception":
            return [encode_frame(unit, bytes((0x83, 2)))]
        if name == "bad CRC":
            return [usual[:-1] + bytes((usual[-1] ^ 0x5A,))]
        if name == "short":  # the first bytes of the usual reply, one register missing
            return [encode_frame(unit, usual[1:-4])]
        if name == "garbage":
            return [b"\x00\xff\x13"]
        if name == "another unit":
            return [_reply(unit ^ 3, list(range(count)))]
        if name == "late":
            return [self.before] if self.before is not None else []
        if name in ("head", "tail"):
            cut = 1 + (len(request) * 7) % (len(usual) - 1)  # the same cut for head and tail
            return [usual[:cut] if name == "head" else usual[cut:]]
        if name == "usual+stray":
            return [usual + _reply(unit ^ 3, [0] * count)]
        assert name == "misshapen"  # the function code of the usual reply, a register too many
        return [_reply(unit, list(range(count + 1)))]


class _Device(PushedFrames):
    """A master's stream of whole frames, pushed (as its Modbus TCP stream is on asyncio),
    with the device at its other end: each request is answered by a plan from the script."""

    def __init__(self, script: _Script) -> None:
        super().__init__(self._answer, turn_at_end=False)
        self.script = script
        self.link: Link | None = None

    def _answer(self, request: bytes) -> None:
        script = self.script
        script.seen.append(request)
        plans = list(PLANS)
        plan = script.rng.choices(plans, [WEIGHTS.get(name, 1) for name in plans])[0]
        script.plans.append(plan)
        loop = asyncio.get_running_loop()
        first = script.rng.choice((0.0, STEP))
        for number, read in enumerate(PLANS[plan]):
            loop.call_later(first + number * STEP, self._push, request, read)
        count = request[5]
        script.before = _reply(request[0], [666] * count)

    def _push(self, request: bytes, read: tuple[str, ...]) -> None:
        """One read of the stream's socket: its frames handed over in one callback."""
        for name in read:
            if self.ended.is_set():
                return
            if name == "end":
                self.script.ends += 1
                self.end()
                continue
            for frame in self.script.frames(request, name):
                self._hand_over(frame)

    def _hand_over(self, frame: bytes) -> None:
        if self.receiver is None:
            return  # no reader: the link has ended
        link = self.link
        assert link is not None
        reader = link._push_reader
        assert reader is not None
        tap = reader.reply_tap
        expected = tap is not None and len(frame) == tap.length and frame.startswith(tap.prefix)
        if expected and reader.timer is not None:
            self.script.armed += 1
        self.push(frame)
        if expected and reader.reply_tap is None:
            self.script.taken += 1
        silence_timer(link)


async def _run(seed: int) -> tuple[Any, ...]:
    """One run of the script: what the callers got, what the master and links counted, and what
    the device saw."""
    script = _Script(random.Random(seed))
    devices: list[_Device] = []

    async def opener() -> _Device:
        devices.append(_Device(script))
        return devices[-1]

    options = {"timeout": TIMEOUT, "retries": 1, "reconnect_delay": (STEP, STEP)}
    master = Master(await opener(), opener=opener, **options)
    results: list[Any] = []
    directs: set[bool] = set()
    rng = random.Random(seed + 1000)
    async with master:
        for _ in range(OPERATIONS):
            unit, address, count = SHAPES[rng.randrange(len(SHAPES))]
            await master.connection.wait_connected()
            link = master.link
            devices[-1].link = link
            try:
                results.append(await master.read_holding_registers(unit, address, count))
                directs.add(link.direct)  # the link is open once it has answered
            except ModbusError as error:
                results.append(type(error).__name__)
                if isinstance(error, ConnectionLost):
                    await anyio.sleep(10 * STEP)  # the reconnect's delay
            results.append(anyio.current_time())  # a virtual clock: exact
        stats = {
            unit: {
                name: value
                for name, value in dataclasses.asdict(master.unit_stats(unit)).items()
                if name != "last_probe"
            }
            for unit in (1, 2)
        }
    links = [device.link for device in devices if device.link is not None]
    counters = [
        (each.frames_sent, each.frames_received, each.writes_begun, dict(each.discarded))
        for each in links
    ]
    coverage = (script.armed, script.taken, script.ends)
    return results, stats, counters, script.seen, script.plans, coverage, directs


def _on_virtual_loop(seed: int) -> tuple[Any, ...]:
    return anyio.run(
        _run, seed, backend="asyncio", backend_options={"loop_factory": VirtualTimeLoop}
    )


@pytest.mark.parametrize("seed", SEEDS)
def test_the_reply_tap_and_the_general_route_agree(
    seed: int, monkeypatch: pytest.MonkeyPatch
) -> None:
    direct = _on_virtual_loop(seed)
    monkeypatch.setattr(link_module, "_direct", lambda link: False)
    general = _on_virtual_loop(seed)
    assert direct[-1] == {True}, f"seed {seed}: the direct route ran"
    assert general[-1] == {False}, f"seed {seed}: the general route ran"
    for name, mine, theirs in zip(
        ("results", "unit statistics", "link counters", "requests", "plans", "coverage"),
        direct[:-1],
        general[:-1],
        strict=True,
    ):
        assert mine == theirs, f"seed {seed}: the {name} differ"


def test_the_scripts_meet_the_sequences_the_tap_is_about() -> None:
    """Over the seeds: expected replies taken by the tap, expected replies pushed while the
    receiver's timer was armed (behind a malformed frame, in one read), and ends of the stream
    behind a malformed frame."""
    armed = taken = ends = 0
    plans: set[str] = set()
    for seed in SEEDS:
        results, _, _, _, drawn, (each_armed, each_taken, each_ends), _ = _on_virtual_loop(seed)
        armed, taken, ends = armed + each_armed, taken + each_taken, ends + each_ends
        plans.update(drawn)
        assert any(isinstance(result, list) for result in results), f"seed {seed}"
    assert plans == set(PLANS)
    assert armed >= 10
    assert taken >= 100
    assert ends >= 3

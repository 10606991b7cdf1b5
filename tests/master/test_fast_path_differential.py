"""The master's fast path (the usual exchange) against the machine's route, differentially.

Seeded random sequences of reads and writes, each with a device plan (a fault or not)
and sometimes a cancellation, run four times: with ``fast_path`` on and off, on a serial
port over a pty (the push path, where the fast path runs) and on a VirtualBus (on the
virtual clock of tests/virtual_clock.py: its timeouts and guards are exact and take no real
time). Every run must give the same results, the same per-unit statistics and the same
requests on the wire. The device plays each plan reacting to what it sees (the request,
the caller gone, the master's retry), not to the clock, so that the outcome does not depend
on the machine's load.
"""

from __future__ import annotations

import dataclasses
import os
import random
from collections.abc import Awaitable, Callable
from dataclasses import dataclass

import anyio
import anyio.abc
import pytest

from aiortu.core.pdu import decode_request
from aiortu.core.rtu import encode_frame
from aiortu.core.serial import LineSettings
from aiortu.errors import ModbusError
from aiortu.master import Master
from aiortu.testing import VirtualBus
from aiortu.transport import open_serial
from tests.master.fakes import standard_reply
from tests.transport.ptys import LINE, Pty, open_pty, read_master
from tests.virtual_clock import VirtualTimeLoop

TIMEOUT = 0.25
"""The response timeout of the plans where an attempt must time out. Their retry must
still get its answer within it: a stall of the machine longer than this fails the run, so
it is kept well above the 2 ms the device takes (each timed-out attempt costs it four
times over across the runs)."""
PATIENT = 2.0
"""The response timeout of the others: the device's answer is never late for it."""
TIMING_OUT = frozenset(
    ("silent, then ok", "silent twice", "late, then ok", "cancelled, then silent")
)
GUARD = 0.15
"""The late-reply guard: a late reply sent once the retry is decided lands in it."""
NOISE = b"\x00\xff\x13"
UNITS = (1, 2, 3)
KINDS = ("read", "read_input", "write", "write_many")

# What the device does with each request frame of an operation, in order.
PLANS: dict[str, tuple[str, ...]] = {
    "ok": ("answer",),
    "silent, then ok": ("silent", "answer"),
    "silent twice": ("silent", "silent"),
    "noise before the reply": ("noise_answer",),
    "another unit first": ("other_unit_answer",),
    "misshapen, then ok": ("misshapen", "answer"),
    "late, then ok": ("late", "answer"),
    "exception": ("exception",),
    "cancelled while waiting": ("cancel_answer",),
    "cancelled, then silent": ("cancel_silent",),
    "a queued caller cancelled": ("cancel_queued_answer",),
}
WEIGHTS = {"ok": 6}  # the rest weigh 1


@dataclass(frozen=True)
class Op:
    kind: str
    unit: int
    address: int
    count: int
    plan: str


def scenario(seed: int, length: int, must: list[str]) -> list[Op]:
    """*length* operations: one with each plan in *must*, the others drawn at random, in
    a random order."""
    rng = random.Random(seed)
    plans = list(PLANS)
    weights = [WEIGHTS.get(plan, 1) for plan in plans]
    chosen = must + rng.choices(plans, weights, k=length - len(must))
    rng.shuffle(chosen)
    return [
        Op(rng.choice(KINDS), rng.choice(UNITS), rng.randrange(0, 200), rng.randint(1, 4), plan)
        for plan in chosen
    ]


def perform(master: Master, op: Op) -> Awaitable[object]:
    timeout = TIMEOUT if op.plan in TIMING_OUT else PATIENT
    if op.kind == "read":
        return master.read_holding_registers(op.unit, op.address, op.count, timeout=timeout)
    if op.kind == "read_input":
        return master.read_input_registers(op.unit, op.address, op.count, timeout=timeout)
    if op.kind == "write":
        return master.write_register(op.unit, op.address, op.count, timeout=timeout)
    values = list(range(op.count))
    return master.write_registers(op.unit, op.address, values, timeout=timeout)


class Device:
    """The other end of the line: reads whole request frames, writes replies."""

    def __init__(
        self, read: Callable[[int], Awaitable[bytes]], write: Callable[[bytes], Awaitable[None]]
    ) -> None:
        self.read = read
        self.write = write
        self.seen: list[bytes] = []

    async def request(self) -> bytes:
        head = await self.read(7)
        rest = head[6] + 2 if head[1] == 0x10 else 1
        frame = head + await self.read(rest)
        self.seen.append(frame)
        return frame


@dataclass
class Call:
    """One operation's caller, run in a task."""

    scope: anyio.CancelScope = dataclasses.field(default_factory=anyio.CancelScope)
    done: anyio.Event = dataclasses.field(default_factory=anyio.Event)
    result: object = None
    retries_before: int = 0
    """The unit's retries when the call began (see the "late" action)."""

    async def run(self, call: Callable[[], Awaitable[object]]) -> None:
        with self.scope:
            try:
                self.result = repr(await call())
            except ModbusError as error:
                self.result = type(error).__name__
        if self.scope.cancelled_caught:
            self.result = "cancelled"
        self.done.set()


async def _until(condition: Callable[[], bool]) -> None:
    with anyio.fail_after(5):
        while not condition():  # noqa: ASYNC110
            await anyio.sleep(0.001)


async def act(
    action: str,
    frame: bytes,
    device: Device,
    master: Master,
    call: Call,
    tasks: anyio.abc.TaskGroup,
) -> None:
    unit = frame[0]
    pdu = standard_reply(unit, decode_request(frame[1:-2]))
    reply = encode_frame(unit, pdu)
    await anyio.sleep(0.002)  # a real device hears the request's end a wire time later
    if action == "answer":
        await device.write(reply)
    elif action == "noise_answer":
        await device.write(NOISE + reply)
    elif action == "other_unit_answer":
        await device.write(encode_frame(unit % 3 + 1, pdu))
        await anyio.sleep(0.01)
        await device.write(reply)
    elif action == "misshapen":
        await device.write(encode_frame(unit, pdu[:-1]))
    elif action == "late":
        # Sent once the master has decided to retry: it lands in the guard.
        await _until(lambda: master.unit_stats(unit).retries > call.retries_before)
        await device.write(reply)
    elif action == "exception":
        await device.write(encode_frame(unit, bytes((pdu[0] | 0x80, 0x02))))
    elif action.startswith("cancel_"):
        if action == "cancel_queued_answer":
            await cancel_a_queued_caller(master, tasks)
        else:
            call.scope.cancel()
            await call.done.wait()
        if action != "cancel_silent":
            await device.write(reply)


async def cancel_a_queued_caller(master: Master, tasks: anyio.abc.TaskGroup) -> None:
    queued = Call()
    tasks.start_soon(queued.run, lambda: master.read_holding_registers(1, 300, 1))
    await _until(lambda: master.engine.queued == 1)
    queued.scope.cancel()
    await queued.done.wait()
    assert queued.result == "cancelled"


async def play(master: Master, device: Device, ops: list[Op]) -> list[object]:
    """One operation after another: each caller finds the line free."""
    results = []
    async with anyio.create_task_group() as tasks:
        for op in ops:
            call = Call(retries_before=master.unit_stats(op.unit).retries)
            tasks.start_soon(call.run, lambda op=op: perform(master, op))
            for action in PLANS[op.plan]:
                with anyio.fail_after(5):
                    frame = await device.request()
                await act(action, frame, device, master, call, tasks)
            with anyio.fail_after(5):
                await call.done.wait()
            results.append(call.result)
        # Whatever the line task still finishes (a cancelled caller's attempt) ends.
        await _until(lambda: not master.engine.busy)
    return results


async def play_burst(master: Master, device: Device, ops: list[Op]) -> list[object]:
    """Every operation's caller at once: the first finds the line free, the others
    queue and are handed the line in turn (a register read then runs its usual exchange
    from the hand-over, where the engine allows it)."""
    calls = [Call() for _ in ops]
    async with anyio.create_task_group() as tasks:
        for call, op in zip(calls, ops, strict=True):
            tasks.start_soon(call.run, lambda op=op: perform(master, op))
        await _until(lambda: master.engine.queued == len(ops) - 1)
        for call, op in zip(calls, ops, strict=True):
            for action in PLANS[op.plan]:
                with anyio.fail_after(5):
                    frame = await device.request()
                await act(action, frame, device, master, call, tasks)
            with anyio.fail_after(5):
                await call.done.wait()
        await _until(lambda: not master.engine.busy)
    return [call.result for call in calls]


Player = Callable[[Master, Device, list[Op]], Awaitable[list[object]]]


def summary(master: Master) -> dict[int, dict[str, object]]:
    stats = {}
    for unit, unit_stats in sorted(master.engine.stats.items()):
        fields = dataclasses.asdict(unit_stats)
        for timing in ("last_latency", "mean_latency", "last_probe"):
            fields.pop(timing)
        stats[unit] = fields
    return stats


async def on_a_pty(
    usual_exchanges: bool, ops: list[Op], player: Player = play, gap: float = 0
) -> tuple[object, ...]:
    with open_pty() as pty:
        stream = await open_serial(pty.path, LINE)
        options = {"timeout": TIMEOUT, "retries": 1, "frame_gap": gap, "late_reply_guard": GUARD}
        options["fast_path"] = usual_exchanges
        async with Master(stream, LINE, **options) as master:  # type: ignore[arg-type]
            await anyio.sleep(0.05)  # past the receiver's first silence

            async def write(data: bytes, pty: Pty = pty) -> None:
                pty.write(data)

            device = Device(lambda count: read_master(pty, count), write)
            results = await player(master, device, ops)
            return results, summary(master), device.seen, master.engine.transactions


async def on_a_virtual_bus(
    usual_exchanges: bool, ops: list[Op], player: Player = play, gap: float = 0
) -> tuple[object, ...]:
    bus = VirtualBus(2)
    end = bus.endpoints[1]
    buffer = bytearray()

    async def read(count: int) -> bytes:
        while len(buffer) < count:
            buffer.extend(await end.receive())
        data = bytes(buffer[:count])
        del buffer[:count]
        return data

    options = {"timeout": TIMEOUT, "retries": 1, "frame_gap": gap, "late_reply_guard": GUARD}
    options["fast_path"] = usual_exchanges
    async with Master(bus.endpoints[0], LineSettings(19200), **options) as master:  # type: ignore[arg-type]
        await anyio.sleep(0.05)
        device = Device(read, end.send)
        results = await player(master, device, ops)
        return results, summary(master), device.seen, master.engine.transactions


SEED = int(os.environ.get("AIORTU_DIFFERENTIAL_SEED", "1207"))
FAULTS = [plan for plan in PLANS if plan != "ok"]


def compare(runs: dict[tuple[str, bool], tuple[object, ...]]) -> None:
    reference = runs["pty", False]
    for key, run in runs.items():
        for name, ours, theirs in zip(
            ("results", "statistics", "requests on the wire", "transactions"),
            run,
            reference,
            strict=True,
        ):
            assert ours == theirs, f"{name} differ: {key} against the machine on the pty"


def both_lines(
    usual_exchanges: bool, ops: list[Op], player: Player, gap: float
) -> dict[tuple[str, bool], tuple[object, ...]]:
    """The runs on a pty (in real time) and on a virtual bus (on the virtual clock)."""
    return {
        ("pty", usual_exchanges): anyio.run(on_a_pty, usual_exchanges, ops, player, gap),
        ("virtual bus", usual_exchanges): anyio.run(
            on_a_virtual_bus,
            usual_exchanges,
            ops,
            player,
            gap,
            backend_options={"loop_factory": VirtualTimeLoop},
        ),
    }


def print_failing(seed: int, ops: list[Op]) -> None:
    print(f"differential seed {seed} (AIORTU_DIFFERENTIAL_SEED={seed}); operations:")
    for op in ops:
        print(f"  {op}")


GAPS = [0, 0.002]
"""Frame gaps: none, and one the fast path waits for on a timer after each reply."""


@pytest.mark.parametrize("gap", GAPS)
@pytest.mark.parametrize("half", [0, 1])
def test_the_fast_path_and_the_machine_agree(half: int, gap: float) -> None:
    # Each half of the faults is sure to come up once; the other operations are drawn.
    seed = SEED + half
    ops = scenario(seed, 8, FAULTS[half::2])
    runs = {}
    try:
        for usual_exchanges in (True, False):
            runs |= both_lines(usual_exchanges, ops, play, gap)
        compare(runs)
    except BaseException:
        print_failing(seed, ops)
        raise


BURST_PLANS = (
    "ok",
    "silent, then ok",
    "noise before the reply",
    "another unit first",
    "misshapen, then ok",
    "exception",
)
"""The plans of callers that queue: the device plays them in the order they queued."""


@pytest.mark.parametrize("gap", GAPS)
def test_many_callers_at_once_agree(gap: float) -> None:
    # Twelve callers at once, mostly reads: eleven queue, and each is handed the line
    # by the one before (with a gap, its request waits for the silence on a timer);
    # faults on the way send some through the machine (the guard).
    seed = SEED + 2
    rng = random.Random(seed)
    ops = [
        Op(
            rng.choice(KINDS[:2]) if rng.random() < 0.8 else rng.choice(KINDS[2:]),
            rng.choice(UNITS),
            rng.randrange(0, 200),
            rng.randint(1, 4),
            rng.choices(BURST_PLANS, [12, 1, 1, 1, 1, 1])[0],
        )
        for _ in range(12)
    ]
    ops[3] = dataclasses.replace(ops[3], kind="read", plan="silent, then ok")
    runs = {}
    try:
        for usual_exchanges in (True, False):
            runs |= both_lines(usual_exchanges, ops, play_burst, gap)
        compare(runs)
    except BaseException:
        print_failing(seed, ops)
        raise

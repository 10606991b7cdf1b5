"""Causality against stale replies: a frame that began before the request could have
been received and answered is not the reply, where the line's wire times are real."""

from __future__ import annotations

import asyncio
import math
import os
from typing import cast

import anyio
import pytest

import aiortu
from aiortu.core.machines import MasterMachine, OutcomeKind, RetryPolicy, SkipReason, Transaction
from aiortu.core.pdu import ReadHoldingRegistersRequest, ReadHoldingRegistersResponse
from aiortu.core.rtu import FrameReceived, Receiver, Role, encode_frame
from aiortu.core.serial import LineSettings
from aiortu.line import Link
from aiortu.master._engine import LineEngine
from aiortu.testing import VirtualBus
from aiortu.transport import open_serial
from tests.transport.ptys import open_pty

REPLY = ReadHoldingRegistersResponse((1, 2)).encode()


def _waiting(reply_delay: float | None, observer: bool = False) -> MasterMachine:
    """A machine waiting for the reply to a request that went out from 1.000 to 1.005."""
    machine = MasterMachine(on_transition=(lambda *_: None) if observer else None)
    transaction = Transaction(7, ReadHoldingRegistersRequest(0, 2), timeout=0.5)
    transaction.reply_delay = reply_delay
    machine.begin(transaction)
    machine.sent(1.000, 1.005)
    return machine


@pytest.mark.parametrize("observer", [False, True])  # the usual-reply step, and the table's
def test_a_frame_begun_before_the_unit_could_answer_is_stale(observer: bool) -> None:
    machine = _waiting(0.002, observer)
    assert machine.transaction is not None
    assert machine.transaction.earliest_reply == pytest.approx(1.007)
    early = machine.frame_received(7, REPLY, 1.0065, 1.010)
    assert (early.kind, early.skipped) == (OutcomeKind.WAIT, SkipReason.STALE)
    genuine = machine.frame_received(7, REPLY, 1.0071, 1.011)
    assert genuine.kind is OutcomeKind.DONE


class _Line:
    """What the fast path uses of a link: the request leaves the wire at 1.005."""

    char_time = 0.0005
    queue_size = 16
    sends_at_once = True

    def __init__(self, loop: asyncio.AbstractEventLoop, wire_timed: bool) -> None:
        self.loop = loop
        self.wire_timed = wire_timed
        self.expected: object = None

    def send_now(self, frame: bytes) -> float:
        return 1.005

    def clock(self) -> float:
        return 1.001

    def quiet_at(self) -> float:
        return 1.0  # the line is quiet: the request goes out at once

    def call_at(self, when: float, callback: object) -> asyncio.TimerHandle:
        return self.loop.call_at(when + 1e9, lambda: None)  # never fires here

    def expect(self, tap: object) -> None:
        self.expected = tap

    def forget_expected(self) -> None:
        self.expected = None


def _fast_path(
    loop: asyncio.AbstractEventLoop, min_turnaround: float | None
) -> tuple[LineEngine, asyncio.Future[object]]:
    """A fast-path read of 2 registers from unit 7 (sent 1.001 to 1.005)."""
    wire_timed = min_turnaround is not None
    config = aiortu.MasterConfig.of(min_turnaround=min_turnaround or 0.0, retries=0)
    engine = LineEngine(cast("Link", _Line(loop, wire_timed)), config, can_reconnect=False)
    engine.open = True
    transaction = Transaction(7, ReadHoldingRegistersRequest(0, 2), 0.5, RetryPolicy(0))
    future = engine.submit(transaction)
    assert isinstance(future, asyncio.Future)
    return engine, future


def test_the_usual_reply_taken_at_once_obeys_the_same_rule() -> None:
    # The read callback's fast path: a reply whose first byte came before 1.007 (the end
    # of the request, the unit's 1.5 ms turnaround and the byte's own 0.5 ms) is handed to
    # the machine as a frame (dated by its first byte), not taken.
    frame = encode_frame(7, REPLY)  # 9 bytes: the first one 4 ms before the last
    loop = asyncio.new_event_loop()
    try:
        engine, future = _fast_path(loop, 0.0015)
        engine.fast.on_reply(frame, 1.0105)  # began at 1.0065
        assert [(event.frame, event.start, event.end) for event in engine.attempts.events] == [
            (frame, pytest.approx(1.0065), 1.0105)
        ]
        assert not future.done()
        assert engine.busy  # the line task has the transaction now
        transaction = engine.machine.transaction
        assert transaction is not None
        assert engine.line_task.job is not None
        assert engine.line_task.job.transaction is transaction
        assert transaction.reply_delay == pytest.approx(0.002)  # the same rule
        assert transaction.earliest_reply == pytest.approx(1.007)

        engine, future = _fast_path(loop, 0.0015)
        engine.fast.on_reply(frame, 1.0111)  # began at 1.0071
        assert not engine.attempts.events
        assert not engine.busy
        assert future.result().values == (1, 2)  # type: ignore[attr-defined]

        # A reply whose first byte came exactly at the earliest is taken: the machine's rule
        # too (a frame is stale when it starts before `earliest_reply`).
        engine, future = _fast_path(loop, 0.0015)
        engine.fast.on_reply(frame, engine.fast._stale_before)
        assert not engine.attempts.events
        assert future.result().values == (1, 2)  # type: ignore[attr-defined]

        # Without real wire times no reply is stale by its time here.
        engine, future = _fast_path(loop, None)
        engine.fast.on_reply(frame, 1.0)
        assert not engine.attempts.events
        assert not engine.busy
        assert future.done()
    finally:
        loop.close()


def test_without_real_wire_times_a_reply_only_has_to_end_after_the_request_began() -> None:
    # TCP, ptys, unpaced virtual lines: a genuine reply may come before the computed end
    # of the request's wire time.
    machine = _waiting(None)
    assert machine.frame_received(7, REPLY, 0.990, 0.999).skipped is SkipReason.STALE
    assert machine.frame_received(7, REPLY, 1.001, 1.002).kind is OutcomeKind.DONE


def test_a_frame_salvaged_after_a_pause_is_dated_when_it_came() -> None:
    # Garbage, a pause shorter than the silence that ends a frame, then a reply: the
    # receiver finds the reply in its buffer once the silence comes. It must carry the
    # time it came, not the time it would have had right after the garbage.
    settings = LineSettings(19200)
    char = settings.char_time
    receiver = Receiver(settings, role=Role.MASTER, frame_silence=0.020)
    receiver.feed(b"\x00", 0.0)
    receiver.expire(0.030)  # out of INIT
    frame = encode_frame(7, REPLY)
    assert receiver.feed(b"\x39\xd8\x64\x41\xbd", 1.0) == []  # garbage: no layout
    start = 1.008  # the pause: 8 ms, under the 20 ms silence
    out = receiver.feed(frame, start + (len(frame) - 1) * char)
    out += receiver.expire(2.0)
    frames = [event for event in out if isinstance(event, FrameReceived)]
    assert [event.frame for event in frames] == [frame]
    assert frames[0].start == pytest.approx(start)


async def test_a_late_reply_right_after_the_request_is_skipped_on_a_paced_line() -> None:
    # A late reply from an earlier request, the same shape as the genuine one, goes on
    # the wire while the request does: the bus sends it right after the request, before
    # the slave (which keeps t3.5 of silence) answers.
    settings = LineSettings(19200)
    late = encode_frame(1, bytes.fromhex("03 04 DE AD DE AD"))
    results = {}
    for wire_timed in (False, True):
        bus = VirtualBus(3, settings=settings)
        store = aiortu.MemoryStore(holding_registers={0: [1, 2]})
        async with (
            aiortu.Slave(bus.endpoints[1], {1: store}, settings),
            aiortu.Master(bus.endpoints[0], settings, retries=0, wire_timed=wire_timed) as master,
        ):
            master.set_min_turnaround(1, settings.t3_5)
            await anyio.sleep(0.05)

            async def inject(bus: VirtualBus = bus) -> None:
                await anyio.sleep(0.001)
                await bus.endpoints[2].send(late)

            async with anyio.create_task_group() as tasks:
                tasks.start_soon(inject)
                results[wire_timed] = await master.read_holding_registers(1, 0, 2)
            assert master.unit_stats(1).skipped_frames == (1 if wire_timed else 0)
    assert results == {False: [0xDEAD, 0xDEAD], True: [1, 2]}


async def test_the_usual_reply_on_a_port_obeys_the_rule_too() -> None:
    # A pty delivers at once whatever the baud rate: its wire times are not real, so a
    # reply that comes long before the request's computed wire time is genuine. Told
    # otherwise, the master must skip it, on the port's read callback path too.
    settings = LineSettings(9600, parity="N")  # 8 request bytes: 9 ms on a real wire
    reply = encode_frame(1, REPLY)
    for wire_timed in (None, True):
        with open_pty() as pty:
            stream = await open_serial(pty.path, settings)
            assert stream.wire_timed is False
            async with (
                stream,
                aiortu.Master(stream, settings, retries=0, timeout=0.1, wire_timed=wire_timed)
                as master,
            ):  # fmt: skip
                await anyio.sleep(0.05)

                async def device() -> None:
                    await anyio.wait_readable(pty.master)
                    os.read(pty.master, 64)
                    os.write(pty.master, reply)  # at once: well within the 9 ms

                async with anyio.create_task_group() as tasks:
                    tasks.start_soon(device)
                    if wire_timed:
                        with pytest.raises(aiortu.ResponseTimeout):
                            await master.read_holding_registers(1, 0, 2)
                    else:
                        assert await master.read_holding_registers(1, 0, 2) == [1, 2]


async def test_wire_timed_comes_from_the_stream() -> None:
    paced = VirtualBus(2, settings=LineSettings(19200))
    assert Link(paced.endpoints[0]).wire_timed is True
    assert Link(VirtualBus(2).endpoints[0]).wire_timed is False
    # A bus faster than the link's settings delivers sooner than the link computes.
    assert Link(VirtualBus(2, settings=LineSettings(115200)).endpoints[0]).wire_timed is False
    assert Link(VirtualBus(2, settings=LineSettings(9600)).endpoints[0]).wire_timed is True
    with open_pty() as pty:
        stream = await open_serial(pty.path, LineSettings(19200, parity="N"))
        async with stream:
            assert Link(stream).wire_timed is False


@pytest.mark.parametrize("seconds", [-0.001, math.nan, math.inf, "1", True, 11])
async def test_a_bad_min_turnaround_is_refused(seconds: object) -> None:
    bus = VirtualBus(2)
    with pytest.raises(aiortu.InvalidValue, match="min_turnaround"):
        aiortu.Master(bus.endpoints[0], min_turnaround=seconds)  # type: ignore[arg-type]
    async with aiortu.Master(bus.endpoints[0]) as master:
        with pytest.raises(aiortu.InvalidValue, match="min_turnaround"):
            master.set_min_turnaround(1, seconds)  # type: ignore[arg-type]
        master.set_min_turnaround(1, 0.004)
        master.set_min_turnaround(1, None)
        with pytest.raises(aiortu.InvalidRequest):
            master.set_min_turnaround(0, 0.004)

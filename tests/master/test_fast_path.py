"""The fast path: a register read on an idle serial line runs without the master machine
while its reply comes as usual, and the machine takes the attempt over on anything else
(FastPath in aiortu/master/_fast_path.py, MasterMachine.usual_exchange).

Every scenario runs twice over a pty, once that way and once with every transaction
through the machine (``fast_path=False``); the results, the statistics and the requests
on the wire must be the same.
"""

from __future__ import annotations

import asyncio
import contextlib
import dataclasses
from collections.abc import AsyncIterator, Awaitable, Callable

import anyio
import pytest

import aiortu
from aiortu.core.machines import (
    KnownRequest,
    MasterMachine,
    MasterState,
    OutcomeKind,
    RetryPolicy,
    Transaction,
)
from aiortu.core.pdu import ReadHoldingRegistersRequest, WriteSingleRegisterRequest
from aiortu.core.rtu import crc16
from aiortu.errors import ConnectionLost
from aiortu.master import Master, MasterConfig
from aiortu.master._attempt import NO_GUARD
from aiortu.master._engine import LineEngine
from aiortu.transport import open_serial
from tests.transport.ptys import LINE, Pty, open_pty, read_master

TIMEOUT = 0.15


def _with_crc(body: bytes) -> bytes:
    crc = crc16(body)
    return body + bytes((crc & 0xFF, crc >> 8))


REQUEST = _with_crc(bytes.fromhex("010300000002"))  # unit 1, FC 03, 2 registers at 0
REPLY = _with_crc(bytes.fromhex("01030400070008"))  # [7, 8]
OTHER_UNIT = _with_crc(bytes.fromhex("02030400090009"))
WRONG_COUNT = _with_crc(bytes.fromhex("010302000700"))  # 2 bytes where 4 are due
EXCEPTION = _with_crc(bytes.fromhex("018302"))
BAD_CRC = REPLY[:-1] + bytes((REPLY[-1] ^ 0xFF,))

# What the device does with each request it reads, in order: a list of steps, each a
# pause in seconds or bytes to write ("split" writes a frame in two chunks).
Step = float | bytes | tuple[str, bytes]
SCENARIOS: dict[str, list[list[Step]]] = {
    "usual reply": [[REPLY]],
    "split reply": [[("split", REPLY)]],
    "another unit first": [[OTHER_UNIT, 0.01, REPLY]],
    "noise first": [[b"\x00\xff\x13", 0.03, REPLY]],
    "exception": [[EXCEPTION]],
    "wrong byte count": [[WRONG_COUNT], [WRONG_COUNT]],
    "bad CRC, then retried": [[BAD_CRC], [REPLY]],
    "silent, then retried": [[], [REPLY]],
    "late, then retried": [[TIMEOUT + 0.05, REPLY], [REPLY]],
    "silent twice": [[], []],
    "usual reply, then noise": [[REPLY, b"\x55"]],
}


async def _play(pty: Pty, steps: list[list[Step]]) -> list[bytes]:
    """Play the device: read each request, answer it as *steps* say; return the requests."""
    seen = []
    for answer in steps:
        seen.append(await read_master(pty, len(REQUEST)))
        # A device on a real line hears the request's last byte one wire time after the
        # master began to send it; a pty hands it over at once. Answering sooner than
        # that makes a reply followed by noise in one chunk look older than the request.
        await anyio.sleep(LINE.wire_time(len(REQUEST)))
        for step in answer:
            if isinstance(step, float):
                await anyio.sleep(step)
            elif isinstance(step, tuple):
                frame = step[1]
                pty.write(frame[:3])
                await anyio.sleep(0.003)
                pty.write(frame[3:])
            else:
                pty.write(step)
    return seen


async def _read_once(
    usual_exchanges: bool, steps: list[list[Step]]
) -> tuple[object, dict[str, object], list[bytes], int]:
    with open_pty() as pty:
        stream = await open_serial(pty.path, LINE)
        async with Master(
            stream, LINE, timeout=TIMEOUT, retries=1, frame_gap=0, fast_path=usual_exchanges
        ) as master:
            engine = master.engine
            await anyio.sleep(0.05)  # past INIT
            result: object = None
            seen: list[bytes] = []

            async def device() -> None:
                seen.extend(await _play(pty, steps))

            async with anyio.create_task_group() as tg:
                tg.start_soon(device)
                with anyio.fail_after(3):
                    try:
                        result = await master.read_holding_registers(1, 0, 2)
                    except (aiortu.ModbusError, aiortu.ExceptionResponse) as error:
                        result = type(error)
            await anyio.sleep(0.05)  # whatever follows the reply has come
            stats = dataclasses.asdict(master.unit_stats(1))
            for timing in ("last_latency", "mean_latency", "last_probe"):
                stats.pop(timing)
            return result, stats, seen, engine.transactions


@pytest.mark.parametrize("steps", SCENARIOS.values(), ids=SCENARIOS.keys())
async def test_a_usual_exchange_ends_as_the_machine_would(steps: list[list[Step]]) -> None:
    through_machine = await _read_once(False, steps)
    usual = await _read_once(True, steps)
    assert usual == through_machine
    assert all(request == REQUEST for request in usual[2])


async def test_the_usual_reply_leaves_the_machine_untouched() -> None:
    for usual_exchanges, begun in ((True, False), (False, True)):
        with open_pty() as pty:
            stream = await open_serial(pty.path, LINE)
            async with Master(
                stream, LINE, timeout=TIMEOUT, frame_gap=0, fast_path=usual_exchanges
            ) as master:
                await anyio.sleep(0.05)
                async with anyio.create_task_group() as tg:
                    tg.start_soon(_play, pty, [[REPLY]])
                    assert await master.read_holding_registers(1, 0, 2) == [7, 8]
                assert (master.engine.machine.transaction is not None) is begun
                assert master.engine.machine.state is MasterState.IDLE


async def _cancelled_mid_wait(
    pty: Pty, master: Master, answer_late: Callable[[], Awaitable[None]]
) -> None:
    async with anyio.create_task_group() as tg:
        tg.start_soon(answer_late)
        with anyio.move_on_after(0.03) as scope:
            await master.read_holding_registers(1, 0, 2)
        assert scope.cancelled_caught


async def test_a_caller_cancelled_mid_wait_leaves_the_reply_to_the_line() -> None:
    # The caller is gone while its request is on the wire; the reply comes later. It
    # must not reach the next read, which must get its own data.
    second = _with_crc(bytes.fromhex("010304000a000b"))
    with open_pty() as pty:
        stream = await open_serial(pty.path, LINE)
        async with Master(stream, LINE, timeout=TIMEOUT, retries=0, frame_gap=0) as master:
            await anyio.sleep(0.05)

            async def answer_late() -> None:
                assert await read_master(pty, len(REQUEST)) == REQUEST
                await anyio.sleep(0.06)  # after the caller is gone, within the timeout
                pty.write(REPLY)

            await _cancelled_mid_wait(pty, master, answer_late)
            async with anyio.create_task_group() as tg:
                tg.start_soon(_play, pty, [[second]])
                with anyio.fail_after(2):
                    assert await master.read_holding_registers(1, 0, 2) == [10, 11]
            stats = master.unit_stats(1)
            assert (stats.requests, stats.successes, stats.failures) == (2, 2, 0)
            assert master.engine.transactions == 2


async def test_a_link_lost_mid_wait_fails_the_read_with_connection_lost() -> None:
    with open_pty() as pty:
        stream = await open_serial(pty.path, LINE)
        async with Master(stream, LINE, timeout=1.0, retries=0, frame_gap=0) as master:
            await anyio.sleep(0.05)

            async def hang_up() -> None:
                assert await read_master(pty, len(REQUEST)) == REQUEST
                pty.close_master()

            async with anyio.create_task_group() as tg:
                tg.start_soon(hang_up)
                with anyio.fail_after(2), pytest.raises(ConnectionLost):
                    await master.read_holding_registers(1, 0, 2)


async def test_a_caller_cancelled_after_the_machine_took_over_gets_no_more_retries() -> None:
    # The first attempt times out, so the machine takes the attempt over and retries;
    # the caller is gone during the retry: nothing is sent after it.
    with open_pty() as pty:
        stream = await open_serial(pty.path, LINE)
        async with Master(stream, LINE, timeout=0.1, retries=3, frame_gap=0) as master:
            await anyio.sleep(0.05)
            with anyio.move_on_after(0.15) as scope:
                await master.read_holding_registers(1, 0, 2)
            assert scope.cancelled_caught
            await anyio.sleep(0.3)  # the retry times out; a third attempt would be out
            sent = await _drain(pty)
            assert sent == REQUEST * 2
            stats = master.unit_stats(1)
            assert (stats.requests, stats.retries, stats.successes) == (1, 1, 0)
            assert not master.engine.busy  # the line is free again


async def _drain(pty: Pty) -> bytes:
    """What the master has written so far."""
    data = b""
    while True:
        with anyio.move_on_after(0.02):
            data += await read_master(pty, 1)
            continue
        return data


async def test_closing_the_master_fails_a_usual_exchange_in_flight() -> None:
    with open_pty() as pty:
        stream = await open_serial(pty.path, LINE)
        outcome: list[BaseException] = []
        ended = anyio.Event()
        async with anyio.create_task_group() as tg:
            async with Master(stream, LINE, timeout=5.0, frame_gap=0) as master:
                await anyio.sleep(0.05)

                async def read() -> None:
                    try:
                        await master.read_holding_registers(1, 0, 2)
                    except ConnectionLost as error:
                        outcome.append(error)
                    finally:
                        ended.set()

                tg.start_soon(read)
                assert await read_master(pty, len(REQUEST)) == REQUEST
                assert master.engine.fast.on_wire  # the usual exchange waits
            with anyio.fail_after(0.5):  # not the 5 s timeout
                await ended.wait()
        assert isinstance(outcome[0], ConnectionLost)


@contextlib.asynccontextmanager
async def _master_on_a_pty(
    response_timeout: float, frame_gap: float = 0
) -> AsyncIterator[tuple[Master, Pty]]:
    """A master on one end of a pty, past its initial silence, and the other end."""
    with open_pty() as pty:
        stream = await open_serial(pty.path, LINE)
        async with Master(stream, LINE, timeout=response_timeout, frame_gap=frame_gap) as master:
            await anyio.sleep(0.05)
            yield master, pty


async def _read_on_the_wire(master: Master, pty: Pty) -> asyncio.Task[list[int]]:
    """A read of registers 0..1 of unit 1, started as a task, its request on the wire."""
    read = asyncio.create_task(master.read_holding_registers(1, 0, 2))
    assert await read_master(pty, len(REQUEST)) == REQUEST
    assert master.engine.fast.on_wire  # its usual exchange waits
    return read


async def _in_the_same_pass(condition: Callable[[], bool]) -> None:
    """Return in the loop pass in which *condition* became true. Polled, not awaited on
    an event: this task then runs before any task that the same pass woke."""
    with anyio.fail_after(1):
        while not condition():  # noqa: ASYNC110
            await asyncio.sleep(0)


async def test_a_caller_cancelled_once_its_reply_came_leaves_it_counted() -> None:
    # The read callback has completed the caller's future, and the caller is cancelled
    # before it wakes: the transaction is over and counted, and the line is free.
    async with _master_on_a_pty(response_timeout=1.0) as (master, pty):
        read = await _read_on_the_wire(master, pty)
        pty.write(REPLY)
        await _in_the_same_pass(lambda: not master.engine.fast.on_wire)
        read.cancel()
        with pytest.raises(asyncio.CancelledError):
            await read
        stats = master.unit_stats(1)
        assert (stats.requests, stats.successes, stats.failures) == (1, 1, 0)
        async with anyio.create_task_group() as tg:
            tg.start_soon(_play, pty, [[REPLY]])
            with anyio.fail_after(1):
                assert await master.read_holding_registers(1, 0, 2) == [7, 8]


async def test_closing_the_master_fails_a_read_the_machine_took_over() -> None:
    # Another unit's frame makes the machine take the read over, in the line task; the
    # master closes at once: the caller gets ConnectionLost, not a wait forever.
    async with _master_on_a_pty(response_timeout=5.0) as (master, pty):
        read = await _read_on_the_wire(master, pty)
        pty.write(OTHER_UNIT)
        await _in_the_same_pass(lambda: master.engine.line_task.job is not None)
    with anyio.fail_after(1), pytest.raises(ConnectionLost):
        await read


async def test_closing_the_engine_fails_a_read_taken_over_and_not_finished() -> None:
    # The engine closes once its line task is gone. A read taken over meanwhile (its
    # timer may fire while the link closes) has nobody left to run it: close() fails it.
    async with _master_on_a_pty(response_timeout=5.0) as (master, pty):
        read = await _read_on_the_wire(master, pty)
        master.engine.fast.take_over()
        master.engine.close(ConnectionLost("closed"))
        with anyio.fail_after(1), pytest.raises(ConnectionLost, match="closed"):
            await read


class _Link:
    loop = object()  # a push stream's link has one
    sends_at_once = True


class _LinkSending:
    loop = object()
    sends_at_once = False  # someone else is sending, or the stream failed


def _engine(**changes: object) -> LineEngine:
    """An engine whose fast path may run, but for *changes* to it (`link`, `open`,
    `busy`, `guard_until`, `health`, `machine`, `enabled`)."""
    config = MasterConfig(fast_path=bool(changes.pop("enabled", True)))
    engine = LineEngine(_Link(), config, can_reconnect=False)  # type: ignore[arg-type]
    engine.open = bool(changes.pop("open", True))
    engine.queue.busy = bool(changes.pop("busy", False))
    engine.attempts.guard_until = changes.pop("guard_until", NO_GUARD)  # type: ignore[assignment]
    for name, value in changes.items():
        setattr(engine, name, value)
    return engine


def _predicate_case(
    unit: int = 1, request: object = None, handed: bool = False, **changes: object
) -> KnownRequest | None:
    """FastPath.may_run where every condition holds, but for *changes*."""
    if request is None:
        request = ReadHoldingRegistersRequest(0, 2)
    transaction = Transaction(unit, request, 1.0)  # type: ignore[arg-type]
    return _engine(**changes).fast.may_run(transaction, handed)


class _NoLoop:
    loop = None


def _busy_machine() -> MasterMachine:
    machine = MasterMachine()
    machine.begin(Transaction(1, ReadHoldingRegistersRequest(0, 2), 1.0))
    machine.sent(0.0, 0.004)  # waiting for its reply
    return machine


def _late_reply_awaited() -> MasterMachine:
    machine = MasterMachine()
    machine.begin(Transaction(1, ReadHoldingRegistersRequest(0, 3), 1.0, RetryPolicy(0)))
    machine.sent(0.0, 0.004)
    assert machine.expired(2.0).kind is OutcomeKind.FAILED  # timed out: its reply may come
    return machine


VETOES: dict[str, dict[str, object]] = {
    "switched off": {"enabled": False},
    "no read callback": {"link": _NoLoop()},
    "the link cannot write at once": {"link": _LinkSending()},
    "the line task does not serve": {"open": False},
    "line held or waited for": {"busy": True},
    "late-reply guard pending": {"guard_until": 12.0},
    "fail fast, the unit offline": {
        "health": aiortu.HealthPolicy(fail_fast_offline=True),
        "stats": {1: aiortu.UnitStats(online=False)},
    },
    "machine not idle": {"machine": _busy_machine()},
    "machine observed": {"machine": MasterMachine(on_transition=lambda *step: None)},
    "a late reply awaited from the unit": {"machine": _late_reply_awaited()},
    "not a register read": {"request": WriteSingleRegisterRequest(0, 1)},
    "a broadcast": {"unit": 0},
}


def test_the_fast_path_runs_where_every_condition_holds() -> None:
    known = _predicate_case()
    assert isinstance(known, KnownRequest)
    assert known.reply_shape == (bytes((1, 3, 4)), 9)


@pytest.mark.parametrize("change", VETOES.values(), ids=VETOES.keys())
def test_each_condition_of_the_fast_path_alone_keeps_it_off(change: dict[str, object]) -> None:
    assert _predicate_case(**change) is None


def test_fail_fast_lets_the_fast_path_run_for_a_unit_not_offline() -> None:
    fail_fast = aiortu.HealthPolicy(fail_fast_offline=True)
    assert _predicate_case(health=fail_fast) is not None
    assert _predicate_case(health=fail_fast, stats={1: aiortu.UnitStats()}) is not None


def test_the_line_handed_to_a_queued_caller_lets_the_fast_path_run() -> None:
    # The line is not free (others wait for it), but the queue has just handed it to
    # this caller: the same shortcut as on a free line.
    assert _predicate_case(busy=True, handed=True) is not None
    assert _predicate_case(busy=True, handed=True, guard_until=12.0) is None


async def test_queued_register_reads_run_their_usual_exchanges_without_the_machine(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    # Callers that queue on a pushing VirtualBus: each is handed the line and its read
    # goes out from the hand-over, so the machine begins no transaction at all.
    bus = aiortu.testing.VirtualBus(2)
    store = aiortu.MemoryStore(holding_registers={0: [100, 101]})
    slave = aiortu.Slave(bus.endpoints[1], {1: store}, frame_gap=0)
    master = Master(bus.endpoints[0], frame_gap=0, timeout=5)
    begun: list[Transaction] = []
    begin = MasterMachine.begin

    def counted(machine: MasterMachine, transaction: Transaction) -> None:
        begun.append(transaction)
        begin(machine, transaction)

    monkeypatch.setattr(MasterMachine, "begin", counted)
    results: list[object] = []

    async def read() -> None:
        results.append(await master.read_holding_registers(1, 0, 2))

    async with slave, master, anyio.create_task_group() as group:
        for _ in range(20):
            group.start_soon(read)
    assert results == [[100, 101]] * 20
    assert master.unit_stats(1).requests == 20
    assert begun == []


async def test_a_queued_caller_cancelled_after_the_hand_over_leaves_its_reply_counted() -> None:
    # B queues behind A; A's reply hands the line to B, whose request goes out from the
    # read callback. B is cancelled while it is on the wire: its reply is counted and
    # never reaches C, which gets its own data.
    second = _with_crc(bytes.fromhex("010304000a000b"))
    async with _master_on_a_pty(response_timeout=1.0) as (master, pty):
        first = await _read_on_the_wire(master, pty)
        queued = asyncio.create_task(master.read_holding_registers(1, 0, 2))
        await _in_the_same_pass(lambda: master.engine.queued == 1)
        pty.write(REPLY)
        assert await read_master(pty, len(REQUEST)) == REQUEST  # B's, from the hand-over
        assert await first == [7, 8]
        assert master.engine.fast.on_wire  # B's usual exchange waits
        queued.cancel()
        with pytest.raises(asyncio.CancelledError):
            await queued
        third = asyncio.create_task(master.read_holding_registers(1, 0, 2))
        await _in_the_same_pass(lambda: master.engine.queued == 1)  # B still holds the line
        pty.write(REPLY)  # B's reply, after B is gone
        assert await read_master(pty, len(REQUEST)) == REQUEST  # C's, from the hand-over
        pty.write(second)
        with anyio.fail_after(2):
            assert await third == [10, 11]
        stats = master.unit_stats(1)
        assert (stats.requests, stats.successes, stats.failures) == (3, 3, 0)


# -- a request that waits for the line's silence ----------------------------------------------

GAP = 0.05
"""A frame gap long enough that a test acts while a handed-over request waits for it."""
AT_4 = _with_crc(bytes.fromhex("010300040002"))  # unit 1, FC 03, 2 registers at 4


async def _handed_over_waiting(
    master: Master, pty: Pty
) -> tuple[asyncio.Task[list[int]], asyncio.Task[list[int]]]:
    """A read on the wire, a second one queued behind it; the first's reply hands the line
    to the second, whose request waits for the frame gap. Returns both tasks."""
    first = await _read_on_the_wire(master, pty)
    second = asyncio.create_task(master.read_holding_registers(1, 0, 2))
    await _in_the_same_pass(lambda: master.engine.queued == 1)
    pty.write(REPLY)
    await _in_the_same_pass(lambda: master.engine.fast.waiting)
    return first, second


async def test_a_queued_read_waits_for_the_gap_on_a_timer_then_goes_out() -> None:
    async with _master_on_a_pty(response_timeout=1.0, frame_gap=GAP) as (master, pty):
        await anyio.sleep(GAP)
        first, second = await _handed_over_waiting(master, pty)
        assert await first == [7, 8]
        replied = master.engine.clock()
        assert await read_master(pty, len(REQUEST)) == REQUEST  # from the timer callback
        assert master.engine.clock() - replied >= GAP * 0.9  # not before the gap
        assert master.engine.fast.on_wire
        pty.write(REPLY)
        with anyio.fail_after(1):
            assert await second == [7, 8]
        assert master.engine.machine.state is MasterState.IDLE
        assert not master.engine.busy


async def test_a_caller_cancelled_while_its_request_waits_for_the_gap_sends_nothing() -> None:
    # B is handed the line and waits for the gap; B is cancelled: nothing of B's goes out,
    # and C, queued behind it, gets the line.
    async with _master_on_a_pty(response_timeout=1.0, frame_gap=GAP) as (master, pty):
        await anyio.sleep(GAP)
        first, second = await _handed_over_waiting(master, pty)
        third = asyncio.create_task(master.read_holding_registers(1, 4, 2))
        await _in_the_same_pass(lambda: master.engine.queued == 1)
        second.cancel()
        with pytest.raises(asyncio.CancelledError):
            await second
        assert await first == [7, 8]
        assert await read_master(pty, len(AT_4)) == AT_4  # C's, not B's
        pty.write(REPLY)
        with anyio.fail_after(1):
            assert await third == [7, 8]
        stats = master.unit_stats(1)
        assert (stats.requests, stats.successes) == (2, 2)
        assert not master.engine.busy


async def test_a_link_lost_while_a_request_waits_for_the_gap_fails_it() -> None:
    async with _master_on_a_pty(response_timeout=1.0, frame_gap=GAP) as (master, pty):
        await anyio.sleep(GAP)
        first, second = await _handed_over_waiting(master, pty)
        assert await first == [7, 8]
        pty.close_master()
        with anyio.fail_after(1), pytest.raises(ConnectionLost):
            await second
        assert not master.engine.fast.waiting
        assert master.unit_stats(1).requests == 1  # nothing was sent for it


async def test_closing_the_engine_fails_a_request_waiting_for_the_gap() -> None:
    async with _master_on_a_pty(response_timeout=1.0, frame_gap=GAP) as (master, pty):
        await anyio.sleep(GAP)
        first, second = await _handed_over_waiting(master, pty)
        assert await first == [7, 8]
        master.engine.close(ConnectionLost("closed"))
        with anyio.fail_after(1), pytest.raises(ConnectionLost, match="closed"):
            await second
        assert not master.engine.fast.waiting
        await anyio.sleep(GAP * 2)
        assert await _drain(pty) == b""  # the timer sent nothing


class _QuietLink:
    """A link on a fixed clock whose line falls quiet at `quiet`: it records what the fast
    path sends and the callback it leaves for the silence."""

    sends_at_once = True
    char_time = 0.001
    wire_timed = False

    def __init__(self, loop: asyncio.AbstractEventLoop, now: float, quiet: float) -> None:
        self.loop, self._now, self._quiet = loop, now, quiet
        self.sent: list[bytes] = []
        self.when_quiet: list[Callable[[], object]] = []

    def clock(self) -> float:
        return self._now

    def quiet_at(self) -> float:
        return self._quiet

    def call_when_quiet(self, callback: Callable[[], object]) -> None:
        self.when_quiet.append(callback)

    def send_now(self, frame: bytes) -> float | None:
        if self._quiet > self._now:
            return None  # as Link.send_now: nothing goes before the silence
        self.sent.append(frame)
        return self._now + len(frame) * self.char_time

    def call_at(self, when: float, callback: Callable[[], object]) -> asyncio.TimerHandle:
        return self.loop.call_at(when + 3600.0, callback)  # never fires in the test

    def expect(self, tap: object) -> None:
        pass


@pytest.mark.parametrize(("quiet", "waits"), [(5.0, False), (5.0 + 1e-9, True)])
async def test_a_request_goes_out_at_once_from_the_instant_the_line_is_quiet(
    quiet: float, waits: bool
) -> None:
    # The line quiet at this very instant: the request goes out now, not from a callback;
    # quiet a moment later: it waits, then goes out, and no longer holds the line waiting.
    link = _QuietLink(asyncio.get_running_loop(), 5.0, quiet)
    engine = LineEngine(link, MasterConfig(), can_reconnect=False)  # type: ignore[arg-type]
    engine.open = True
    future = engine.fast.start(Transaction(1, ReadHoldingRegistersRequest(0, 2), 1.0))
    try:
        assert future is not None
        assert (link.sent, len(link.when_quiet)) == (([], 1) if waits else ([REQUEST], 0))
        assert engine.fast.waiting is waits
        link._now = quiet  # the silence has come
        for callback in list(link.when_quiet):
            callback()
        assert len(link.when_quiet) == (1 if waits else 0)  # no second wait
        assert (link.sent, engine.fast.waiting, engine.fast.on_wire) == ([REQUEST], False, True)
    finally:
        engine.attempts.stop_timer()

"""The master on a faulty line: silence, late replies, other units, noise, exceptions,
many callers, cancellations, dead units and a dead line."""

from __future__ import annotations

import itertools
import random

import anyio
import anyio.lowlevel
import pytest

import aiortu
from aiortu.core.codes import ExceptionCode
from aiortu.core.pdu import ReadHoldingRegistersResponse, Request, WriteSingleRegisterRequest
from aiortu.core.rtu import encode_frame
from aiortu.errors import UnitOffline
from tests.virtual_clock import on_virtual_clock

from .fakes import FakeSlave, answer, line, register_value, silent, standard_reply


def late(delay: float, values: tuple[int, ...]):  # type: ignore[no-untyped-def]
    async def step(slave: FakeSlave, unit: int, request: Request) -> None:
        await anyio.sleep(delay)
        await slave.reply(unit, ReadHoldingRegistersResponse(values).encode())

    return step


@on_virtual_clock
async def test_no_reply_times_out_after_the_retries() -> None:
    async with line(default=silent, timeout=0.05, retries=2) as (master, slave, _):
        with pytest.raises(aiortu.ResponseTimeout):
            await master.read_holding_registers(5, 0, 1)
        assert len(slave.seen) == 3
        stats = master.unit_stats(5)
        assert (stats.requests, stats.timeouts, stats.retries, stats.failures) == (1, 3, 2, 1)


@on_virtual_clock
async def test_the_timeout_runs_from_the_end_of_transmission() -> None:
    async with line(default=silent, timeout=0.1, retries=0) as (master, _, _):
        start = anyio.current_time()
        with pytest.raises(TimeoutError):
            await master.read_holding_registers(5, 0, 1, timeout=0.05)
        assert 0.05 <= anyio.current_time() - start < 0.09


@pytest.mark.parametrize("retries", [0, 1])
async def test_a_late_reply_never_reaches_the_next_request(retries: int) -> None:
    # Request 0 is answered 50 ms after its timeout with data of its own.
    script = {0: late(0.15, (0xDEAD, 0xDEAD, 0xDEAD))}
    options = {"timeout": 0.1, "retries": retries, "late_reply_guard": 0.3}
    async with line(script=script, **options) as (master, _, _):
        first: list[int] | None = None
        try:
            first = await master.read_holding_registers(7, 0, 3)
        except aiortu.ResponseTimeout:
            assert retries == 0
        if first is not None:
            # The late reply came during the guard before the retry: the retry got its own.
            assert first == [register_value(7, i) for i in range(3)]
        for _ in range(3):
            assert await master.read_holding_registers(7, 0, 3) == [
                register_value(7, i) for i in range(3)
            ]


@on_virtual_clock
async def test_a_reply_from_another_unit_is_skipped() -> None:
    async def other_first(slave: FakeSlave, unit: int, request: Request) -> None:
        await slave.reply(unit + 1, standard_reply(unit + 1, request))
        await slave.reply(unit, standard_reply(unit, request))

    async with line(default=other_first) as (master, _, _):
        assert await master.read_holding_registers(3, 0, 2) == [3000, 3001]
        assert master.unit_stats(3).skipped_frames == 1


@on_virtual_clock
async def test_a_bad_crc_then_the_right_reply() -> None:
    async def bad_then_good(slave: FakeSlave, unit: int, request: Request) -> None:
        frame = bytearray(encode_frame(unit, standard_reply(unit, request)))
        frame[-1] ^= 0xFF
        await slave.send_raw(bytes(frame))
        await anyio.sleep(0.005)
        await slave.reply(unit, standard_reply(unit, request))

    async with line(default=bad_then_good, retries=0) as (master, _, _):
        assert await master.read_holding_registers(3, 4, 2) == [3004, 3005]


@on_virtual_clock
async def test_bad_crc_every_time_raises_crc_error_after_the_retries() -> None:
    async def bad(slave: FakeSlave, unit: int, request: Request) -> None:
        frame = bytearray(encode_frame(unit, standard_reply(unit, request)))
        frame[3] ^= 0x01
        await slave.send_raw(bytes(frame))

    async with line(default=bad, retries=1, timeout=0.2) as (master, slave, _):
        start = anyio.current_time()
        with pytest.raises(aiortu.CRCError):
            await master.read_holding_registers(3, 4, 2)
        # The frame error grace ends each attempt well before the response timeout.
        assert anyio.current_time() - start < 0.3
        assert len(slave.seen) == 2
        assert master.unit_stats(3).crc_errors == 2


@on_virtual_clock
async def test_a_short_reply() -> None:
    async def truncated(slave: FakeSlave, unit: int, request: Request) -> None:
        await slave.send_raw(encode_frame(unit, standard_reply(unit, request))[:-3])

    async def too_few(slave: FakeSlave, unit: int, request: Request) -> None:
        await slave.reply(unit, ReadHoldingRegistersResponse((1,)).encode())

    async with line(default=truncated, retries=1, timeout=0.1) as (master, slave, _):
        with pytest.raises(aiortu.FrameError):
            await master.read_holding_registers(3, 4, 2)
        assert len(slave.seen) == 2
    async with line(default=too_few, retries=0, timeout=0.05) as (master, slave, _):
        with pytest.raises(aiortu.MalformedPDU):
            await master.read_holding_registers(3, 4, 2)


@on_virtual_clock
async def test_an_exception_reply_raises_and_is_not_retried() -> None:
    async def refuse(slave: FakeSlave, unit: int, request: Request) -> None:
        await slave.reply(unit, bytes((request.function_code | 0x80, 0x02)))

    async with line(default=refuse, retries=3) as (master, slave, _):
        with pytest.raises(aiortu.ExceptionResponse) as caught:
            await master.read_holding_registers(3, 4, 2)
        assert caught.value.code is ExceptionCode.ILLEGAL_DATA_ADDRESS
        assert caught.value.unit == 3
        assert len(slave.seen) == 1
        assert master.unit_stats(3).exceptions == 1
        assert master.is_online(3)


@on_virtual_clock
async def test_exception_codes_can_be_retried_on_request() -> None:
    async def busy_once(slave: FakeSlave, unit: int, request: Request) -> None:
        await slave.reply(unit, bytes((request.function_code | 0x80, 0x06)))

    script = {0: busy_once}
    retry_on = {ExceptionCode.SERVER_DEVICE_BUSY}
    async with line(script=script, retry_on=retry_on) as (master, slave, _):
        assert await master.read_holding_registers(3, 0, 1) == [3000]
        assert len(slave.seen) == 2


@on_virtual_clock
async def test_garbage_before_the_reply() -> None:
    async def garbage_first(slave: FakeSlave, unit: int, request: Request) -> None:
        frame = encode_frame(unit, standard_reply(unit, request))
        await slave.send_raw(bytes.fromhex("ff 00 13 37") + frame)

    async with line(default=garbage_first, retries=0) as (master, _, _):
        assert await master.read_holding_registers(3, 4, 2) == [3004, 3005]


@on_virtual_clock
async def test_many_callers_share_one_line() -> None:
    callers, per_caller = 100, 20
    async with line(timeout=1.0) as (master, slave, bus):
        results: dict[int, list[list[int]]] = {}

        async def caller(index: int) -> None:
            unit = index % 10 + 1
            got = results.setdefault(index, [])
            for sequence in range(per_caller):
                address = index * per_caller + sequence
                got.append(await master.read_holding_registers(unit, address, 2))

        async with anyio.create_task_group() as tasks:
            for index in range(callers):
                tasks.start_soon(caller, index)

        for index, got in results.items():
            unit = index % 10 + 1
            for sequence, values in enumerate(got):
                address = index * per_caller + sequence
                assert values == [register_value(unit, address), register_value(unit, address + 1)]
        # Each caller's requests reached the line in the caller's order.
        addresses: dict[int, list[int]] = {}
        for seen in slave.seen:
            address = seen.request.address  # type: ignore[attr-defined]
            addresses.setdefault(address // per_caller, []).append(address)
        assert all(found == sorted(found) for found in addresses.values())
        assert len(slave.seen) == callers * per_caller
        # Never two requests in flight: master and slave take turns on the wire, one
        # frame at a time.
        trace = list(bus.trace)
        assert trace
        senders = [entry.sender for entry in trace]
        assert all(a != b for a, b in itertools.pairwise(senders))
        assert all(len(entry.data) == 8 for entry in trace if entry.sender == 0)


@on_virtual_clock
async def test_cancelled_callers_never_desynchronise_the_line() -> None:
    # Also run under trio by tests/project/test_trio.py: anyio's task list, not asyncio's.
    generator = random.Random(4)
    tasks_before = len(anyio.get_running_tasks())

    async def slow(slave: FakeSlave, unit: int, request: Request) -> None:
        await anyio.sleep(generator.uniform(0, 0.006))
        await answer(slave, unit, request)

    # The uncancelled reads are due a reply: a timeout no load reaches.
    async with line(default=slow, timeout=5) as (master, _, _):
        cancelled = 0
        for index in range(200):
            unit = index % 7 + 1
            with anyio.move_on_after(generator.uniform(0, 0.008)) as scope:
                await master.read_holding_registers(unit, index, 2)
            cancelled += scope.cancelled_caught
            address = 1000 + index
            assert await master.read_holding_registers(unit, address, 2) == [
                register_value(unit, address),
                register_value(unit, address + 1),
            ]
        assert cancelled > 20
    with anyio.fail_after(5):  # the line's tasks end: none is left behind
        while len(anyio.get_running_tasks()) != tasks_before:  # noqa: ASYNC110
            await anyio.sleep(0.01)


@on_virtual_clock
async def test_health_offline_after_failures_and_online_after_a_success() -> None:
    script = dict.fromkeys(range(3), silent)
    async with line(script=script, timeout=0.03, retries=0) as (master, _, _):
        for _ in range(2):
            with pytest.raises(aiortu.ResponseTimeout):
                await master.read_coils(9, 0, 1)
        assert master.is_online(9)
        with pytest.raises(aiortu.ResponseTimeout):
            await master.read_coils(9, 0, 1)
        assert not master.is_online(9)
        assert master.unit_stats(9).consecutive_failures == 3
        await master.read_coils(9, 0, 1)
        stats = master.unit_stats(9)
        assert stats.online
        assert stats.consecutive_failures == 0
        assert stats.last_latency is not None
        assert stats.mean_latency is not None


@on_virtual_clock
async def test_fail_fast_on_an_offline_unit_except_for_probes() -> None:
    options = {"timeout": 0.03, "retries": 0, "offline_after": 2, "probe_interval": 0.2}
    async with line(default=silent, fail_fast_offline=True, **options) as (master, slave, _):
        for _ in range(2):
            with pytest.raises(aiortu.ResponseTimeout):
                await master.read_coils(9, 0, 1)
        sent = len(slave.seen)
        with pytest.raises(UnitOffline):
            await master.read_coils(9, 0, 1)
        assert len(slave.seen) == sent
        await anyio.sleep(0.2)
        with pytest.raises(aiortu.ResponseTimeout) as caught:
            await master.read_coils(9, 0, 1)  # the probe goes out
        assert not isinstance(caught.value, UnitOffline)
        await anyio.sleep(0.01)
        assert len(slave.seen) == sent + 1
        # Other units are not affected.
        assert master.is_online(8)


@on_virtual_clock
async def test_a_broadcast_on_a_serial_line_is_no_unit_of_the_health() -> None:
    # Unit 0 on a serial line is the broadcast: sent, counted as unit 0's requests, never
    # a failure (no reply is awaited), never refused, even with fail-fast after one failure.
    options = {"timeout": 0.03, "retries": 0, "offline_after": 1, "fail_fast_offline": True}
    async with line(**options) as (master, slave, _):
        for value in range(3):
            await master.broadcast.write_register(4, value)
        await anyio.sleep(0.01)
        sent = [(0, WriteSingleRegisterRequest(4, value)) for value in range(3)]
        assert [(seen.unit, seen.request) for seen in slave.seen] == sent
        stats = master.unit_stats(0)
        assert (stats.requests, stats.failures, stats.timeouts) == (3, 0, 0)
        assert stats.online
        with pytest.raises(aiortu.InvalidRequest, match=r"use master\.broadcast"):
            await master.read_holding_registers(0, 0, 1)


@on_virtual_clock
async def test_requests_in_flight_fail_when_the_line_dies() -> None:
    async def hang_up(slave: FakeSlave, unit: int, request: Request) -> None:
        assert slave.link is not None
        await slave.link.aclose()

    async with line(default=hang_up, timeout=2.0) as (master, _, _):
        with anyio.fail_after(1):
            with pytest.raises(aiortu.ConnectionLost):
                await master.read_coils(1, 0, 1)
            with pytest.raises(aiortu.ConnectionLost):
                await master.read_coils(1, 0, 1)


@on_virtual_clock
async def test_priority_goes_first() -> None:
    async with line() as (master, slave, _):
        order: list[int] = []

        async def read(address: int, priority: int) -> None:
            await master.read_holding_registers(1, address, 1, priority=priority)
            order.append(address)

        async with anyio.create_task_group() as tasks:
            tasks.start_soon(read, 0, 0)
            await anyio.lowlevel.checkpoint()
            for address in (1, 2, 3):
                tasks.start_soon(read, address, 0)
            tasks.start_soon(read, 9, -1)
        addresses = [seen.request.address for seen in slave.seen]  # type: ignore[attr-defined]
        assert addresses.index(9) < addresses.index(1)

"""The master under load: many callers on a paced 19200-baud line, and a noisy line.

The concurrency test runs 100 coroutines x 8 requests (800 transactions) to 10 units:
at 19200 baud each read of one register takes about 12.6 ms on the wire with its two
t3.5 silences, about 10 s of line time, which still interleaves every caller with every
other. Both tests run on the virtual clock (tests/virtual_clock.py): the line's pacing, the
timeouts and the guard are exact and take no real time, and a collector pause of the
machine cannot open a gap inside a frame.
"""

from __future__ import annotations

import itertools
import random

import anyio

import aiortu
from aiortu.core.pdu import ReadHoldingRegistersRequest, Request
from aiortu.core.serial import LineSettings
from aiortu.testing import FaultPlan, VirtualBus
from tests.virtual_clock import on_virtual_clock

from .fakes import FakeSlave, answer, register_value, until_idle

SETTINGS = LineSettings(19200, parity="E")


async def answer_after_silence(slave: FakeSlave, unit: int, request: Request) -> None:
    """Reply as a conforming device does: after t3.5 of silence on the line."""
    assert slave.link is not None
    await slave.link.wait_for_silence(SETTINGS.t3_5)
    await answer(slave, unit, request)


@on_virtual_clock
async def test_many_callers_on_a_paced_line_keep_order_and_t3_5() -> None:
    callers, per_caller, units = 100, 8, 10
    bus = VirtualBus(2, settings=SETTINGS, trace_size=10 * callers * per_caller)
    slave = FakeSlave(bus.endpoints[1], default=answer_after_silence)
    results: dict[int, list[tuple[int, list[int]]]] = {}

    async def caller(master: aiortu.Master, index: int) -> None:
        unit = index % units + 1
        got = results.setdefault(index, [])
        for sequence in range(per_caller):
            address = index * per_caller + sequence
            got.append((address, await master.read_holding_registers(unit, address, 1)))

    async with anyio.create_task_group() as tasks:
        tasks.start_soon(slave.run)
        async with aiortu.Master(bus.endpoints[0], SETTINGS, timeout=1.0) as master:
            await until_idle(master, slave)
            with anyio.fail_after(40):
                async with anyio.create_task_group() as callers_group:
                    for index in range(callers):
                        callers_group.start_soon(caller, master, index)
            stats = [master.unit_stats(unit) for unit in range(1, units + 1)]
        tasks.cancel_scope.cancel()

    # Every result is right, and each caller got its answers in its own order.
    for index, got in results.items():
        unit = index % units + 1
        assert [address for address, _ in got] == [
            index * per_caller + sequence for sequence in range(per_caller)
        ]
        assert all(values == [register_value(unit, address)] for address, values in got)
    # Every call answered once; a retry (a reply late on a busy machine) is allowed, a
    # failed call is not, and each retry is one more request on the wire.
    assert sum(s.successes for s in stats) == callers * per_caller
    assert sum(s.failures for s in stats) == 0
    retries = sum(s.retries for s in stats)
    # Each caller's requests reached the wire in the caller's order (a retry repeats one).
    by_caller: dict[int, list[int]] = {}
    for seen in slave.seen:
        assert isinstance(seen.request, ReadHoldingRegistersRequest)
        by_caller.setdefault(seen.request.address // per_caller, []).append(seen.request.address)
    assert all(found == sorted(found) for found in by_caller.values())
    assert sum(len(set(found)) for found in by_caller.values()) == callers * per_caller
    # The master sent each request once plus its retries, and kept t3.5 of silence after
    # the end of whatever was on the wire before each of its frames.
    trace = list(bus.trace)
    sent = [index for index, entry in enumerate(trace) if entry.sender == 0]
    assert len(sent) == callers * per_caller + retries
    gaps = [trace[i].start - trace[i - 1].end for i in sent if i > 0]
    assert min(gaps) >= SETTINGS.t3_5 - 1e-6, min(gaps)
    if retries == 0:
        # Without a late reply the wire is a plain alternation, never two senders at once.
        assert len(trace) == 2 * callers * per_caller
        assert bus.collisions == 0
        assert all(a.sender != b.sender for a, b in itertools.pairwise(trace))
    assert all(len(entry.data) == 8 for entry in trace if entry.sender == 0)


async def a_noisy_line_gives_right_values_or_typed_errors(
    bit_error_rate: float, transactions: int
) -> None:
    generator = random.Random(11)
    bus = VirtualBus(2, faults=FaultPlan(bit_error_rate=bit_error_rate, seed=5))
    slave = FakeSlave(bus.endpoints[1])
    outcomes: dict[str, int] = {}
    async with anyio.create_task_group() as tasks:
        tasks.start_soon(slave.run)
        async with aiortu.Master(
            bus.endpoints[0],
            LineSettings(1_000_000),
            frame_gap=0,
            timeout=0.05,
            late_reply_guard=0.01,
        ) as master:
            await until_idle(master, slave)
            with anyio.fail_after(40):
                for index in range(transactions):
                    unit = generator.randint(1, 5)
                    address = generator.randrange(0, 60000)
                    count = generator.randint(1, 20)
                    try:
                        values = await master.read_holding_registers(unit, address, count)
                    except aiortu.ModbusError as error:
                        outcomes[type(error).__name__] = outcomes.get(type(error).__name__, 0) + 1
                        continue
                    expected = [register_value(unit, address + i) for i in range(count)]
                    assert values == expected, index
                    outcomes["ok"] = outcomes.get("ok", 0) + 1
        tasks.cancel_scope.cancel()
    assert bus.injector is not None
    assert bus.injector.stats.bits_flipped > 0
    assert outcomes["ok"] >= transactions * 0.8, outcomes


@on_virtual_clock
async def test_a_line_with_rare_bit_errors_gives_right_values_or_typed_errors() -> None:
    await a_noisy_line_gives_right_values_or_typed_errors(1e-4, 400)


@on_virtual_clock
async def test_a_noisy_line_gives_right_values_or_typed_errors() -> None:
    await a_noisy_line_gives_right_values_or_typed_errors(2e-3, 150)

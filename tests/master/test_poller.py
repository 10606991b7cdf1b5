"""The poller against a fake slave: merged reads on the wire, typed values, samples
through callbacks and the async iterator, and dead units that do not stall the cycle."""

from __future__ import annotations

import io
import itertools

import anyio
import pytest

import aiortu
from aiortu import Point, Poller
from aiortu.cli._poll import TablePrinter
from aiortu.core.model import Table, ValueType, decode_value
from aiortu.core.pdu import (
    ReadCoilsRequest,
    ReadDiscreteInputsRequest,
    ReadHoldingRegistersRequest,
    ReadInputRegistersRequest,
    Request,
)
from aiortu.core.rtu import encode_frame
from aiortu.master import CycleReport, Sample, UnitHealth, UnitSkipped, UnitState
from aiortu.testing import VirtualBus
from tests.virtual_clock import on_virtual_clock

from .fakes import FakeSlave, answer, coil_value, line, register_value, standard_reply

POINTS = [
    Point.of("a", 1, "40001"),
    Point.of("b", 1, "40003", "float32", layout="CDAB"),  # gap 1: merged with a
    Point.of("c", 1, "40010", "int32"),  # gap 5: merged with max_gap=5
    Point.of("d", 1, "40100"),  # far: its own read
    Point.of("e", 1, "30005", "int16", scale=0.5),
    Point.of("f", 2, "40001"),
    Point.of("g", 2, "00010"),
    Point.of("h", 2, "00030"),  # 19 bits after g: merged (bit gap 80)
    Point.of("i", 2, "10002"),
]


def wire(request: object) -> tuple[int, int, int]:
    match request:
        case (
            ReadHoldingRegistersRequest(address=a, count=n)
            | ReadInputRegistersRequest(address=a, count=n)
            | ReadCoilsRequest(address=a, count=n)
            | ReadDiscreteInputsRequest(address=a, count=n)
        ):
            return request.function_code, a, n  # type: ignore[attr-defined]
    raise AssertionError(request)


@on_virtual_clock
async def test_the_requests_on_the_wire_are_the_merged_ranges_and_values_decode() -> None:
    async with line() as (master, slave, _):
        poller = Poller(master, POINTS, max_gap=5, max_bit_gap=80)
        samples = {s.name: s for s in await poller.poll_once()}
        requests = [(seen.unit, *wire(seen.request)) for seen in slave.seen]
        assert requests == [
            (1, 0x03, 0, 11),  # a, b, c: addresses 0..10
            (1, 0x03, 99, 1),  # d
            (1, 0x04, 4, 1),  # e
            (2, 0x01, 9, 21),  # g, h: coils 9..29
            (2, 0x02, 1, 1),  # i
            (2, 0x03, 0, 1),  # f
        ]
        assert next((r.unit, r.table, r.address, r.count) for r in poller.reads) == (
            1,
            Table.HOLDING_REGISTERS,
            0,
            11,
        )
    assert all(s.ok for s in samples.values())
    assert samples["a"].value == register_value(1, 0)
    assert samples["b"].value == decode_value(
        [register_value(1, 2), register_value(1, 3)], ValueType.FLOAT32, "CDAB"
    )
    assert samples["c"].value == decode_value(
        [register_value(1, 9), register_value(1, 10)], ValueType.INT32
    )
    assert samples["d"].value == register_value(1, 99)
    raw_e = decode_value([register_value(1, 4) ^ 0xFFFF], ValueType.INT16)
    assert samples["e"].value == pytest.approx(raw_e * 0.5)
    assert samples["f"].value == register_value(2, 0)
    assert samples["g"].value is coil_value(2, 9)
    assert samples["h"].value is coil_value(2, 29)
    assert samples["i"].value is coil_value(2, 1)


@on_virtual_clock
async def test_samples_reach_callbacks_and_the_async_iterator() -> None:
    seen: list[Sample] = []
    cycles: list[CycleReport] = []

    async def on_cycle(report: CycleReport) -> None:
        cycles.append(report)

    async with line() as (master, _, _):
        poller = Poller(master, POINTS[:3], interval=0.02, on_sample=seen.append, on_cycle=on_cycle)
        got: list[Sample] = []
        with anyio.fail_after(5):
            async with poller:
                async for sample in poller:
                    got.append(sample)
                    if len(got) == 9:
                        break
    assert [s.name for s in got] == ["a", "b", "c"] * 3
    assert [s.cycle for s in got] == [0, 0, 0, 1, 1, 1, 2, 2, 2]
    assert seen[:9] == got
    assert cycles[0].samples == tuple(got[:3])
    stats = poller.cycle_time
    assert stats.cycles >= 3
    assert stats.last is not None
    assert stats.mean is not None
    assert poller.health()[1].online


@on_virtual_clock
async def test_run_stops_after_the_cycles_and_ends_the_iteration() -> None:
    async with line() as (master, _, _):
        poller = Poller(master, POINTS[:2], interval=0.01)
        with anyio.fail_after(5):
            await poller.run(cycles=4)
        assert poller.cycle_time.cycles == 4
        assert len([s async for s in poller]) == 8


@on_virtual_clock
async def test_points_with_their_own_interval_poll_on_their_own_schedule() -> None:
    async with line() as (master, _, _):
        fast = Point.of("fast", 1, "40001", interval=0.02)
        slow = Point.of("slow", 1, "40002", interval=0.2)
        poller = Poller(master, [fast, slow])
        await poller.run(duration=0.5)
        stats = poller.cycle_stats
        assert stats[0.02].cycles > 3 * stats[0.2].cycles


def _sent_to(bus: VirtualBus, unit: int) -> list[float]:
    """When the master put each request to *unit* on the line: its own schedule, which a
    slow slave task cannot shift as it shifts the times the slave sees them."""
    return [entry.start for entry in bus.trace if entry.sender == 0 and entry.data[0] == unit]


async def _dead_unit_per_cycle(points: list[Point], cycles: int) -> tuple[list[float], list[int]]:
    """Poll `points` (unit 4 is dead) for `cycles` cycles: each cycle's duration, and the
    requests unit 4 had seen by its end."""
    durations: list[float] = []
    dead_requests: list[int] = []
    units = frozenset({1, 2, 3})
    # Replies are due from units 1 to 3: a timeout no load reaches.
    options = {"timeout": 0.5, "retries": 0, "offline_after": 1}
    async with line(units=units, **options) as (master, slave, _):

        def on_cycle(report: CycleReport) -> None:
            durations.append(report.duration)
            dead_requests.append(sum(1 for seen in slave.seen if seen.unit == 4))

        poller = Poller(master, points, interval=0.001, offline_probe_interval=60)
        poller.on_cycle(on_cycle)
        await poller.run(cycles=cycles)
    return durations, dead_requests


@on_virtual_clock
async def test_a_dead_unit_does_not_stall_the_cycle() -> None:
    alive = [Point.of(f"u{u}r{r}", u, f"4{r * 20 + 1:04d}") for u in (1, 2, 3) for r in range(3)]
    dead = [Point.of(f"u4r{r}", 4, f"4{r * 20 + 1:04d}") for r in range(3)]
    durations, dead_requests = await _dead_unit_per_cycle(alive + dead, 8)
    # The first cycle sends one request to the dead unit and pays its timeout; its other
    # reads are skipped. Offline from then on (and its probe a minute away), it gets no
    # request at all: no later cycle can wait for it.
    assert dead_requests == [1] * 8
    assert durations[0] >= 0.5


@on_virtual_clock
async def test_an_offline_unit_is_probed_every_offline_probe_interval() -> None:
    # Unit 1 answers: a timeout no load reaches. Unit 2 never does.
    options = {"timeout": 0.5, "retries": 0, "offline_after": 1}
    cycles = 100
    async with line(units=frozenset({1}), **options) as (master, slave, bus):
        points = [Point.of("alive", 1, "40001"), Point.of("dead", 2, "40001")]
        samples: list[Sample] = []
        poller = Poller(
            master, points, interval=0.01, offline_probe_interval=0.8, on_sample=samples.append
        )
        started = anyio.current_time()
        await poller.run(cycles=cycles)
        elapsed = anyio.current_time() - started
        probes = _sent_to(bus, 2)
        alive = [seen for seen in slave.seen if seen.unit == 1]
    # The first read, then one probe per 0.8 s at most (longer than an attempt's 0.5 s, so
    # the gaps show the schedule). The cycles after the first read, 0.01 s apart, last at
    # least 0.99 s: at least one probe is due.
    assert len(probes) >= 2, probes
    assert len(probes) <= 1 + elapsed / 0.8, (probes, elapsed)
    gaps = [b - a for a, b in itertools.pairwise(probes)]
    assert all(gap >= 0.8 for gap in gaps), gaps
    assert len(alive) == cycles
    dead = [s for s in samples if s.name == "dead"]
    assert sum(isinstance(s.error, UnitSkipped) for s in dead) == cycles - len(probes)
    assert all(isinstance(s.error, aiortu.ResponseTimeout) for s in dead)
    health = poller.health()
    assert not health[2].online
    assert health[2].skipped == cycles - len(probes)
    assert health[2].next_probe is not None


@on_virtual_clock
async def test_the_poll_command_redraws_its_table_in_place_on_a_terminal() -> None:
    async with line() as (master, _, _):
        out = io.StringIO()
        poller = Poller(master, POINTS[:2])
        printer = TablePrinter(out, poller, ansi=True)
        poller.on_cycle(printer.show)
        await poller.run(cycles=2)
    first, second = out.getvalue().split("\x1b[", 1)
    lines = first.splitlines()
    assert len(lines) == 5  # header, column titles, two points, one unit
    assert lines[2] == f"a                   1  {register_value(1, 0)}"
    # The second table moves back up over the first and clears it.
    assert second.startswith("5F\x1b[J")


@on_virtual_clock
async def test_dead_units_take_turns_for_one_probe_per_cycle() -> None:
    # Only dead units: no reply is due, so the short timeout cannot turn a slow reply into
    # one more offline unit taking its turn.
    options = {"timeout": 0.05, "retries": 0, "offline_after": 1}
    dead_units = (4, 5, 6)
    async with line(units=frozenset({1}), **options) as (master, slave, _):
        points = [Point.of(f"dead{unit}", unit, "40001") for unit in dead_units]
        poller = Poller(master, points, interval=0.001, offline_probe_interval=0)
        await poller.run(cycles=10)
        sent = [seen.unit for seen in slave.seen if seen.unit in dead_units]
    # Cycle 1 tries each dead unit once (they are not known to be dead yet); from then on
    # one probe per cycle, the unit waiting longest first: 4, 5, 6, 4, 5, 6, ...
    assert sent[:3] == [4, 5, 6]
    assert sent[3:] == [4, 5, 6, 4, 5, 6, 4, 5, 6]


@on_virtual_clock
async def test_max_probes_per_cycle_none_probes_every_due_unit() -> None:
    options = {"timeout": 0.05, "retries": 0, "offline_after": 1}  # no reply is due
    async with line(units=frozenset({1}), **options) as (master, slave, _):
        points = [Point.of(f"dead{unit}", unit, "40001") for unit in (4, 5)]
        poller = Poller(
            master, points, interval=0.001, offline_probe_interval=0, max_probes_per_cycle=None
        )
        await poller.run(cycles=3)
        sent = [seen.unit for seen in slave.seen if seen.unit in (4, 5)]
    assert sent == [4, 5, 4, 5, 4, 5]
    with pytest.raises(aiortu.InvalidValue):
        Poller(master, points, max_probes_per_cycle=0)


@on_virtual_clock
async def test_a_dead_unit_is_suspect_then_offline_and_then_only_probed() -> None:
    # The master keeps its defaults: 2 retries, offline after 3 failed transactions. Unit 1
    # answers (a timeout no load reaches); unit 2 never does.
    cycles = 25
    async with line(units=frozenset({1}), timeout=0.5) as (master, slave, bus):
        points = [Point.of("alive", 1, "40001"), Point.of("dead", 2, "40001")]
        states: list[UnitState] = []
        attempts_by_cycle: list[int] = []

        def on_cycle(_: CycleReport) -> None:
            states.append(poller.health()[2].state)
            attempts_by_cycle.append(sum(1 for seen in slave.seen if seen.unit == 2))

        poller = Poller(master, points, interval=0.03, offline_probe_interval=0.6)
        poller.on_cycle(on_cycle)
        await poller.run(cycles=cycles)
        attempts = _sent_to(bus, 2)
        alive = [seen for seen in slave.seen if seen.unit == 1]
        health = poller.health()[2]
        stats = master.unit_stats(2)
    # Cycle 1 tries three times (the master's retries); cycles 2 and 3 read the suspect
    # unit once each; then it is offline and only probed, once per 0.6 s at most.
    assert states[:3] == [UnitState.SUSPECT, UnitState.SUSPECT, UnitState.OFFLINE], states
    assert states[3:] == [UnitState.OFFLINE] * (cycles - 3), states
    assert attempts_by_cycle[:3] == [3, 4, 5], attempts_by_cycle
    first, suspect, probes = attempts[:3], attempts[3:5], attempts[5:]
    # Retries are spaced by the timeout and the late-reply guard (docs/master.md).
    assert all(b - a >= 0.5 + master.engine.late_reply_guard for a, b in itertools.pairwise(first))
    # The 22 cycles after, 0.03 s apart, last at least 0.66 s: a probe is due.
    assert len(probes) >= 1, attempts
    assert probes[0] - suspect[1] >= 0.6
    assert all(b - a >= 0.6 for a, b in itertools.pairwise(probes)), attempts
    # At most one probe a cycle; the live unit is read every cycle whatever the dead one does.
    assert all(b - a <= 1 for a, b in itertools.pairwise(attempts_by_cycle[2:]))
    assert len(alive) == cycles
    # The poller's health and the master's statistics tell the same story.
    assert health.state is stats.state is UnitState.OFFLINE
    assert health.next_probe is not None
    assert health.next_probe >= probes[-1] - 1e-9
    assert poller.health()[1].state is UnitState.ONLINE


@on_virtual_clock
async def test_one_crc_error_costs_one_sample_not_seconds() -> None:
    garbled = {"done": False}

    async def garble_once(slave: FakeSlave, unit: int, request: Request) -> None:
        if garbled["done"]:
            await answer(slave, unit, request)
            return
        garbled["done"] = True
        frame = bytearray(encode_frame(unit, standard_reply(unit, request)))
        frame[-1] ^= 0xFF
        await slave.send_raw(bytes(frame))

    # The CLI's default: no retries.
    # Every reply is due (the garbled one too): a timeout no load reaches.
    async with line(default=garble_once, retries=0, timeout=5) as (master, _, _):
        samples: list[Sample] = []
        poller = Poller(
            master, [Point.of("a", 1, "40001")], interval=0.001, on_sample=samples.append
        )
        suspect: list[UnitHealth] = []
        poller.on_cycle(lambda _: suspect.append(poller.health()[1]))
        await poller.run(cycles=5)
    assert isinstance(samples[0].error, aiortu.CRCError)
    assert suspect[0].state is UnitState.SUSPECT
    assert suspect[0].next_probe is None
    # The next cycle reads the unit again, and it is online once it answers.
    assert [s.ok for s in samples] == [False, True, True, True, True]
    assert suspect[1].state is UnitState.ONLINE


async def test_a_hole_in_a_merged_read_splits_it_once_and_fails_only_the_missing_point() -> None:
    # The device has holding registers 107..109 and 111..112, not 110: a read across 110
    # is refused whole with exception 02, as real devices do.
    hole = 110

    async def with_a_hole(slave: FakeSlave, unit: int, request: Request) -> None:
        _, address, count = wire(request)
        if address <= hole < address + count:
            await slave.reply(unit, bytes((0x83, 0x02)))
        else:
            await answer(slave, unit, request)

    points = [
        Point.of("a", 17, "40108"),
        Point.of("b", 17, "40112", "int32"),
        Point.of("missing", 17, "40111"),
        Point.of("also_a", 17, "40108", "int32"),
    ]
    async with line(default=with_a_hole) as (master, slave, _):
        poller = Poller(master, points, max_gap=10)
        assert [(r.address, r.count) for r in poller.reads] == [(107, 6)]
        first = {s.name: s for s in await poller.poll_once()}
        second = {s.name: s for s in await poller.poll_once()}
        requests = [wire(seen.request)[1:] for seen in slave.seen]
    # The merged read once, then each address alone, in both cycles.
    assert requests == [(107, 6), (107, 2), (110, 1), (111, 2), (107, 2), (110, 1), (111, 2)]
    assert poller.split_reads == 1
    assert [(r.address, r.count) for r in poller.reads] == [(107, 2), (110, 1), (111, 2)]
    for samples in (first, second):
        assert samples["a"].value == register_value(17, 107)
        assert samples["also_a"].ok
        assert samples["b"].value == decode_value(
            [register_value(17, 111), register_value(17, 112)], ValueType.INT32
        )
        error = samples["missing"].error
        assert isinstance(error, aiortu.ExceptionResponse)
        assert error.code == 2


async def test_a_read_of_one_address_refused_is_not_split_again() -> None:
    async def refuse(slave: FakeSlave, unit: int, request: Request) -> None:
        await slave.reply(unit, bytes((0x83, 0x02)))

    points = [Point.of("a", 17, "40108"), Point.of("a32", 17, "40108", "int32")]
    async with line(default=refuse) as (master, slave, _):
        poller = Poller(master, points)
        samples = await poller.poll_once()
        assert len(slave.seen) == 1
    assert poller.split_reads == 0
    assert all(isinstance(s.error, aiortu.ExceptionResponse) for s in samples)

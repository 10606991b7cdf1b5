"""Polling many points on many units at given intervals, over one master.

    points = [
        aiortu.Point.of("temperature", 1, "30001", "int16", scale=0.1),
        aiortu.Point.of("flow", 1, "40108", "float32", layout="CDAB"),
        aiortu.Point("pump", 2, "coils", 0),
    ]
    async with aiortu.Poller(master, points, interval=1.0) as poller:
        async for sample in poller:
            print(sample.name, sample.value)

The points are planned once
([`aiortu.core.model.plan_reads`][aiortu.core.model.plan_reads]): neighbours on the same
unit and table share one read when the gap between them is at most `max_gap` elements, within the
spec's limits. A device whose map has a hole inside a merged read refuses the whole block with
exception 02 (illegal data address): the poller then splits that read into the reads of its
points alone ([`PlannedRead.split`][aiortu.core.model.PlannedRead.split]), at once and for
good, so the hole costs one request once and only a point that is really missing shows the
exception. Points with their own `interval` are polled on their own schedule; each interval has
its own cycle.

A cycle runs its reads one after the other (the line carries one transaction at a time anyway) and
delivers one [`Sample`][aiortu.master.Sample] per point: a value, or the error that kept it from
being read. Samples go to the callbacks given as `on_sample` (and `on_cycle`, once per cycle with
all its samples) and to `async for sample in poller`; when an iterating consumer falls more than
`max_pending` samples behind, the oldest are dropped and counted in
[`Poller.dropped`][aiortu.master.Poller.dropped].

Dead devices: the poller uses the master's notion of a unit's state
([`UnitState`][aiortu.master.UnitState]). A read that fails (no reply, a garbled one;
not an exception response, which is an answer) makes the unit *suspect*: its other
reads in that cycle are skipped, so one dead device costs at most one timeout per
cycle, but it is read again in the next cycle, once, without the master's retries: one
CRC error on a noisy line costs one sample, not seconds of them. After the master's
`offline_after` failures in a row the unit is *offline*: its reads are skipped,
delivering samples with [`UnitSkipped`][aiortu.errors.UnitSkipped], except for one probe read every
`offline_probe_interval` seconds, sent once; a probe that succeeds brings the unit back
(the master marks it online) and its other reads go on in the same cycle. At most
`max_probes_per_cycle` offline units (1 by default; `None` for no limit) are probed
in one cycle, the one waiting longest first: with many dead devices on a bus, a cycle
pays for one probe, not for one per dead device, and they take turns.
"""

from __future__ import annotations

import inspect
import math
from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass
from typing import TypeVar

import anyio
import anyio.abc

from aiortu.core.codes import ExceptionCode
from aiortu.core.model import (
    MAX_READ_BITS,
    MAX_READ_REGISTERS,
    PlannedRead,
    Point,
    Table,
    plan_reads,
)
from aiortu.core.pdu import (
    ReadCoilsRequest,
    ReadCoilsResponse,
    ReadDiscreteInputsRequest,
    ReadDiscreteInputsResponse,
    ReadHoldingRegistersRequest,
    ReadHoldingRegistersResponse,
    ReadInputRegistersRequest,
    ReadInputRegistersResponse,
    Response,
)
from aiortu.errors import (
    ConnectionLost,
    ExceptionResponse,
    InvalidValue,
    ModbusError,
    UnitSkipped,
)
from aiortu.master._background import BackgroundPoll
from aiortu.master._client import Master
from aiortu.master._stats import UnitState, UnitStats

__all__ = ("CycleReport", "CycleStats", "Point", "Poller", "Sample", "UnitHealth", "UnitSkipped")

Value = bool | int | float
"""A decoded point value: a bool for bits, an int or a float for registers."""


@dataclass(frozen=True, slots=True)
class Sample:
    """One point's result in one cycle: its `value`, or the `error` that kept it unread.

    `time` is when the read finished, on the master's clock; `cycle` counts the cycles
    of the point's interval from 0.
    """

    point: Point
    value: Value | None
    time: float
    cycle: int
    error: Exception | None = None

    @property
    def name(self) -> str:
        """The point's name."""
        return self.point.name

    @property
    def unit(self) -> int:
        """The point's unit."""
        return self.point.unit

    @property
    def ok(self) -> bool:
        """Whether the point was read."""
        return self.error is None


@dataclass(frozen=True, slots=True)
class CycleReport:
    """One finished cycle of one interval: its index, duration (s) and samples."""

    interval: float
    index: int
    duration: float
    samples: tuple[Sample, ...]


@dataclass(slots=True)
class CycleStats:
    """The cycle times of one interval, in seconds (the reads only, not the waits)."""

    interval: float
    cycles: int = 0
    last: float | None = None
    mean: float | None = None
    longest: float | None = None

    def _record(self, duration: float) -> None:
        self.cycles += 1
        self.last = duration
        previous = self.mean if self.mean is not None else 0.0
        self.mean = previous + (duration - previous) / self.cycles
        self.longest = duration if self.longest is None else max(self.longest, duration)


@dataclass(frozen=True, slots=True)
class UnitHealth:
    """What the poller knows of a unit: the master's health and its own probing."""

    unit: int
    state: UnitState
    """Online, suspect (failed lately, still read every cycle) or offline (probed only)."""
    consecutive_failures: int
    last_latency: float | None
    skipped: int
    """Reads of the unit skipped while it was offline."""
    next_probe: float | None
    """When the next probe may go (master clock), or None unless offline."""

    @property
    def online(self) -> bool:
        """Whether the unit is read every cycle (online or suspect)."""
        return self.state is not UnitState.OFFLINE


SampleCallback = Callable[[Sample], object]
CycleCallback = Callable[[CycleReport], object]
_C = TypeVar("_C", SampleCallback, CycleCallback)


@dataclass
class _Group:
    interval: float
    reads: list[PlannedRead]
    stats: CycleStats
    cycle: int = 0


def _checked_points(points: Iterable[Point]) -> tuple[Point, ...]:
    """`points` as a tuple, checked: at least one, and no name twice."""
    checked = tuple(points)
    if not checked:
        raise InvalidValue("points", checked, "at least one point")
    names = [p.name for p in checked]
    if len(set(names)) != len(names):
        duplicate = next(n for n in names if names.count(n) > 1)
        raise InvalidValue("points", duplicate, "unique names", "a name is used twice")
    return checked


def _planned_groups(
    points: tuple[Point, ...],
    interval: float,
    *,
    max_gap: int,
    max_bit_gap: int | None,
    max_registers: int,
    max_bits: int,
) -> list[_Group]:
    """The reads that poll `points`, one group per interval (a point's own, else
    `interval`), shortest first; the limits go to the planner."""
    by_interval: dict[float, list[Point]] = {}
    for point in points:
        by_interval.setdefault(point.interval or interval, []).append(point)
    return [
        _Group(
            every,
            plan_reads(
                members,
                max_gap=max_gap,
                max_bit_gap=max_bit_gap,
                max_registers=max_registers,
                max_bits=max_bits,
            ),
            CycleStats(every),
        )
        for every, members in sorted(by_interval.items())
    ]


class Poller(BackgroundPoll[Sample]):
    """Polls `points` through `master` (see the module docstring); an async context manager.

    `interval` is the default seconds from the start of one cycle to the start of the
    next (a cycle that takes longer is followed at once by the next). `max_gap`,
    `max_bit_gap`, `max_registers` and `max_bits` go to the planner. `timeout` is the
    response timeout of the poller's reads (None: the master's). `on_sample` and
    `on_cycle` are callbacks (plain or async functions, or iterables of them).

    Raises [`InvalidValue`][aiortu.errors.InvalidValue] for an empty point list, duplicate names
    or limits outside the spec.
    """

    _task_name = "aiortu poller"

    def __init__(
        self,
        master: Master,
        points: Iterable[Point],
        *,
        interval: float = 1.0,
        max_gap: int = 10,
        max_bit_gap: int | None = None,
        max_registers: int = MAX_READ_REGISTERS,
        max_bits: int = MAX_READ_BITS,
        offline_probe_interval: float = 5.0,
        max_probes_per_cycle: int | None = 1,
        timeout: float | None = None,
        on_sample: SampleCallback | Iterable[SampleCallback] | None = None,
        on_cycle: CycleCallback | Iterable[CycleCallback] | None = None,
        max_pending: int = 1024,
    ) -> None:
        self.master = master
        self.points: tuple[Point, ...] = _checked_points(points)
        """The points polled."""
        if not interval > 0:
            raise InvalidValue("interval", interval, "seconds > 0")
        if not offline_probe_interval >= 0:
            raise InvalidValue("offline_probe_interval", offline_probe_interval, "seconds >= 0")
        if max_probes_per_cycle is not None and max_probes_per_cycle < 1:
            raise InvalidValue("max_probes_per_cycle", max_probes_per_cycle, "None or >= 1")
        self.interval = interval
        self.offline_probe_interval = offline_probe_interval
        self.max_probes_per_cycle = max_probes_per_cycle
        self.timeout = timeout
        self._groups = _planned_groups(
            self.points,
            interval,
            max_gap=max_gap,
            max_bit_gap=max_bit_gap,
            max_registers=max_registers,
            max_bits=max_bits,
        )
        self._sample_callbacks = _as_list(on_sample)
        self._cycle_callbacks = _as_list(on_cycle)
        self._last_probe: dict[int, float] = {}
        self._probe_slots: set[int] | None = None
        self._skipped: dict[int, int] = {}
        self._open_stream(max_pending)
        self.dropped = 0
        """Samples dropped because the iterating consumer fell behind."""
        self.split_reads = 0
        """Merged reads a device refused with exception 02 (a hole in its map), each
        replaced by the reads of its points alone (see [`reads`][aiortu.master.Poller])."""

    # -- what is polled, and how it goes ----------------------------------------------

    @property
    def reads(self) -> list[PlannedRead]:
        """Every planned read, by interval, then unit, table and address."""
        return [read for group in self._groups for read in group.reads]

    @property
    def cycle_stats(self) -> dict[float, CycleStats]:
        """The cycle times, by interval."""
        return {group.interval: group.stats for group in self._groups}

    @property
    def cycle_time(self) -> CycleStats:
        """The cycle times of the shortest interval (the only one unless points set theirs)."""
        return self._groups[0].stats

    def health(self) -> dict[int, UnitHealth]:
        """Each polled unit's health, by unit address."""
        report: dict[int, UnitHealth] = {}
        for unit in sorted({p.unit for p in self.points}):
            stats = self.master.unit_stats(unit)
            report[unit] = UnitHealth(
                unit,
                stats.state,
                stats.consecutive_failures,
                stats.last_latency,
                self._skipped.get(unit, 0),
                self._next_probe(unit, stats),
            )
        return report

    def _next_probe(self, unit: int, stats: UnitStats) -> float | None:
        """When `unit` may be probed next: an interval after it went offline or after
        its last probe; None unless offline."""
        if stats.online:
            return None
        last = max(stats.last_probe, self._last_probe.get(unit, -math.inf))
        return last + self.offline_probe_interval

    def on_sample(self, callback: SampleCallback) -> Callable[[], None]:
        """Call `callback` with every sample from now on; return a function that stops it."""
        self._sample_callbacks.append(callback)
        return lambda: self._sample_callbacks.remove(callback)

    def on_cycle(self, callback: CycleCallback) -> Callable[[], None]:
        """Call `callback` after every cycle; return a function that stops it."""
        self._cycle_callbacks.append(callback)
        return lambda: self._cycle_callbacks.remove(callback)

    # -- running ---------------------------------------------------------------------

    async def run(self, *, cycles: int | None = None, duration: float | None = None) -> None:
        """Poll in the current task until cancelled, or until `cycles` cycles of the
        shortest interval have run, or `duration` seconds have passed. Ends the sample
        stream when it returns."""
        try:
            with anyio.move_on_after(math.inf if duration is None else duration):
                async with anyio.create_task_group() as tasks:
                    for group in self._groups[1:]:
                        tasks.start_soon(self._loop, group, None)
                    await self._loop(self._groups[0], cycles)
                    tasks.cancel_scope.cancel()
        finally:
            self._send.close()

    async def poll_once(self) -> list[Sample]:
        """Run one cycle of every interval now, and return its samples (also delivered)."""
        samples: list[Sample] = []
        for group in self._groups:
            samples.extend(await self._cycle(group))
        return samples

    # -- the cycles ------------------------------------------------------------------

    async def _loop(self, group: _Group, cycles: int | None) -> None:
        clock = self.master.clock
        next_start = clock()
        while cycles is None or group.cycle < cycles:
            await self._cycle(group)
            next_start += group.interval
            # After an overrun the next cycle starts at once; missed cycles are not
            # made up in a burst.
            next_start = max(next_start, clock())
            if cycles is not None and group.cycle >= cycles:
                return
            await anyio.sleep(max(0.0, next_start - clock()))

    async def _cycle(self, group: _Group) -> list[Sample]:
        clock = self.master.clock
        start = clock()
        index = group.cycle
        samples: list[Sample] = []
        skip: dict[int, Exception] = {}
        self._probe_slots = self._units_to_probe(group, start)
        pending = list(group.reads)
        while pending:
            read = pending.pop(0)
            error = skip.get(read.unit) or self._gate(read.unit)
            if error is not None:
                skip[read.unit] = error
                if isinstance(error, UnitSkipped):
                    self._skipped[read.unit] = self._skipped.get(read.unit, 0) + 1
                samples += await self._deliver_error(read, error, index)
                continue
            try:
                # A read of a unit that stopped answering is sent once: its retries
                # would stall the cycle for every other unit.
                elements = await self._read(read, 0 if self._failing(read.unit) else None)
            except ModbusError as failure:
                parts = _split_for(read, failure)
                if parts:
                    # A hole in the device's map: read the points alone, now and from now
                    # on, so that the hole costs one request once, not every point.
                    position = group.reads.index(read)
                    group.reads[position : position + 1] = parts
                    pending[:0] = parts
                    self.split_reads += 1
                    continue
                samples += await self._deliver_error(read, failure, index)
                if isinstance(failure, ConnectionLost):
                    # The line is down: every other unit would fail the same way.
                    for other in group.reads:
                        skip.setdefault(other.unit, failure)
                elif not isinstance(failure, ExceptionResponse):
                    skip[read.unit] = failure
                continue
            now = clock()
            for point, value in read.decode(elements):
                sample = Sample(point, value, now, index)
                samples.append(sample)
                await self._deliver(sample)
        group.cycle += 1
        duration = clock() - start
        group.stats._record(duration)
        report = CycleReport(group.interval, index, duration, tuple(samples))
        for callback in list(self._cycle_callbacks):
            await _call(callback, report)
        return samples

    def _failing(self, unit: int) -> bool:
        return self.master.unit_stats(unit).state is not UnitState.ONLINE

    def _units_to_probe(self, group: _Group, now: float) -> set[int] | None:
        """The offline units this cycle may probe: those due, longest waiting first."""
        if self.max_probes_per_cycle is None:
            return None
        # Ties (a unit gone offline at the instant another was probed) go to the unit this
        # poller probed longest ago, so the dead take turns whatever the clock's resolution.
        due = sorted(
            (next_probe, self._last_probe.get(unit, -math.inf), unit)
            for unit in {read.unit for read in group.reads}
            if (next_probe := self._next_probe(unit, self.master.unit_stats(unit))) is not None
            and now >= next_probe
        )
        return {unit for _, _, unit in due[: self.max_probes_per_cycle]}

    def _gate(self, unit: int) -> UnitSkipped | None:
        """None if a read of `unit` may go now (online, or due for a probe), else why not."""
        next_probe = self._next_probe(unit, self.master.unit_stats(unit))
        if next_probe is None:
            return None
        now = self.master.clock()
        if now < next_probe:
            return UnitSkipped(unit, next_probe - now)
        if self._probe_slots is not None and unit not in self._probe_slots:
            return UnitSkipped(unit, 0.0)  # due, waiting for its turn among the dead
        self._last_probe[unit] = now
        return None

    async def _read(self, read: PlannedRead, retries: int | None) -> Sequence[int | bool]:
        request_class, response_class = _READS[read.table]
        request = request_class(read.address, read.count)
        reply = await self.master.request(
            read.unit, request, response_class, timeout=self.timeout, retries=retries
        )
        if isinstance(request, ReadCoilsRequest):
            assert isinstance(reply, ReadCoilsResponse)
            return request.bits_of(reply)
        assert isinstance(reply, ReadHoldingRegistersResponse)
        return reply.values

    async def _deliver_error(self, read: PlannedRead, error: Exception, index: int) -> list[Sample]:
        now = self.master.clock()
        samples = [Sample(point, None, now, index, error) for point in read.points]
        for sample in samples:
            await self._deliver(sample)
        return samples

    async def _deliver(self, sample: Sample) -> None:
        for callback in list(self._sample_callbacks):
            await _call(callback, sample)
        self._publish(sample)


def _split_for(read: PlannedRead, failure: ModbusError) -> list[PlannedRead]:
    """The reads to make instead of `read` that `failure` refused as a block: its points
    alone when the device said "illegal data address" to a read of several; else none."""
    hole = ExceptionCode.ILLEGAL_DATA_ADDRESS
    if isinstance(failure, ExceptionResponse) and failure.code == hole:
        parts = read.split()
        if len(parts) > 1:
            return parts
    return []


_READS: dict[Table, tuple[type[ReadCoilsRequest | ReadHoldingRegistersRequest], type[Response]]] = {
    Table.COILS: (ReadCoilsRequest, ReadCoilsResponse),
    Table.DISCRETE_INPUTS: (ReadDiscreteInputsRequest, ReadDiscreteInputsResponse),
    Table.HOLDING_REGISTERS: (ReadHoldingRegistersRequest, ReadHoldingRegistersResponse),
    Table.INPUT_REGISTERS: (ReadInputRegistersRequest, ReadInputRegistersResponse),
}
"""The request and reply classes of a read of each table."""


def _as_list(callbacks: _C | Iterable[_C] | None) -> list[_C]:
    if callbacks is None:
        return []
    if callable(callbacks):
        return [callbacks]
    return list(callbacks)


async def _call(callback: Callable[..., object], argument: object) -> None:
    result = callback(argument)
    if inspect.isawaitable(result):
        await result

"""A small simulated plant on an in-memory bus, polled by a [`Poller`][aiortu.master.Poller].

This is what `aiortu demo` shows, and a worked example of the whole stack: three
devices, each an [`Slave`][aiortu.slave.Slave] over a [`MemoryStore`][aiortu.slave.MemoryStore]
on its own drop of a four-port [`VirtualBus`][aiortu.testing.VirtualBus] paced at the baud
rate, and a [`Master`][aiortu.master.Master] on the fourth drop that polls typed points
with a Poller and writes a new setpoint now and then:

    async with Demo(baudrate=19200, seed=1) as demo:
        for _ in range(10):
            snapshot = await demo.next_snapshot()
            print(snapshot.elapsed, snapshot.value("controller.process_value"))

The devices (unit address, register map; see `aiortu.cli`):

- unit 1, `EnergyMeter`: float32 readings in CDAB word order in input registers:
  voltage (30001), current (30007), power (30013) and energy (30343), moving as a
  household supply does: a mains voltage wandering around 230 V, a load that steps when
  an appliance switches, energy that only ever counts up.
- unit 2, `TemperatureController`: the setpoint in holding register 40001 and the
  process value in input register 30001, both int16 tenths of a degree, and the heater
  output in percent in 30002. The process value follows the setpoint with a first-order
  lag, so a new setpoint visibly takes effect over a few seconds. The device watches its
  store with an observer and logs each setpoint a master writes.
- unit 3, `DigitalIO`: four output coils (pump, fan, valve, lamp, 00001-00004)
  and four discrete inputs (10001-10004): pump and fan feedback that follow their coils
  after a short delay, a door contact that opens and closes at random, and a heartbeat.

The scenario: after `first_change` seconds, and then every `change_every` seconds, the
master writes the next of `setpoints` to the controller (function 06) and switches the
pump and fan for heating or cooling (function 0F). Each `Snapshot` carries the
latest values, a trend per value, the health of each unit, the poll cycle times and the
recent `DemoEvent`s.
"""

from __future__ import annotations

import contextlib
import random
from collections import deque
from collections.abc import Sequence
from dataclasses import dataclass
from types import TracebackType
from typing import Self

import anyio

from aiortu.cli._demo_devices import (
    DigitalIO,
    EnergyMeter,
    Reading,
    SimulatedDevice,
    TemperatureController,
    Value,
    to_tenths,
)
from aiortu.core.serial import LineSettings
from aiortu.errors import InvalidValue, ModbusError
from aiortu.master import CycleReport, CycleStats, Master, Point, Poller, UnitHealth, UnitStats
from aiortu.slave import Slave
from aiortu.testing import VirtualBus

__all__ = ("Demo", "DemoEvent", "DeviceView", "ReadingView", "Snapshot")

_STEP = 0.1
"""Seconds between two steps of the device simulation."""


@dataclass(frozen=True, slots=True)
class DemoEvent:
    """Something that happened, `time` seconds after the demo started."""

    time: float
    text: str


@dataclass(frozen=True, slots=True)
class ReadingView:
    """One reading in a `Snapshot`: the value (None until read or after an error),
    its display text, and its `trend` since the previous cycle (-1, 0 or +1)."""

    reading: Reading
    value: Value | None
    text: str
    trend: int = 0
    error: str | None = None


@dataclass(frozen=True, slots=True)
class DeviceView:
    """One device in a `Snapshot`: its readings, health and the master's counters."""

    unit: int
    title: str
    register_map: str
    readings: tuple[ReadingView, ...]
    health: UnitHealth
    stats: UnitStats


@dataclass(frozen=True, slots=True)
class Snapshot:
    """The state of the demo after one poll cycle (see `Demo.snapshot`)."""

    elapsed: float
    """Seconds since the demo started."""
    cycle: int
    """Poll cycles finished so far."""
    devices: tuple[DeviceView, ...]
    cycle_time: CycleStats
    reads_per_cycle: int
    events: tuple[DemoEvent, ...]
    """The latest events, oldest first."""
    event_count: int
    """Events logged since the start; the last `len(events)` of them are in `events`."""
    next_change: float | None
    """When the next setpoint change is due (seconds since the start), if any."""

    def value(self, name: str) -> Value | None:
        """The latest value of the point called `name` (`"meter.voltage"`)."""
        for device in self.devices:
            for view in device.readings:
                if view.reading.point.name == name:
                    return view.value
        raise KeyError(name)


class Demo:
    """The simulated plant, its bus, master and poller; an async context manager.

    `baudrate` paces the bus (8E1, the spec's default framing). `interval` is the poll
    interval in seconds. The scenario writes `setpoints` (degrees, in turn) at
    `first_change` seconds and then every `change_every` seconds (None: once). `seed`
    makes the simulation repeatable; `degree` is the unit of measure shown for
    temperatures.

    Raises [`InvalidValue`][aiortu.errors.InvalidValue] for a baud rate, interval or schedule
    that is not positive, or no setpoints.
    """

    def __init__(
        self,
        *,
        baudrate: int = 19200,
        interval: float = 0.5,
        setpoints: Sequence[float] = (45.0, 30.0),
        first_change: float | None = 4.0,
        change_every: float | None = 30.0,
        seed: int | None = None,
        degree: str = "°C",
        max_events: int = 6,
    ) -> None:
        if not interval > 0:
            raise InvalidValue("interval", interval, "seconds > 0")
        if first_change is not None and not first_change >= 0:
            raise InvalidValue("first_change", first_change, "seconds >= 0")
        if change_every is not None and not change_every > 0:
            raise InvalidValue("change_every", change_every, "seconds > 0")
        if not setpoints:
            raise InvalidValue("setpoints", setpoints, "at least one temperature")
        self.settings = LineSettings(baudrate)
        """The line settings of the bus (they set its pacing)."""
        self.interval = interval
        self.setpoints = tuple(float(value) for value in setpoints)
        self.first_change = first_change
        self.change_every = change_every
        rng = random.Random(seed)
        self.meter = EnergyMeter(rng)
        self.controller = TemperatureController(rng, degree=degree)
        self.io = DigitalIO(rng)
        self.devices: tuple[SimulatedDevice, ...] = (self.meter, self.controller, self.io)
        """The simulated devices, by unit address."""
        self.bus = VirtualBus(len(self.devices) + 1, settings=self.settings)
        """The bus: the master on port 0, device *n* on port *n*."""
        self.master = Master(self.bus[0], self.settings, timeout=1.0)
        """The master that polls and writes."""
        self.poller = Poller(
            self.master,
            [reading.point for device in self.devices for reading in device.readings],
            interval=interval,
            on_cycle=self._on_cycle,
        )
        """The poller of every reading."""
        self.events: deque[DemoEvent] = deque(maxlen=max_events)
        """The latest events, oldest first."""
        self.event_count = 0
        """Events logged since the start (more than `events` keeps)."""
        self._start = 0.0
        self._latest: dict[str, ReadingView] = {}
        self._cycles = 0
        self._cycle_done = anyio.Event()
        self._next_change: float | None = None
        self._stack: contextlib.AsyncExitStack | None = None

    # -- lifetime --------------------------------------------------------------------

    async def __aenter__(self) -> Self:
        async with contextlib.AsyncExitStack() as stack:
            self._start = anyio.current_time()
            stack.push_async_callback(self.bus.aclose)
            for port, device in enumerate(self.devices, start=1):
                slave = Slave(self.bus[port], {device.unit: device.store}, self.settings)
                await stack.enter_async_context(slave)
            tasks = await stack.enter_async_context(anyio.create_task_group())
            stack.callback(tasks.cancel_scope.cancel)
            tasks.start_soon(self._simulate, name="aiortu demo simulation")
            await stack.enter_async_context(self.master)
            await stack.enter_async_context(self.poller)
            tasks.start_soon(self._scenario, name="aiortu demo scenario")
            self._stack = stack.pop_all()
        return self

    async def __aexit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        traceback: TracebackType | None,
    ) -> bool | None:
        stack, self._stack = self._stack, None
        if stack is None:
            return None
        return await stack.__aexit__(exc_type, exc, traceback)

    @property
    def elapsed(self) -> float:
        """Seconds since the demo started."""
        return anyio.current_time() - self._start

    # -- what the demo shows -----------------------------------------------------------

    def snapshot(self) -> Snapshot:
        """The latest values, health, cycle times and events."""
        health = self.poller.health()
        devices = tuple(
            DeviceView(
                device.unit,
                device.title,
                device.register_map,
                tuple(
                    self._latest.get(r.point.name) or ReadingView(r, None, r.format(None))
                    for r in device.readings
                ),
                health[device.unit],
                self.master.unit_stats(device.unit),
            )
            for device in self.devices
        )
        return Snapshot(
            self.elapsed,
            self._cycles,
            devices,
            self.poller.cycle_time,
            len(self.poller.reads),
            tuple(self.events),
            self.event_count,
            self._next_change,
        )

    async def next_snapshot(self) -> Snapshot:
        """Wait for the next poll cycle to finish, and return the snapshot after it."""
        await self._cycle_done.wait()
        return self.snapshot()

    def log(self, text: str) -> None:
        """Add an event with the current time."""
        self.events.append(DemoEvent(self.elapsed, text))
        self.event_count += 1

    # -- what the master does ----------------------------------------------------------

    async def write_setpoint(self, celsius: float) -> None:
        """Write a new setpoint to the controller (06), and set the pump and fan (0F) for
        heating or cooling; log both. A failed write is logged, not raised."""
        controller = self.master.slave(self.controller.unit)
        heating = celsius > self.controller.process_value
        degree = self.controller.readings[0].unit_of_measure
        try:
            started = anyio.current_time()
            await controller.write_register(self.controller.SETPOINT, to_tenths(celsius))
            took = (anyio.current_time() - started) * 1000
            self.log(f"master wrote setpoint {celsius:.1f} {degree} to unit 2 ({took:.0f} ms)")
            for old, new in self.controller.setpoint_changes:
                self.log(f"unit 2 saw its setpoint change {old:.1f} -> {new:.1f} {degree}")
            self.controller.setpoint_changes.clear()
            await self.master.write_coils(self.io.unit, 0, [heating, not heating])
            pump, fan = ("on", "off") if heating else ("off", "on")
            purpose = "heating" if heating else "cooling"
            self.log(f"master set unit 3 pump {pump}, fan {fan} for {purpose}")
        except ModbusError as error:
            self.log(f"writing the setpoint failed: {error}")

    # -- background tasks ------------------------------------------------------------

    async def _simulate(self) -> None:
        last = 0.0
        while True:
            now = self.elapsed
            for device in self.devices:
                device.step(now, now - last)
            last = now
            await anyio.sleep(_STEP)

    async def _scenario(self) -> None:
        if self.first_change is None:
            return
        due = self.first_change
        index = 0
        while True:
            self._next_change = due
            await anyio.sleep(max(0.0, due - self.elapsed))
            await self.write_setpoint(self.setpoints[index % len(self.setpoints)])
            index += 1
            if self.change_every is None:
                self._next_change = None
                return
            due += self.change_every

    def _on_cycle(self, report: CycleReport) -> None:
        for sample in report.samples:
            reading = self._reading(sample.point)
            previous = self._latest.get(sample.name)
            if sample.ok:
                trend = _trend(previous.value if previous else None, sample.value, reading)
                view = ReadingView(reading, sample.value, reading.format(sample.value), trend)
            else:
                # Keep the last good value on screen; the error says it is stale.
                kept = previous.value if previous else None
                view = ReadingView(reading, kept, reading.format(kept), 0, str(sample.error))
            self._latest[sample.name] = view
        self._cycles += 1
        done, self._cycle_done = self._cycle_done, anyio.Event()
        done.set()

    def _reading(self, point: Point) -> Reading:
        for device in self.devices:
            for reading in device.readings:
                if reading.point == point:
                    return reading
        raise KeyError(point.name)


def _trend(before: Value | None, after: Value | None, reading: Reading) -> int:
    """+1 or -1 when a number moved by more than its last shown digit, else 0."""
    if isinstance(before, bool) or isinstance(after, bool) or before is None or after is None:
        return 0
    resolution = 10.0**-reading.digits
    if after - before > resolution:
        return 1
    if before - after > resolution:
        return -1
    return 0

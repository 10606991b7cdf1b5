"""The simulated devices of `aiortu demo` (see `aiortu.cli`): each a
[`MemoryStore`][aiortu.slave.MemoryStore] that a [`Slave`][aiortu.slave.Slave] serves, the
`Reading`s a master polls from it, and a simulation step that moves its values.

- `EnergyMeter`: float32 readings in CDAB word order in input registers: voltage
  (30001), current (30007), power (30013) and energy (30343).
- `TemperatureController`: the setpoint in holding register 40001 and the process
  value in input register 30001 (int16 tenths of a degree), heater output in 30002 (%).
- `DigitalIO`: four output coils and four discrete inputs.

The devices take a `random.Random`, so that a seeded generator repeats a run.
"""

from __future__ import annotations

import math
import random
from dataclasses import dataclass
from typing import Protocol

from aiortu.core.model import Layout, Reference, Table, ValueType, encode_value, format_reference
from aiortu.master import Point
from aiortu.slave import Block, Change, MemoryStore

__all__ = (
    "DigitalIO",
    "EnergyMeter",
    "Reading",
    "SimulatedDevice",
    "TemperatureController",
    "Value",
    "from_tenths",
    "to_tenths",
)

Value = bool | int | float
"""A point's value: a bool for bits, an int or a float for registers."""


@dataclass(frozen=True, slots=True)
class Reading:
    """One value the demo polls and shows: its [`Point`][aiortu.core.model.Point], a `label`,
    a unit of measure and how many `digits` after the point to show."""

    point: Point
    label: str
    unit_of_measure: str = ""
    digits: int = 1

    @property
    def reference(self) -> str:
        """The point's 5-digit reference, as a device manual lists it (`"30001"`)."""
        return format_reference(Reference(self.point.table, self.point.address))

    def format(self, value: Value | None) -> str:
        """`value` for display: `"230.4 V"`, `"on"`, or `"-"` when unread."""
        if value is None:
            return "-"
        if isinstance(value, bool):
            return "on" if value else "off"
        text = f"{value:.{self.digits}f}" if isinstance(value, float) else str(value)
        return f"{text} {self.unit_of_measure}" if self.unit_of_measure else text


class SimulatedDevice(Protocol):
    """What the demo needs of a simulated device: its unit address, names, the store a
    [`Slave`][aiortu.slave.Slave] serves, the readings to poll, and a simulation step."""

    unit: int
    title: str
    register_map: str
    store: MemoryStore
    readings: tuple[Reading, ...]

    def step(self, now: float, dt: float) -> None:
        """Advance the simulation to `now` (seconds), `dt` seconds after the last step."""


def _float32_cdab(value: float) -> list[int]:
    return list(encode_value(value, ValueType.FLOAT32, Layout.CDAB))


class EnergyMeter:
    """Unit 1 (by default): a single-phase energy meter with float32 readings in CDAB order.

    `rng` drives the noise and the load steps, so a seeded generator repeats a run.
    """

    VOLTAGE, CURRENT, POWER, ENERGY = 0, 6, 12, 342
    """Input register addresses of the readings (30001, 30007, 30013, 30343)."""

    POWER_FACTOR = 0.93

    def __init__(self, rng: random.Random, unit: int = 1) -> None:
        self.unit = unit
        self.title = "energy meter"
        self.register_map = "float32, CDAB word order: input registers 30001, 30007, 30013, 30343"
        # One block holds the whole map, so reads that merge neighbours never hit a hole.
        self.store = MemoryStore(input_registers=Block(0, 400))
        self.readings: tuple[Reading, ...] = tuple(
            Reading(
                Point(name, unit, Table.INPUT_REGISTERS, address, ValueType.FLOAT32, Layout.CDAB),
                label,
                uom,
                digits,
            )
            for name, address, label, uom, digits in (
                ("meter.voltage", self.VOLTAGE, "voltage", "V", 1),
                ("meter.current", self.CURRENT, "current", "A", 2),
                ("meter.power", self.POWER, "power", "W", 0),
                ("meter.energy", self.ENERGY, "energy", "kWh", 3),
            )
        )
        self._rng = rng
        self._base_load = 4.0
        self._appliance = 0.0
        self._next_switch = 0.0
        self.energy = 842.0 + rng.random() * 10
        """The energy counter in kWh (the simulation's own, full precision)."""
        self.step(0.0, 0.0)

    def step(self, now: float, dt: float) -> None:
        """Advance the meter to `now`: new voltage, current and power; count the energy."""
        rng = self._rng
        if now >= self._next_switch:
            # An appliance (a kettle, a compressor) switches on or off now and then.
            self._appliance = 0.0 if self._appliance else rng.choice((2.5, 4.0, 8.0))
            self._next_switch = now + rng.uniform(4.0, 12.0)
        voltage = 230.0 + 2.0 * math.sin(now / 7.0) + rng.gauss(0.0, 0.3)
        current = max(
            0.0,
            self._base_load + 0.8 * math.sin(now / 11.0) + self._appliance + rng.gauss(0, 0.05),
        )
        power = voltage * current * self.POWER_FACTOR
        self.energy += power * dt / 3_600_000.0
        for address, value in (
            (self.VOLTAGE, voltage),
            (self.CURRENT, current),
            (self.POWER, power),
            (self.ENERGY, self.energy),
        ):
            self.store.set(Table.INPUT_REGISTERS, address, _float32_cdab(value))


def to_tenths(value: float) -> int:
    """`value` in tenths, as an int16 in a 16-bit register (clamped to the int16 range)."""
    tenths = max(-32768, min(32767, round(value * 10)))
    return tenths & 0xFFFF


def from_tenths(register: int) -> float:
    """The value an int16 register of tenths holds."""
    return (register - 0x10000 if register & 0x8000 else register) / 10


class TemperatureController:
    """Unit 2 (by default): a heater controller whose process value follows its setpoint.

    The setpoint (holding register 40001) and the process value (input register 30001)
    are int16 tenths of a degree; the heater output (30002) is in percent. `tau` is the
    time constant of the process in seconds. *on_setpoint* is called with the old and new
    setpoint (degrees) whenever a master writes a new one.
    """

    SETPOINT = 0
    PROCESS_VALUE = 0
    OUTPUT = 1

    def __init__(
        self,
        rng: random.Random,
        unit: int = 2,
        *,
        setpoint: float = 22.0,
        tau: float = 2.0,
        degree: str = "°C",
    ) -> None:
        self.unit = unit
        self.title = "temperature controller"
        self.register_map = (
            "int16 tenths of a degree: setpoint 40001 (writable), process value 30001;"
            " heater output 30002 (%)"
        )
        self.tau = tau
        self.store = MemoryStore(
            holding_registers={self.SETPOINT: [to_tenths(setpoint)]},
            input_registers={self.PROCESS_VALUE: 2},
        )
        self.readings: tuple[Reading, ...] = (
            Reading(
                Point(
                    "controller.setpoint",
                    unit,
                    Table.HOLDING_REGISTERS,
                    self.SETPOINT,
                    ValueType.INT16,
                    scale=0.1,
                ),
                "setpoint",
                degree,
            ),
            Reading(
                Point(
                    "controller.process_value",
                    unit,
                    Table.INPUT_REGISTERS,
                    self.PROCESS_VALUE,
                    ValueType.INT16,
                    scale=0.1,
                ),
                "process value",
                degree,
            ),
            Reading(
                Point("controller.output", unit, Table.INPUT_REGISTERS, self.OUTPUT),
                "heater output",
                "%",
            ),
        )
        self._rng = rng
        self.process_value = setpoint - 0.3
        """The simulated temperature in degrees."""
        self.setpoint_changes: list[tuple[float, float]] = []
        """(old, new) for every setpoint a master wrote, in order."""
        self.store.observe(self._on_change)
        self.step(0.0, 0.0)

    @property
    def setpoint(self) -> float:
        """The setpoint in degrees, as stored."""
        return from_tenths(self.store.get(Table.HOLDING_REGISTERS, self.SETPOINT)[0])

    def _on_change(self, change: Change) -> None:
        # The device learns of a master's write the way an application would: through an
        # observer on its store.
        if change.table is Table.HOLDING_REGISTERS and change.address == self.SETPOINT:
            old, new = from_tenths(change.previous[0]), from_tenths(change.values[0])
            self.setpoint_changes.append((old, new))

    def step(self, now: float, dt: float) -> None:
        """Move the process value towards the setpoint, with a little sensor noise."""
        error = self.setpoint - self.process_value
        if dt > 0:
            self.process_value += error * (1.0 - math.exp(-dt / self.tau))
        measured = self.process_value + self._rng.gauss(0.0, 0.03)
        # A heater only heats: cooling shows as 0 % output.
        output = max(0, min(100, round(12.0 * error + 5.0)))
        self.store.set(Table.INPUT_REGISTERS, self.PROCESS_VALUE, [to_tenths(measured), output])


class DigitalIO:
    """Unit 3 (by default): four output coils and four discrete inputs.

    Coils (00001-00004): pump, fan, valve, lamp. Inputs (10001-10004): pump running and
    fan running (each follows its coil `feedback_delay` seconds later, as a contactor's
    auxiliary contact does), door closed (opens and closes at random) and a heartbeat
    that toggles every second.
    """

    OUTPUTS = ("pump", "fan", "valve", "lamp")
    INPUTS = ("pump running", "fan running", "door closed", "heartbeat")

    def __init__(self, rng: random.Random, unit: int = 3, *, feedback_delay: float = 0.3) -> None:
        self.unit = unit
        self.title = "digital I/O module"
        self.register_map = "coils 00001-00004 (outputs), discrete inputs 10001-10004"
        self.feedback_delay = feedback_delay
        self.store = MemoryStore(
            coils=Block(0, len(self.OUTPUTS), [0, 0, 1, 1]),
            discrete_inputs=Block(0, len(self.INPUTS), [0, 0, 1, 0]),
        )
        self.readings: tuple[Reading, ...] = tuple(
            Reading(Point(f"io.{name}", unit, Table.COILS, index), name)
            for index, name in enumerate(self.OUTPUTS)
        ) + tuple(
            Reading(Point(f"io.{name.replace(' ', '_')}", unit, Table.DISCRETE_INPUTS, index), name)
            for index, name in enumerate(self.INPUTS)
        )
        self._rng = rng
        self._seen = [False, False]
        self._changed_at = [0.0, 0.0]
        self._next_door = rng.uniform(5.0, 15.0)

    def step(self, now: float, dt: float) -> None:
        """Update the inputs from the coils, the door and the clock."""
        store = self.store
        coils = [bool(bit) for bit in store.get(Table.COILS, 0, 2)]
        inputs = [bool(bit) for bit in store.get(Table.DISCRETE_INPUTS, 0, 4)]
        for index, coil in enumerate(coils):
            if coil != self._seen[index]:
                self._seen[index] = coil
                self._changed_at[index] = now
            if now - self._changed_at[index] >= self.feedback_delay:
                inputs[index] = coil
        if now >= self._next_door:
            inputs[2] = not inputs[2]
            # Doors stay closed longer than they stay open.
            self._next_door = now + (self._rng.uniform(8, 20) if inputs[2] else 3.0)
        inputs[3] = int(now) % 2 == 1
        store.set(Table.DISCRETE_INPUTS, 0, [int(bit) for bit in inputs])

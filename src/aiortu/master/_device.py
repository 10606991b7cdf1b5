"""A profile bound to one unit of a master: read points as named, scaled values, write them by
name with the profile's checks.

    profile = aiortu.load_profile("sdm630.toml")
    meter = aiortu.Device(master, 1, profile)
    readings = await meter.read()                  # every point
    voltage = readings["l1_voltage"]
    print(voltage.value, voltage.unit_of_measurement)
    await meter.write("demand_period", 15)

Reads follow the profile's [`ReadPlan`][aiortu.core.model.ReadPlan] (one per poll class); a
merged read the device refuses with exception 02 is split at once and the plan keeps the split.
Everything goes through the master's public methods.
"""

from __future__ import annotations

from collections.abc import Awaitable, Callable, Iterable, Sequence
from dataclasses import dataclass, fields

from aiortu.core.codes import ExceptionCode
from aiortu.core.model import (
    BlockRead,
    Profile,
    ProfilePoint,
    Raw,
    ReadPlan,
    Table,
    Value,
    check_write,
    encode_point,
)
from aiortu.errors import ConnectionLost, ExceptionResponse, ModbusError
from aiortu.master._client import Master

__all__ = ("Device", "Reading")


@dataclass(frozen=True, slots=True)
class Reading:
    """One point's result on unit `unit`: its `value` (scaled, named), its `raw` value as
    read, or the `error` that kept it unread (`value` and `raw` are then None)."""

    unit: int
    point: ProfilePoint
    value: Value
    raw: Raw | None = None
    error: Exception | None = None

    @property
    def name(self) -> str:
        """The point's name."""
        return self.point.name

    @property
    def unit_of_measurement(self) -> str:
        """The point's unit of measurement (`""` when it has none)."""
        return self.point.unit

    @property
    def ok(self) -> bool:
        """Whether the point was read."""
        return self.error is None


ReadBlock = Callable[[BlockRead], Awaitable[Sequence[int | bool]]]

_UNIT, _POINT, _VALUE, _RAW, _ERROR = (Reading.__dict__[f.name].__set__ for f in fields(Reading))


def _reading(
    unit: int, point: ProfilePoint, value: Value, raw: Raw | None, error: Exception | None
) -> Reading:
    """`Reading(unit, point, value, raw, error)` at about half the cost, for every point of
    every poll: a frozen dataclass's `__init__` calls `object.__setattr__` for each field,
    this sets each slot through its own setter (unpacking the five fails at import if a
    field is added)."""
    reading = object.__new__(Reading)
    _UNIT(reading, unit)
    _POINT(reading, point)
    _VALUE(reading, value)
    _RAW(reading, raw)
    _ERROR(reading, error)
    return reading


class Device:
    """`profile` bound to unit `unit` of `master` (see the module docstring).

    `timeout` is the response timeout of its requests (None: the master's).
    """

    def __init__(
        self, master: Master, unit: int, profile: Profile, *, timeout: float | None = None
    ) -> None:
        self.master = master
        self.unit = unit
        self.profile = profile
        self.timeout = timeout
        self._plans: dict[str | None, ReadPlan] = {}
        self._wanted: dict[str | None, tuple[ProfilePoint, ...]] = {}

    def plan(self, poll_class: str | None = None) -> ReadPlan:
        """The read plan of `poll_class` (every point when None), made once and kept."""
        plan = self._plans.get(poll_class)
        if plan is None:
            plan = ReadPlan(self.profile, self.profile.points_of(poll_class))
            self._plans[poll_class] = plan
        return plan

    async def read(self, poll_class: str | None = None) -> dict[str, Reading]:
        """Read every point of `poll_class` (every point when None): a
        [`Reading`][aiortu.master.Reading] per point, by name, in the profile's order.

        A point that could not be read has its error in its reading; only a lost
        connection stops the whole read.
        """
        plan = self.plan(poll_class)
        wanted = self._wanted.get(poll_class)
        if wanted is None:
            wanted = self._wanted[poll_class] = self.profile.points_of(poll_class)
        raws, errors = await read_plan(plan, self._read_block)
        values, unit = plan.values(raws), self.unit
        get_value, get_raw, get_error = values.get, raws.get, errors.get
        return {
            p.name: _reading(unit, p, get_value(p.name), get_raw(p.name), get_error(p.name))
            for p in wanted
        }

    async def read_points(self, names: Iterable[str]) -> dict[str, Reading]:
        """Read the points `names` (their plan made once and kept): a
        [`Reading`][aiortu.master.Reading] each, by name."""
        key = ",".join(names := list(names))
        plan = self._plans.get(f"points:{key}")
        if plan is None:
            chosen = [self.profile.point(name) for name in names]
            plan = self._plans[f"points:{key}"] = ReadPlan(self.profile, chosen)
        raws, errors = await read_plan(plan, self._read_block)
        values = plan.values(raws)
        return {
            n: Reading(self.unit, self.profile.point(n), values.get(n), raws.get(n), errors.get(n))
            for n in names
        }

    async def read_point(self, name: str) -> Value:
        """The value of the point `name`, with its scale factor applied; raises the error that
        kept it unread."""
        reading = (await self.read_points([name]))[name]
        if reading.error is not None:
            raise reading.error
        return reading.value

    async def write(self, name: str, value: object) -> None:
        """Write `value` to the point `name`: checked against its access, kind and limits
        ([`InvalidValue`][aiortu.errors.InvalidValue], naming the point, before anything is
        sent), scaled back to raw (reading its scale factor first), and written with 05, 06 or
        16 as its table and width need."""
        point = self.profile.point(name)
        try:
            checked = check_write(point, value)
        except ModbusError as error:
            error.args = (f"{self.profile.source}: {error}",)
            raise
        sf = None
        if point.scale_factor is not None:
            factor = await self.read_point(point.scale_factor)
            sf = int(factor) if isinstance(factor, int | float) else None
        elements = encode_point(point, checked, sf)
        master, unit, timeout = self.master, self.unit, self.timeout
        if point.table is Table.COILS:
            await master.write_coil(unit, point.address, bool(elements[0]), timeout=timeout)
        elif len(elements) == 1:
            await master.write_register(unit, point.address, elements[0], timeout=timeout)
        else:
            await master.write_registers(unit, point.address, list(elements), timeout=timeout)

    async def _read_block(self, read: BlockRead) -> Sequence[int | bool]:
        master, unit, timeout = self.master, self.unit, self.timeout
        if read.table is Table.HOLDING_REGISTERS:
            return await master.read_holding_registers(
                unit, read.address, read.count, timeout=timeout
            )
        if read.table is Table.INPUT_REGISTERS:
            return await master.read_input_registers(
                unit, read.address, read.count, timeout=timeout
            )
        if read.table is Table.COILS:
            return await master.read_coils(unit, read.address, read.count, timeout=timeout)
        return await master.read_discrete_inputs(unit, read.address, read.count, timeout=timeout)


async def read_plan(
    plan: ReadPlan, read_block: ReadBlock
) -> tuple[dict[str, Raw], dict[str, Exception]]:
    """Run `plan`'s reads through `read_block`: the raw values and the errors, by point name.

    A merged read refused with exception 02 is split
    ([`ReadPlan.refused`][aiortu.core.model.ReadPlan.refused]) and its pieces read at once;
    another exception response is the error of the read's points; a read that got no usable
    answer fails the rest of the plan with it (one dead unit costs one timeout).
    `ConnectionLost` propagates: every other read would fail the same way.
    """
    raws: dict[str, Raw] = {}
    errors: dict[str, Exception] = {}
    pending = list(plan.reads)
    while pending:
        read = pending.pop(0)
        try:
            elements = await read_block(read)
        except ExceptionResponse as error:
            pieces = plan.refused(read) if error.code == ExceptionCode.ILLEGAL_DATA_ADDRESS else ()
            if pieces:
                pending[:0] = pieces
                continue
            errors.update((p.name, error) for p in read.points)
            continue
        except ModbusError as error:
            if isinstance(error, ConnectionLost):
                raise
            # No answer, or a garbled one: the unit's other reads would cost a timeout each.
            for failed in (read, *pending):
                errors.update((p.name, error) for p in failed.points)
            break
        for point, raw in read.decode(elements):
            raws[point.name] = raw
    return raws, errors

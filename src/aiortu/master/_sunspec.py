# ruff: noqa: ASYNC109  (timeout is each request's response timeout, as in the master)
"""The SunSpec model walk: a SunSpec device describes itself, and the walk turns that into a
profile.

    found = await aiortu.walk_sunspec(master, 1)
    if found is not None:
        inverter = aiortu.Device(master, 1, found.profile)
        readings = await inverter.read()           # "m103.W", "m103.PhVphA", ... scaled

The walk looks for the marker "SunS" at 40000, 50000 and 0, then reads each model's id and
length and lays out its points from SunSpec's model definitions
([`SunSpecModels`][aiortu.core.model.SunSpecModels]). A model the definitions do not know is
skipped (by its length) and the walk goes on; each skip is logged and listed in
[`SunSpecDevice.skipped`][aiortu.master.SunSpecDevice].
"""

from __future__ import annotations

from dataclasses import dataclass, replace

from aiortu._log import get_logger
from aiortu.core.model import (
    ADDRESS_RANGE,
    END_ID,
    MARKER,
    MARKER_BASES,
    DeviceInfo,
    PlanLimits,
    PointType,
    Profile,
    ProfilePoint,
    SunSpecModels,
    Table,
    model_points,
)
from aiortu.errors import ExceptionResponse
from aiortu.master._client import Master
from aiortu.master._device import Device

__all__ = ("FoundModel", "SunSpecDevice", "walk_sunspec")

_log = get_logger(__name__)

MAX_MODELS = 256
"""The most models a walk reads before it gives up on finding the end."""


@dataclass(frozen=True, slots=True)
class FoundModel:
    """A model of the device: its `id`, the `address` of its id, and its `length` (L)."""

    id: int
    address: int
    length: int

    def __str__(self) -> str:
        return f"model {self.id} at {self.address} ({self.length} registers)"


@dataclass(frozen=True, slots=True)
class SunSpecDevice:
    """What a walk found: the marker's `base`, the `models` it laid out, those it `skipped`
    (the definitions do not know them), and the `profile` of the device's points."""

    base: int
    models: tuple[FoundModel, ...]
    skipped: tuple[FoundModel, ...]
    profile: Profile

    @property
    def warnings(self) -> tuple[str, ...]:
        """One sentence per skipped model."""
        return tuple(
            f"{m} skipped: the SunSpec model definitions do not know it" for m in self.skipped
        )


async def _marker_base(
    master: Master, unit: int, bases: tuple[int, ...], timeout: float | None
) -> int | None:
    for base in bases:
        try:
            found = await master.read_holding_registers(unit, base, 2, timeout=timeout)
        except ExceptionResponse:
            continue
        if tuple(found) == MARKER:
            return base
    return None


async def walk_sunspec(
    master: Master,
    unit: int,
    *,
    models: SunSpecModels | None = None,
    bases: tuple[int, ...] = MARKER_BASES,
    timeout: float | None = None,
) -> SunSpecDevice | None:
    """Walk the SunSpec models of `unit` (see the module docstring); None when no marker
    answers. `models` defaults to
    [`SunSpecModels.locate()`][aiortu.core.model.SunSpecModels.locate]; `timeout` is the
    response timeout of each request (None: the master's)."""
    models = models or SunSpecModels.locate()
    base = await _marker_base(master, unit, bases, timeout)
    if base is None:
        return None
    points = [ProfilePoint("sunspec.marker", Table.HOLDING_REGISTERS, base, PointType.U32, 2)]
    found: list[FoundModel] = []
    skipped: list[FoundModel] = []
    seen: dict[int, int] = {}
    address = base + 2
    for _ in range(MAX_MODELS):
        if address + 2 > ADDRESS_RANGE.stop:
            break
        model_id, length = await master.read_holding_registers(unit, address, 2, timeout=timeout)
        if model_id == END_ID:
            break
        model = FoundModel(model_id, address, length)
        definition = models.definition(model_id)
        if definition is None:
            skipped.append(model)
            _log.warning(
                "unit %d: %s skipped: the SunSpec model definitions do not know it", unit, model
            )
        else:
            seen[model_id] = seen.get(model_id, 0) + 1
            prefix = f"m{model_id}" + (f"_{seen[model_id]}" if seen[model_id] > 1 else "")
            points += model_points(definition, address, length, prefix)
            found.append(model)
        address += 2 + length
    profile = Profile(
        f"sunspec unit {unit}",
        DeviceInfo("SunSpec", "unknown", f"found by a SunSpec model walk at {base}"),
        tuple(points),
        limits=PlanLimits(max_gap=0),
    )
    profile = await _named(master, unit, profile, timeout)
    return SunSpecDevice(base, tuple(found), tuple(skipped), profile)


async def _named(master: Master, unit: int, profile: Profile, timeout: float | None) -> Profile:
    """`profile` with the manufacturer and model its common model (1) gives, when it has one."""
    names = [p.name for p in profile.points if p.name in ("m1.Mn", "m1.Md")]
    if len(names) < 2:
        return profile
    common = Device(master, unit, profile, timeout=timeout)
    manufacturer = await common.read_point("m1.Mn")
    model = await common.read_point("m1.Md")
    device = DeviceInfo(
        manufacturer if isinstance(manufacturer, str) and manufacturer else "SunSpec",
        model if isinstance(model, str) and model else "unknown",
        profile.device.description,
    )
    return replace(profile, device=device)

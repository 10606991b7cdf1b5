# ruff: noqa: ASYNC109  (timeout is each request's response timeout, as in the master)
"""Which known profile a unit is: its device identification objects (43/14), the register
probes a profile gives, and the SunSpec marker.

    matches = await aiortu.master.match_profiles(master, 7, profiles)
    for match in matches:
        print(match.profile.device.model, "by", ", ".join(match.by))

A profile matches when every condition its `[device.identify]` gives holds; one that gives
none never matches (nothing says it is that device). With SunSpec's model definitions, a unit
that holds the SunSpec marker matches the profile its model walk builds.
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping
from dataclasses import dataclass

from aiortu.core.codes import DeviceIdReadCode
from aiortu.core.model import OBJECT_IDS, Profile, SunSpecModels
from aiortu.errors import ConnectionLost, ModbusError
from aiortu.master._client import Master
from aiortu.master._device import Device
from aiortu.master._sunspec import walk_sunspec

__all__ = ("ProfileMatch", "match_profiles")

_REGULAR = frozenset(OBJECT_IDS[n] for n in ("vendor_url", "product_name", "model_name"))


@dataclass(frozen=True, slots=True)
class ProfileMatch:
    """A profile the unit matches, and `by` what: "device identification", "probes", "SunSpec
    marker"."""

    profile: Profile
    by: tuple[str, ...]


async def _objects(
    master: Master, unit: int, regular: bool, timeout: float | None
) -> dict[int, bytes] | None:
    code = DeviceIdReadCode.REGULAR if regular else DeviceIdReadCode.BASIC
    try:
        return await master.read_device_identification(unit, code, timeout=timeout)
    except ConnectionLost:
        raise
    except ModbusError:
        return None  # no identification: the profiles that ask for it do not match


async def _probes_hold(master: Master, unit: int, profile: Profile, timeout: float | None) -> bool:
    probes = profile.device.identify.probes
    readings = await Device(master, unit, profile, timeout=timeout).read_points(
        p.point for p in probes
    )
    return profile.device.identify.probes_match({n: r.raw for n, r in readings.items() if r.ok})


async def match_profiles(
    master: Master,
    unit: int,
    profiles: Iterable[Profile],
    *,
    sunspec: SunSpecModels | None = None,
    timeout: float | None = None,
) -> list[ProfileMatch]:
    """The profiles among `profiles` that `unit` matches (see the module docstring), and its
    SunSpec walk's when `sunspec` (the definitions) is given and the unit holds the marker."""
    profiles = list(profiles)
    wanted = {OBJECT_IDS[n] for p in profiles for n in p.device.identify.objects}
    objects: Mapping[int, bytes] | None = None
    if wanted:
        objects = await _objects(master, unit, bool(wanted & _REGULAR), timeout)
    matches = []
    for profile in profiles:
        identity = profile.device.identify
        if identity.empty:
            continue
        by = []
        if identity.objects:
            if objects is None or not identity.objects_match(objects):
                continue
            by.append("device identification")
        if identity.probes:
            if not await _probes_hold(master, unit, profile, timeout):
                continue
            by.append("probes")
        matches.append(ProfileMatch(profile, tuple(by)))
    if sunspec is not None:
        found = await walk_sunspec(master, unit, models=sunspec, timeout=timeout)
        if found is not None:
            matches.append(ProfileMatch(found.profile, ("SunSpec marker",)))
    return matches

"""A device profile as records: the device, its limits, its holes and its named points.

[`load_profile`][aiortu.core.model.load_profile] builds these from a TOML file; everything
here is plain data, checked once when built, so the planner and the codecs trust it.
"""

from __future__ import annotations

import enum
from collections.abc import Mapping
from dataclasses import dataclass, field

from aiortu.core.codes import DeviceIdObject
from aiortu.core.errors import InvalidValue
from aiortu.core.model._addressing import Table
from aiortu.core.model._values import Layout

__all__ = (
    "OBJECT_IDS",
    "Access",
    "DeviceInfo",
    "Hole",
    "Identification",
    "PlanLimits",
    "PointType",
    "Probe",
    "Profile",
    "ProfilePoint",
    "Value",
)

Value = bool | int | float | str | tuple[str, ...] | None
"""A point's value: a number or a bool, a text (strings, and enums by name), the names of the
flags set (bitfields), or `None` when the device says it has none."""


OBJECT_IDS: Mapping[str, int] = {
    "vendor_name": DeviceIdObject.VENDOR_NAME,
    "product_code": DeviceIdObject.PRODUCT_CODE,
    "revision": DeviceIdObject.MAJOR_MINOR_REVISION,
    "vendor_url": DeviceIdObject.VENDOR_URL,
    "product_name": DeviceIdObject.PRODUCT_NAME,
    "model_name": DeviceIdObject.MODEL_NAME,
    "user_application_name": DeviceIdObject.USER_APPLICATION_NAME,
}
"""The device identification objects a profile may name, with their object ids."""

_UNREAD = object()


class PointType(enum.StrEnum):
    """How a point's value is held in its table."""

    BOOL = "bool"
    U16 = "u16"
    I16 = "i16"
    U32 = "u32"
    I32 = "i32"
    U64 = "u64"
    I64 = "i64"
    F32 = "f32"
    F64 = "f64"
    STRING = "string"
    BITFIELD = "bitfield"
    ENUM = "enum"

    @property
    def is_integer(self) -> bool:
        """Whether the raw value is an integer (bitfields and enums included)."""
        return self not in (PointType.F32, PointType.F64, PointType.STRING, PointType.BOOL)

    @property
    def is_number(self) -> bool:
        """Whether scale, offset and write limits apply (integers and floats)."""
        return self not in (PointType.STRING, PointType.BOOL, PointType.BITFIELD, PointType.ENUM)


FIXED_WIDTHS: Mapping[PointType, int] = {
    PointType.U16: 1,
    PointType.I16: 1,
    PointType.U32: 2,
    PointType.I32: 2,
    PointType.U64: 4,
    PointType.I64: 4,
    PointType.F32: 2,
    PointType.F64: 4,
}
"""The registers a number of each fixed-width type spans (a profile file gives no size)."""


class Access(enum.StrEnum):
    """Whether a master may write a point: `r` (read-only) or `rw`."""

    R = "r"
    RW = "rw"


@dataclass(frozen=True, slots=True)
class ProfilePoint:
    """One named value of a device: where it sits, how it is held, what it means.

    `address` is the protocol address (0-based) of its first element and `size` the
    elements it spans (1 for a bit). `scale`, `offset` and `scale_factor` (the name of an
    integer point holding a power of ten) turn the raw number into the value: `raw *
    scale * 10**sf + offset`. `minimum` and `maximum` bound writes, in the value's terms.
    """

    name: str
    table: Table
    address: int
    type: PointType
    size: int
    layout: Layout = Layout.ABCD
    encoding: str = "ascii"
    scale: float | None = None
    offset: float | None = None
    scale_factor: str | None = None
    not_available: int | None = None
    unit: str = ""
    description: str = ""
    access: Access = Access.R
    minimum: float | None = None
    maximum: float | None = None
    poll: str = "normal"
    values: Mapping[int, str] = field(default_factory=dict)
    bits: Mapping[int, str] = field(default_factory=dict)
    initial: Value = None
    meta: Mapping[str, object] = field(default_factory=dict)

    @property
    def stop(self) -> int:
        """One past the point's last address."""
        return self.address + self.size

    @property
    def writable(self) -> bool:
        """Whether a master may write the point."""
        return self.access is Access.RW


@dataclass(frozen=True, slots=True)
class Hole:
    """`count` addresses of `table` from `start` (protocol addresses) the device does not map."""

    table: Table
    start: int
    count: int

    @property
    def stop(self) -> int:
        """One past the hole's last address."""
        return self.start + self.count


@dataclass(frozen=True, slots=True)
class Probe:
    """A point read to recognise a device, and the raw values it may have."""

    point: str
    equals: tuple[int | str | bool, ...]


@dataclass(frozen=True, slots=True)
class Identification:
    """How a device is recognised: device identification `objects` (by name, a text each
    must contain, ignoring case) and register `probes`. Empty when the profile says none."""

    objects: Mapping[str, str] = field(default_factory=dict)
    probes: tuple[Probe, ...] = ()

    @property
    def empty(self) -> bool:
        """Whether the profile gives no way to recognise the device."""
        return not self.objects and not self.probes

    def objects_match(self, found: Mapping[int, bytes]) -> bool:
        """Whether the device identification objects `found` (by id) contain each text the
        profile asks for, ignoring case."""
        for name, text in self.objects.items():
            value = found.get(OBJECT_IDS[name])
            if value is None or text.lower() not in value.decode("latin-1").lower():
                return False
        return True

    def probes_match(self, raws: Mapping[str, object]) -> bool:
        """Whether each probe's point read (raw values by point name) one of its values."""
        return all(raws.get(p.point, _UNREAD) in p.equals for p in self.probes)


@dataclass(frozen=True, slots=True)
class DeviceInfo:
    """What the device is: `manufacturer`, `model`, free text, and how to identify it."""

    manufacturer: str
    model: str
    description: str = ""
    url: str = ""
    identify: Identification = field(default_factory=Identification)


@dataclass(frozen=True, slots=True)
class PlanLimits:
    """How reads may be merged: the most elements per read and the most unused ones between
    two points, for registers and for bits."""

    max_block: int = 125
    max_gap: int = 10
    max_bit_block: int = 2000
    max_bit_gap: int = 160

    def for_table(self, table: Table) -> tuple[int, int]:
        """The largest read and the largest gap for `table`."""
        if table.is_bit:
            return self.max_bit_block, self.max_bit_gap
        return self.max_block, self.max_gap


DEFAULT_POLL_CLASS = "normal"
"""The poll class of points that name none, polled every second unless redefined."""


@dataclass(frozen=True, slots=True)
class Profile:
    """A device described as data; see `docs/profiles.md`.

    `source` names where it came from (a file name) for messages; `poll_classes` maps each
    class to its interval in seconds.
    """

    source: str
    device: DeviceInfo
    points: tuple[ProfilePoint, ...]
    holes: tuple[Hole, ...] = ()
    poll_classes: Mapping[str, float] = field(default_factory=lambda: {DEFAULT_POLL_CLASS: 1.0})
    limits: PlanLimits = field(default_factory=PlanLimits)
    _by_name: dict[str, ProfilePoint] = field(init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        object.__setattr__(self, "_by_name", {p.name: p for p in self.points})

    def point(self, name: str) -> ProfilePoint:
        """The point called `name`; [`InvalidValue`][aiortu.errors.InvalidValue] if there is
        none."""
        try:
            return self._by_name[name]
        except KeyError:
            raise InvalidValue(
                "point",
                name,
                "a point of the profile",
                message=f"{self.source}: no point named {name!r}",
            ) from None

    def points_of(self, poll_class: str | None = None) -> tuple[ProfilePoint, ...]:
        """The points of `poll_class`, or every point when None."""
        if poll_class is None:
            return self.points
        if poll_class not in self.poll_classes:
            known = ", ".join(sorted(self.poll_classes))
            raise InvalidValue(
                "poll_class",
                poll_class,
                known,
                message=f"{self.source}: no poll class {poll_class!r} (known: {known})",
            )
        return tuple(p for p in self.points if p.poll == poll_class)

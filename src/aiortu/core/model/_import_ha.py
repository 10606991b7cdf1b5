"""Home Assistant's `modbus:` configuration as profiles: one per unit (`slave`) of each hub.

The converter takes the parsed YAML (a list of hubs, or a mapping with the `modbus:` key),
so this module needs no YAML parser; `aiortu profile import home-assistant FILE` parses the
file first. Converted: `sensors`, `binary_sensors`, `switches` and `climates` with their
addresses, input and write types, data types, swaps, scales, offsets, units, Home Assistant
classes and scan intervals. Anything the profile format cannot say (a `custom` structure, a
`float16`) is an error naming the file, the entity and the key, never silently dropped.
"""

from __future__ import annotations

import re
from collections.abc import Mapping
from dataclasses import dataclass, field, replace
from typing import Any

from aiortu.core.errors import ConfigError
from aiortu.core.model._addressing import Table
from aiortu.core.model._profile import (
    DEFAULT_POLL_CLASS,
    FIXED_WIDTHS,
    Access,
    DeviceInfo,
    PointType,
    Profile,
    ProfilePoint,
)
from aiortu.core.model._profile_dump import dump_profile
from aiortu.core.model._profile_load import parse_profile
from aiortu.core.model._values import Layout

__all__ = ("checked", "profiles_from_home_assistant")

_DATA_TYPES: dict[str, PointType] = {
    "int8": PointType.I16,
    "int16": PointType.I16,
    "int32": PointType.I32,
    "int64": PointType.I64,
    "uint8": PointType.U16,
    "uint16": PointType.U16,
    "uint32": PointType.U32,
    "uint64": PointType.U64,
    "float32": PointType.F32,
    "float64": PointType.F64,
    "string": PointType.STRING,
}
_SWAPS = {"none": Layout.ABCD, "byte": Layout.BADC, "word": Layout.CDAB, "word_byte": Layout.DCBA}
_REGISTER_TABLES = {"holding": Table.HOLDING_REGISTERS, "input": Table.INPUT_REGISTERS}
_BIT_TABLES = {"coil": Table.COILS, "discrete_input": Table.DISCRETE_INPUTS} | _REGISTER_TABLES
_WRITE_TABLES = {
    "holding": Table.HOLDING_REGISTERS,
    "holdings": Table.HOLDING_REGISTERS,
    "coil": Table.COILS,
    "coils": Table.COILS,
}
_HVAC_MODES = ("off", "heat", "cool", "auto", "dry", "fan_only", "heat_cool")
_DEFAULT_SCAN = 15.0  # Home Assistant's default scan_interval, seconds
_META_KEYS = ("device_class", "state_class", "precision", "unique_id")


def checked(profile: Profile) -> Profile:
    """`profile`, held to every rule of a profile file (points that overlap, limits, ...): an
    import gives what `aiortu profile check` would pass, or says why not."""
    return parse_profile(dump_profile(profile), profile.source)


def _slug(name: str) -> str:
    slug = re.sub(r"[^A-Za-z0-9]+", "_", name.strip()).strip("_").lower()
    return slug if slug and not slug[0].isdigit() else f"p_{slug}"


@dataclass
class _Hub:
    """The profiles of one hub being built, by unit."""

    source: str
    name: str
    points: dict[int, list[ProfilePoint]] = field(default_factory=dict)
    classes: dict[str, float] = field(default_factory=lambda: {DEFAULT_POLL_CLASS: 1.0})

    def add(self, unit: int, point: ProfilePoint) -> None:
        taken = {p.name for p in self.points.setdefault(unit, [])}
        name, n = point.name, 2
        while name in taken:
            name, n = f"{point.name}_{n}", n + 1
        self.points[unit].append(replace(point, name=name) if name != point.name else point)

    def poll_class(self, seconds: float) -> str:
        name = f"every_{seconds:g}s".replace(".", "_")
        self.classes[name] = seconds
        return name


class _Entity:
    """One entity of a platform, read with errors naming the file, the entity and the key."""

    def __init__(self, hub: _Hub, platform: str, index: int, entry: object) -> None:
        self.hub = hub
        if not isinstance(entry, Mapping):
            raise ConfigError(hub.source, f"{hub.name}.{platform}[{index}]", "must be a mapping")
        self.entry: Mapping[str, Any] = entry
        name = entry.get("name")
        self.label = str(name) if name is not None else f"{platform}[{index}]"
        self.key = f"{hub.name}.{platform}[{index}] ({self.label})"

    def fail(self, key: str, problem: str) -> ConfigError:
        return ConfigError(self.hub.source, f"{self.key}.{key}", problem)

    def integer(
        self, key: str, default: int | None = None, entry: Mapping[str, Any] | None = None
    ) -> int:
        value = (entry or self.entry).get(key, default)
        if value is None:
            raise self.fail(key, "missing")
        if isinstance(value, bool) or not isinstance(value, int) or not 0 <= value <= 0xFFFF:
            raise self.fail(key, f"must be an integer 0..65535, not {value!r}")
        return value

    def number(self, key: str) -> float | None:
        value = self.entry.get(key)
        if value is None:
            return None
        if isinstance(value, bool) or not isinstance(value, int | float):
            raise self.fail(key, f"must be a number, not {value!r}")
        return float(value)

    def choice(self, key: str, choices: Mapping[str, Any], default: str) -> Any:
        value = self.entry.get(key, default)
        if value not in choices:
            raise self.fail(key, f"must be one of {', '.join(choices)}, not {value!r}")
        return choices[value]

    def unit(self) -> int:
        value = self.entry.get("slave", self.entry.get("device_address", 1))
        if isinstance(value, bool) or not isinstance(value, int) or not 0 <= value <= 255:
            raise self.fail("slave", f"must be a unit address 0..255, not {value!r}")
        return value

    def poll(self) -> str:
        seconds = self.entry.get("scan_interval", _DEFAULT_SCAN)
        if isinstance(seconds, bool) or not isinstance(seconds, int | float) or seconds <= 0:
            raise self.fail("scan_interval", f"must be seconds > 0, not {seconds!r}")
        return self.hub.poll_class(float(seconds))

    def meta(self) -> dict[str, object]:
        meta: dict[str, object] = {"name": self.label}
        meta |= {k: self.entry[k] for k in _META_KEYS if k in self.entry}
        return meta

    def value_type(self, default: str = "int16") -> tuple[PointType, int, Layout]:
        data_type = self.entry.get("data_type", default)
        if data_type not in _DATA_TYPES:
            known = ", ".join(_DATA_TYPES)
            raise self.fail("data_type", f"{data_type!r} has no profile type (known: {known})")
        kind = _DATA_TYPES[data_type]
        size = self.integer("count") if kind is PointType.STRING else FIXED_WIDTHS[kind]
        layout = self.choice("swap", _SWAPS, "none")
        return kind, size, layout

    def register_point(self, name: str, table: Table, address: int, **extra: Any) -> ProfilePoint:
        kind, size, layout = self.value_type()
        numeric = kind.is_number
        return ProfilePoint(
            name,
            table,
            address,
            kind,
            size,
            layout=layout,
            scale=self.number("scale") if numeric else None,
            offset=self.number("offset") if numeric else None,
            unit=str(self.entry.get("unit_of_measurement", "")),
            poll=self.poll(),
            meta=self.meta(),
            **extra,
        )


def _sensor(entity: _Entity) -> None:
    table = entity.choice("input_type", _REGISTER_TABLES, "holding")
    point = entity.register_point(_slug(entity.label), table, entity.integer("address"))
    count = entity.integer("slave_count", 0) or entity.integer("virtual_count", 0)
    entity.hub.add(entity.unit(), point)
    for n in range(1, count + 1):
        extra = replace(point, name=f"{point.name}_{n}", address=point.address + n * point.size)
        entity.hub.add(entity.unit(), extra)


def _binary_sensor(entity: _Entity) -> None:
    table = entity.choice("input_type", _BIT_TABLES, "coil")
    address = entity.integer("address")
    count = entity.integer("slave_count", 0) or entity.integer("virtual_count", 0)
    for n in range(count + 1):
        name = _slug(entity.label) + (f"_{n}" if n else "")
        point = ProfilePoint(
            name, table, address + n, PointType.BOOL, 1, poll=entity.poll(), meta=entity.meta()
        )
        entity.hub.add(entity.unit(), point)


def _switch(entity: _Entity) -> None:
    table = entity.choice("write_type", _WRITE_TABLES, "holding")
    address = entity.integer("address")
    name = _slug(entity.label)
    if table.is_bit:
        point = ProfilePoint(
            name,
            table,
            address,
            PointType.BOOL,
            1,
            access=Access.RW,
            poll=entity.poll(),
            meta=entity.meta(),
        )
    else:
        on, off = entity.integer("command_on", 1), entity.integer("command_off", 0)
        point = ProfilePoint(
            name,
            table,
            address,
            PointType.ENUM,
            1,
            access=Access.RW,
            values={off: "off", on: "on"},
            poll=entity.poll(),
            meta=entity.meta(),
        )
    entity.hub.add(entity.unit(), point)
    verify = entity.entry.get("verify")
    if isinstance(verify, Mapping) and verify.get("address", address) != address:
        _switch_state(entity, name, verify, point)


def _switch_state(
    entity: _Entity, name: str, verify: Mapping[str, Any], switch: ProfilePoint
) -> None:
    """The point `verify` reads back: a bit, or a register whose `state_on` and `state_off`
    (the commands unless given) name it on or off."""
    table = _BIT_TABLES.get(verify.get("input_type", "holding"))
    if table is None:
        raise entity.fail("verify.input_type", f"must be one of {', '.join(_BIT_TABLES)}")
    address = entity.integer("address", entry=verify)
    if table.is_bit:
        state = ProfilePoint(
            f"{name}_state",
            table,
            address,
            PointType.BOOL,
            1,
            poll=entity.poll(),
            meta=entity.meta(),
        )
    else:
        commands = {label: raw for raw, label in switch.values.items()} or {"on": 1, "off": 0}
        on = entity.integer("state_on", commands["on"], entry=verify)
        off = entity.integer("state_off", commands["off"], entry=verify)
        state = ProfilePoint(
            f"{name}_state",
            table,
            address,
            PointType.ENUM,
            1,
            values={off: "off", on: "on"},
            poll=entity.poll(),
            meta=entity.meta(),
        )
    entity.hub.add(entity.unit(), state)


def _climate(entity: _Entity) -> None:
    name = _slug(entity.label)
    table = entity.choice("input_type", _REGISTER_TABLES, "holding")
    unit = "°" + str(entity.entry.get("temperature_unit", "C"))
    current = entity.register_point(f"{name}_current_temperature", table, entity.integer("address"))
    entity.hub.add(entity.unit(), _with_unit(current, unit))
    target_address = entity.entry.get("target_temp_register")
    if isinstance(target_address, list):
        target_address = target_address[0] if target_address else None
    target = entity.register_point(
        f"{name}_target_temperature",
        Table.HOLDING_REGISTERS,
        entity.integer("target_temp_register", target_address),
        access=Access.RW,
        minimum=entity.number("min_temp"),
        maximum=entity.number("max_temp"),
    )
    entity.hub.add(entity.unit(), _with_unit(target, unit))
    mode = entity.entry.get("hvac_mode_register")
    if isinstance(mode, Mapping):
        values = mode.get("values", {})
        named = {}
        for key, raw in values.items():
            mode_name = str(key).removeprefix("state_")
            numbers = raw if isinstance(raw, list) else [raw]
            for number in numbers:
                if isinstance(number, int) and not isinstance(number, bool):
                    named[number] = mode_name
        point = ProfilePoint(
            f"{name}_hvac_mode",
            Table.HOLDING_REGISTERS,
            entity.integer("address", entry=mode),
            PointType.ENUM,
            1,
            access=Access.RW if mode.get("write_registers", True) else Access.R,
            values=named,
            poll=entity.poll(),
            meta=entity.meta(),
        )
        entity.hub.add(entity.unit(), point)
    onoff = entity.entry.get("hvac_onoff_register")
    if isinstance(onoff, int) and not isinstance(onoff, bool):
        point = ProfilePoint(
            f"{name}_on",
            Table.HOLDING_REGISTERS,
            onoff,
            PointType.U16,
            1,
            access=Access.RW,
            poll=entity.poll(),
            meta=entity.meta(),
        )
        entity.hub.add(entity.unit(), point)


def _with_unit(point: ProfilePoint, unit: str) -> ProfilePoint:
    return point if point.unit else replace(point, unit=unit)


_PLATFORMS = {
    "sensors": _sensor,
    "binary_sensors": _binary_sensor,
    "switches": _switch,
    "climates": _climate,
}


def profiles_from_home_assistant(
    document: object, source: str = "configuration.yaml"
) -> dict[tuple[str, int], Profile]:
    """The profiles of a Home Assistant `modbus:` section (the parsed YAML), by hub name and
    unit; [`ConfigError`][aiortu.errors.ConfigError] naming the file, the entity and the key
    for anything the profile format cannot hold."""
    hubs = document.get("modbus", document) if isinstance(document, Mapping) else document
    if isinstance(hubs, Mapping):
        hubs = [hubs]
    if not isinstance(hubs, list):
        raise ConfigError(source, "modbus", "must be a list of hubs")
    profiles: dict[tuple[str, int], Profile] = {}
    for index, entry in enumerate(hubs):
        if not isinstance(entry, Mapping):
            raise ConfigError(source, f"modbus[{index}]", "must be a mapping")
        hub = _Hub(source, str(entry.get("name", f"modbus[{index}]")))
        for platform, convert in _PLATFORMS.items():
            entities = entry.get(platform, [])
            if not isinstance(entities, list):
                raise ConfigError(source, f"{hub.name}.{platform}", "must be a list")
            for position, item in enumerate(entities):
                convert(_Entity(hub, platform, position, item))
        for unit, points in hub.points.items():
            device = DeviceInfo(
                "Home Assistant", f"{hub.name} unit {unit}", f"imported from {source}"
            )
            used = {p.poll for p in points} | {DEFAULT_POLL_CLASS}
            classes = {k: v for k, v in hub.classes.items() if k in used}
            profiles[(hub.name, unit)] = checked(
                Profile(
                    f"{source} ({hub.name}, unit {unit})",
                    device,
                    tuple(points),
                    poll_classes=classes,
                )
            )
    return profiles

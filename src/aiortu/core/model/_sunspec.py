"""SunSpec, sans-IO: the model definitions, and the points of a model found at an address.

A SunSpec device holds the marker `SunS` at holding register 40000, 50000 or 0, then its
models one after the other, each an id and a length `L` followed by `L` registers, ending with
id 0xFFFF. What each model holds comes from SunSpec's model definitions, the JSON files
pysunspec2 ships (Apache 2.0): [`SunSpecModels`][aiortu.core.model.SunSpecModels] reads them
from an installed pysunspec2 (`pip install aiortu[sunspec]`) or from a directory, at run time,
so new SunSpec models arrive with pysunspec2 releases and no hand copy goes stale.

[`model_points`][aiortu.core.model.model_points] turns a definition into profile points named
`m<id>.<point>` (repeated groups `m<id>.<group>.<n>.<point>`), with SunSpec's types, units,
scale factors (`sunssf`, looked up in the point's group and the groups around it), enums,
bitfields, access and "not implemented" values.
"""

from __future__ import annotations

import importlib.util
import json
import os
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

from aiortu.core.errors import ConfigError
from aiortu.core.model._addressing import Table
from aiortu.core.model._profile import (
    Access,
    DeviceInfo,
    PlanLimits,
    PointType,
    Profile,
    ProfilePoint,
    Value,
)

__all__ = (
    "END_ID",
    "MARKER",
    "MARKER_BASES",
    "SunSpecModels",
    "model_length",
    "model_points",
    "sunspec_layout",
)

MARKER = (0x5375, 0x6E53)
"""The registers of the marker "SunS"."""

MARKER_BASES = (40000, 50000, 0)
"""Where a SunSpec device may hold its marker, in the order they are tried."""

END_ID = 0xFFFF
"""The model id that ends the list of models."""

# SunSpec type: (point type, registers, the raw value meaning "not implemented").
_TYPES: dict[str, tuple[PointType, int, int | None]] = {
    "uint16": (PointType.U16, 1, 0xFFFF),
    "int16": (PointType.I16, 1, -0x8000),
    "sunssf": (PointType.I16, 1, -0x8000),
    "count": (PointType.U16, 1, None),
    "acc16": (PointType.U16, 1, 0),
    "enum16": (PointType.ENUM, 1, 0xFFFF),
    "bitfield16": (PointType.BITFIELD, 1, 0xFFFF),
    "uint32": (PointType.U32, 2, 0xFFFFFFFF),
    "int32": (PointType.I32, 2, -0x80000000),
    "acc32": (PointType.U32, 2, 0),
    "enum32": (PointType.ENUM, 2, 0xFFFFFFFF),
    "bitfield32": (PointType.BITFIELD, 2, 0xFFFFFFFF),
    "ipaddr": (PointType.U32, 2, 0),
    "uint64": (PointType.U64, 4, 0xFFFFFFFFFFFFFFFF),
    "int64": (PointType.I64, 4, -0x8000000000000000),
    "acc64": (PointType.U64, 4, 0),
    "float32": (PointType.F32, 2, None),
    "float64": (PointType.F64, 4, None),
}
_TEXT_TYPES = ("string", "ipv6addr", "eui48")


def _pysunspec2_models() -> Path | None:
    """The model definitions of an installed pysunspec2, without importing its code."""
    try:
        spec = importlib.util.find_spec("sunspec2")
    except (ImportError, ValueError):
        return None
    if spec is None or not spec.submodule_search_locations:
        return None
    for location in spec.submodule_search_locations:
        candidate = Path(location) / "models" / "json"
        if candidate.is_dir():
            return candidate
    return None


@dataclass
class SunSpecModels:
    """SunSpec's model definitions, read from `directory` (JSON files `model_<id>.json`)."""

    directory: Path
    _cache: dict[int, dict[str, Any] | None] = field(default_factory=dict, repr=False)

    @classmethod
    def locate(cls, directory: str | Path | None = None) -> SunSpecModels:
        """The definitions in `directory`, else in `$AIORTU_SUNSPEC_MODELS`, else those of an
        installed pysunspec2; [`ConfigError`][aiortu.errors.ConfigError] when there are none."""
        given = directory or os.environ.get("AIORTU_SUNSPEC_MODELS")
        found = Path(given) if given else _pysunspec2_models()
        if found is None or not (found / "model_1.json").is_file():
            where = str(found) if found is not None else "no directory given"
            raise ConfigError(
                "SunSpec model definitions",
                "models_dir",
                f"not found ({where}): install pysunspec2 (pip install 'aiortu[sunspec]'), "
                "or give the directory of SunSpec's model_<id>.json files",
            )
        return cls(found)

    def definition(self, model_id: int) -> dict[str, Any] | None:
        """The definition of model `model_id`, or None when the definitions do not know it."""
        if model_id not in self._cache:
            path = self.directory / f"model_{model_id}.json"
            try:
                document = json.loads(path.read_text(encoding="utf-8"))
            except (OSError, ValueError):
                document = None
            self._cache[model_id] = document if isinstance(document, dict) else None
        return self._cache[model_id]


def _group_size(group: Mapping[str, Any], repeats: Mapping[str, int]) -> int:
    size = sum(int(p["size"]) for p in group.get("points", ()))
    for sub in group.get("groups", ()):
        size += _group_size(sub, repeats) * repeats.get(sub["name"], _fixed_count(sub))
    return size


def _fixed_count(group: Mapping[str, Any]) -> int:
    count = group.get("count", 1)
    return count if isinstance(count, int) and count > 0 else 0


def _repeats(group: Mapping[str, Any], registers: int) -> dict[str, int]:
    """How many times each repeating subgroup of the model's `group` appears in its
    `registers` (2 + L): the one with no fixed count fills what the others leave."""
    repeats: dict[str, int] = {}
    fixed = _group_size(group, repeats)
    for sub in group.get("groups", ()):
        if _fixed_count(sub) == 0:
            size = _group_size(sub, {})
            repeats[sub["name"]] = max(0, registers - fixed) // size if size else 0
    return repeats


def model_length(definition: Mapping[str, Any], repeats: int = 0) -> int:
    """The `L` of a model with `repeats` instances of its repeating group."""
    group = definition["group"]
    counts = {s["name"]: repeats for s in group.get("groups", ()) if _fixed_count(s) == 0}
    return _group_size(group, counts) - 2


@dataclass
class _Walker:
    """Lays a model's groups out from an address, naming and typing their points."""

    model_id: int
    address: int
    prefix: str
    repeats: Mapping[str, int]
    points: list[ProfilePoint] = field(default_factory=list)

    def group(
        self, group: Mapping[str, Any], name: str, scopes: tuple[dict[str, str], ...]
    ) -> None:
        own = {p["name"]: f"{name}.{p['name']}" for p in group.get("points", ())}
        scopes = (own, *scopes)
        for spec in group.get("points", ()):
            self.point(spec, own[spec["name"]], scopes)
        for sub in group.get("groups", ()):
            count = self.repeats.get(sub["name"], _fixed_count(sub))
            if count == 1 and _fixed_count(sub) == 1:
                self.group(sub, f"{name}.{sub['name']}", scopes)
                continue
            for index in range(1, count + 1):
                self.group(sub, f"{name}.{sub['name']}.{index}", scopes)

    def point(self, spec: Mapping[str, Any], name: str, scopes: tuple[dict[str, str], ...]) -> None:
        size = int(spec["size"])
        kind_name = spec["type"]
        start, self.address = self.address, self.address + size
        if kind_name == "pad" or (kind_name not in _TYPES and kind_name not in _TEXT_TYPES):
            return
        kind, width, missing = _TYPES.get(kind_name, (PointType.STRING, size, 0))
        if width != size:
            return  # a definition at odds with its type: not guessed at
        symbols = {int(s["value"]): str(s["name"]) for s in spec.get("symbols", ())}
        sf = spec.get("sf")
        self.points.append(
            ProfilePoint(
                name,
                Table.HOLDING_REGISTERS,
                start,
                kind,
                size,
                scale=10.0**sf if isinstance(sf, int) else None,
                scale_factor=_scope_lookup(scopes, sf) if isinstance(sf, str) else None,
                not_available=missing,
                unit=str(spec.get("units", "")),
                description=str(spec.get("label", "")),
                access=Access.RW if spec.get("access") == "RW" else Access.R,
                values=symbols if kind is PointType.ENUM else {},
                bits=symbols if kind is PointType.BITFIELD else {},
                meta={"sunspec_model": self.model_id, "sunspec_type": kind_name},
            )
        )


def _scope_lookup(scopes: Sequence[Mapping[str, str]], name: str) -> str | None:
    for scope in scopes:
        if name in scope:
            return scope[name]
    return None


def model_points(
    definition: Mapping[str, Any], address: int, length: int, prefix: str
) -> list[ProfilePoint]:
    """The points of a model whose id sits at `address` and whose `L` is `length`, named
    `prefix.<point>`; repeating groups fill what `length` leaves after the fixed part."""
    group = definition["group"]
    walker = _Walker(int(definition["id"]), address, prefix, _repeats(group, length + 2))
    walker.group(group, prefix, ())
    end = address + 2 + length
    return [p for p in walker.points if p.stop <= end]


def sunspec_layout(
    models: SunSpecModels,
    model_ids: Sequence[int],
    *,
    base: int = 40000,
    repeats: int = 1,
    values: Mapping[str, Value] | None = None,
    manufacturer: str = "aiortu",
    model: str = "SunSpec device",
) -> Profile:
    """A profile laying `model_ids` out as a SunSpec device would from `base`: the marker,
    each model (its repeating groups `repeats` times) with its id and length set, the end
    model; `values` sets points by name (scale factors default to 0). Serve it with
    [`ProfileStore`][aiortu.slave.ProfileStore] to simulate a SunSpec device."""
    points = [
        ProfilePoint(
            "sunspec.marker",
            Table.HOLDING_REGISTERS,
            base,
            PointType.U32,
            2,
            initial=MARKER[0] << 16 | MARKER[1],
        )
    ]
    address = base + 2
    given = dict(values or {})
    seen: dict[int, int] = {}
    for model_id in model_ids:
        definition = models.definition(model_id)
        if definition is None:
            raise ConfigError("SunSpec model definitions", f"model {model_id}", "unknown model")
        seen[model_id] = seen.get(model_id, 0) + 1
        prefix = f"m{model_id}" + (f"_{seen[model_id]}" if seen[model_id] > 1 else "")
        length = model_length(definition, repeats)
        given.setdefault(f"{prefix}.ID", model_id)
        given.setdefault(f"{prefix}.L", length)
        points += model_points(definition, address, length, prefix)
        address += 2 + length
    points.append(ProfilePoint("sunspec.end", Table.HOLDING_REGISTERS, address, PointType.U16, 1))
    points.append(
        ProfilePoint("sunspec.end_length", Table.HOLDING_REGISTERS, address + 1, PointType.U16, 1)
    )
    given.setdefault("sunspec.end", END_ID)
    placed = [_with_initial(p, given, repeats) for p in points]
    return Profile(
        f"sunspec:{','.join(map(str, model_ids))}",
        DeviceInfo(manufacturer, model, "a SunSpec device laid out from the model definitions"),
        tuple(placed),
        limits=PlanLimits(max_gap=0),
    )


def _with_initial(point: ProfilePoint, values: Mapping[str, Value], repeats: int) -> ProfilePoint:
    if point.name in values:
        return replace(point, initial=values[point.name])
    if point.meta.get("sunspec_type") == "sunssf":
        return replace(point, initial=0)
    if point.meta.get("sunspec_type") == "count":
        return replace(point, initial=repeats)
    return point

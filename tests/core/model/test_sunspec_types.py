"""SunSpec point types as profile points: their type, their size and their "not implemented"
value (SunSpec's: the lowest value of a signed type, the highest of an unsigned one, 0 for an
accumulator or an address); and a device laid out from model definitions (two small ones
written here: pysunspec2's are in the interop tests)."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import pytest

from aiortu.core.model import PointType, SunSpecModels, model_points, sunspec_layout
from aiortu.errors import ConfigError

TYPES: dict[str, tuple[PointType, int, int | None]] = {
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
    "string": (PointType.STRING, 8, 0),
}


def test_every_sunspec_type_becomes_a_point_of_its_size_with_its_not_implemented_value() -> None:
    header = [
        {"name": "ID", "type": "uint16", "size": 1},
        {"name": "L", "type": "uint16", "size": 1},
    ]
    body = [{"name": name, "type": name, "size": size} for name, (_, size, _) in TYPES.items()]
    definition: dict[str, Any] = {"id": 64999, "group": {"name": "m", "points": header + body}}
    length = sum(size for _, size, _ in TYPES.values())
    points = model_points(definition, 40002, length, "m")
    assert [p.name for p in points] == ["m.ID", "m.L", *(f"m.{name}" for name in TYPES)]
    address = 40004
    for point, (name, (kind, size, missing)) in zip(points[2:], TYPES.items(), strict=True):
        assert (point.type, point.size, point.not_available) == (kind, size, missing), name
        assert point.address == address, name
        address += size


COMMON = {
    "id": 1,
    "group": {
        "name": "common",
        "points": [
            {"name": "ID", "type": "uint16", "size": 1},
            {"name": "L", "type": "uint16", "size": 1},
            {"name": "Mn", "type": "string", "size": 16},
        ],
    },
}
STRINGS = {
    "id": 64999,
    "group": {
        "name": "strings",
        "points": [
            {"name": "ID", "type": "uint16", "size": 1},
            {"name": "L", "type": "uint16", "size": 1},
            {"name": "N", "type": "count", "size": 1},
            {"name": "A_SF", "type": "sunssf", "size": 1},
        ],
        "groups": [
            {
                "name": "module",
                "count": "N",
                "points": [{"name": "A", "type": "uint16", "size": 1, "sf": "A_SF"}],
            }
        ],
    },
}


def _models(tmp_path: Path) -> SunSpecModels:
    for definition in (COMMON, STRINGS):
        (tmp_path / f"model_{definition['id']}.json").write_text(json.dumps(definition))
    return SunSpecModels.locate(tmp_path)


def test_a_layout_repeats_groups_and_sets_ids_lengths_counts_and_values(tmp_path: Path) -> None:
    models = _models(tmp_path)
    profile = sunspec_layout(models, [1, 64999], repeats=2, values={"m64999.module.2.A": 7})
    initial = {point.name: point.initial for point in profile.points}
    assert initial["m1.ID"] == 1
    assert initial["m1.L"] == 16
    assert initial["m64999.ID"] == 64999
    assert initial["m64999.L"] == 4  # N, A_SF and two modules
    assert initial["m64999.N"] == 2  # a count is the repeats laid out
    assert initial["m64999.A_SF"] == 0  # scale factors default to 0
    assert initial["m64999.module.1.A"] is None
    assert initial["m64999.module.2.A"] == 7
    assert profile.point("m64999.module.2.A").address == 40000 + 2 + 18 + 5
    assert initial["sunspec.end"] == 0xFFFF


def test_a_layout_of_a_model_the_definitions_do_not_know_is_refused(tmp_path: Path) -> None:
    with pytest.raises(ConfigError, match="model 12345: unknown model"):
        sunspec_layout(_models(tmp_path), [1, 12345])

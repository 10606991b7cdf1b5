"""SunSpec point types as profile points: their type, their size and their "not implemented"
value (SunSpec's: the lowest value of a signed type, the highest of an unsigned one, 0 for an
accumulator or an address)."""

from __future__ import annotations

from typing import Any

from aiortu.core.model import PointType, model_points

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

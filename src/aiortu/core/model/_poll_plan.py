"""Poll planning, sans-IO: which read requests cover a set of points, and how to slice
the replies back into typed values.

A [`Point`][aiortu.core.model.Point] is one value a poller reads: a name, a unit, a table, a
protocol address, and for register tables a [`ValueType`][aiortu.core.model.ValueType] in a
[`Layout`][aiortu.core.model.Layout], with an optional scale.
[`plan_reads`][aiortu.core.model.plan_reads] groups the points by unit and table, sorts them by
address and merges neighbours into one read when the unused elements between them are at most
`max_gap` (`max_bit_gap` for coils and discrete inputs) and the merged read stays within the spec's
limits (125 registers, 2000 bits) or smaller ones the caller gives. Each
[`PlannedRead`][aiortu.core.model.PlannedRead] knows which slice of its reply belongs to which
point; [`PlannedRead.decode`][aiortu.core.model.PlannedRead.decode] turns a reply into values,
and [`PlannedRead.split`][aiortu.core.model.PlannedRead.split] gives the reads of its points
alone, for a device that refuses a merged block across a hole in its map.

    >>> points = [Point.of("a", 1, "40001"), Point.of("b", 1, "40003", "float32")]
    >>> [(r.address, r.count) for r in plan_reads(points, max_gap=2)]
    [(0, 4)]

Nothing here does I/O or reads a clock.
"""

from __future__ import annotations

from collections.abc import Iterable, Sequence
from dataclasses import dataclass, field

from aiortu.core.codes import UNIT_ADDRESSES
from aiortu.core.errors import InvalidValue
from aiortu.core.model._addressing import ADDRESS_RANGE, Table, parse_reference
from aiortu.core.model._values import Layout, ValueType, decode_value

__all__ = (
    "MAX_READ_BITS",
    "MAX_READ_REGISTERS",
    "PlannedRead",
    "Point",
    "PointSlice",
    "plan_reads",
)

MAX_READ_REGISTERS = 125
"""The most registers one read (03, 04) may ask for."""

MAX_READ_BITS = 2000
"""The most bits one read (01, 02) may ask for."""


def _value_type(kind: ValueType | str) -> ValueType:
    try:
        return ValueType(str(kind).lower())
    except ValueError:
        raise InvalidValue("type", kind, ", ".join(ValueType)) from None


def _layout(layout: Layout | str) -> Layout:
    try:
        return Layout(str(layout).upper())
    except ValueError:
        raise InvalidValue("layout", layout, ", ".join(Layout)) from None


@dataclass(frozen=True, slots=True)
class Point:
    """One value to poll: `name`, `unit` (1..247), `table`, protocol `address`.

    For register tables `type` (a [`ValueType`][aiortu.core.model.ValueType] or its name,
    default `uint16`) and `layout` say how the value sits in its registers; `scale`,
    when given, multiplies the decoded number (a raw 215 with scale 0.1 reads 21.5). For
    coils and discrete inputs the value is a `bool` and `type`, `layout` and `scale`
    are ignored. `interval` overrides the poller's interval for this point (seconds).

    Raises [`InvalidValue`][aiortu.errors.InvalidValue] for a unit, address, type or layout out
    of range, or a value that would run past address 65535.
    """

    name: str
    unit: int
    table: Table
    address: int
    type: ValueType = ValueType.UINT16
    layout: Layout = Layout.ABCD
    scale: float | None = None
    interval: float | None = None

    def __post_init__(self) -> None:
        try:
            object.__setattr__(self, "table", Table(self.table))
        except ValueError:
            raise InvalidValue("table", self.table, ", ".join(Table)) from None
        object.__setattr__(self, "type", _value_type(self.type))
        object.__setattr__(self, "layout", _layout(self.layout))
        if isinstance(self.unit, bool) or not isinstance(self.unit, int):
            raise InvalidValue("unit", self.unit, UNIT_ADDRESSES)
        if self.unit not in UNIT_ADDRESSES:
            raise InvalidValue("unit", self.unit, UNIT_ADDRESSES)
        if isinstance(self.address, bool) or not isinstance(self.address, int):
            raise InvalidValue("address", self.address, ADDRESS_RANGE)
        last = range(ADDRESS_RANGE.stop - self.width + 1)
        if self.address not in last:
            raise InvalidValue("address", self.address, last, f"{self.name}: {self.width} wide")
        if self.interval is not None and not self.interval > 0:
            raise InvalidValue("interval", self.interval, "seconds > 0")

    @classmethod
    def of(
        cls,
        name: str,
        unit: int,
        reference: str,
        type: ValueType | str = ValueType.UINT16,
        *,
        layout: Layout | str = Layout.ABCD,
        scale: float | None = None,
        interval: float | None = None,
    ) -> Point:
        """A point from a 5- or 6-digit reference such as `"40108"` (holding register 107)."""
        ref = parse_reference(reference)
        return cls(
            name,
            unit,
            ref.table,
            ref.address,
            _value_type(type),
            _layout(layout),
            scale,
            interval,
        )

    @property
    def width(self) -> int:
        """How many elements of its table the point spans: 1 for bits, 1, 2 or 4 registers."""
        return 1 if self.table.is_bit else self.type.register_count

    def decode(self, elements: Sequence[int | bool]) -> bool | int | float:
        """The point's value from its `elements` (exactly
        [`width`][aiortu.core.model.Point.width] of them)."""
        if self.table.is_bit:
            return bool(elements[0])
        value = decode_value([int(e) for e in elements], self.type, self.layout)
        return value * self.scale if self.scale is not None else value


@dataclass(frozen=True, slots=True)
class PointSlice:
    """Where a point's elements sit in a read's reply: `offset` from its start, `width` long."""

    point: Point
    offset: int
    width: int


@dataclass(frozen=True, slots=True)
class PlannedRead:
    """One read request: `count` elements of `table` from `address` on `unit`, and the
    [`PointSlice`][aiortu.core.model.PointSlice]s it serves, in address order."""

    unit: int
    table: Table
    address: int
    count: int
    slices: tuple[PointSlice, ...] = field(default=())

    @property
    def points(self) -> tuple[Point, ...]:
        """The points this read serves."""
        return tuple(s.point for s in self.slices)

    def split(self) -> list[PlannedRead]:
        """This read as one read per address the points start at (points at the same
        address share one, as wide as the widest), in address order: what to read instead
        when the device refuses the merged block because of a hole in it (exception 02).
        A read of one such address is returned as it is, alone."""
        by_start: dict[int, list[PointSlice]] = {}
        for piece in self.slices:
            by_start.setdefault(piece.offset, []).append(piece)
        if len(by_start) == 1:
            return [self]
        parts: list[PlannedRead] = []
        for offset, pieces in sorted(by_start.items()):
            width = max(piece.width for piece in pieces)
            slices = tuple(PointSlice(piece.point, 0, piece.width) for piece in pieces)
            parts.append(PlannedRead(self.unit, self.table, self.address + offset, width, slices))
        return parts

    def decode(self, elements: Sequence[int | bool]) -> list[tuple[Point, bool | int | float]]:
        """Each point of this read with its value, from the reply's `elements`.

        Raises [`InvalidValue`][aiortu.errors.InvalidValue] if `elements` is shorter than
        [`count`][aiortu.core.model.PlannedRead].
        """
        if len(elements) < self.count:
            raise InvalidValue("len(elements)", len(elements), f"at least {self.count}")
        return [
            (s.point, s.point.decode(elements[s.offset : s.offset + s.width])) for s in self.slices
        ]


def _check_limit(name: str, value: int, spec_limit: int) -> None:
    allowed = range(1, spec_limit + 1)
    if isinstance(value, bool) or not isinstance(value, int) or value not in allowed:
        raise InvalidValue(name, value, allowed)


def plan_reads(
    points: Iterable[Point],
    *,
    max_gap: int = 10,
    max_bit_gap: int | None = None,
    max_registers: int = MAX_READ_REGISTERS,
    max_bits: int = MAX_READ_BITS,
) -> list[PlannedRead]:
    """The read requests that cover `points`, ordered by unit, table and address.

    Points of the same unit and table are merged into one read while the unused
    elements between the end of the read so far and the next point are at most
    `max_gap` registers (`max_bit_gap` bits; default `16 * max_gap`) and the read
    stays within `max_registers` (1..125) or `max_bits` (1..2000) elements. Overlapping
    points and duplicates share a read. Every point is in exactly one read.
    """
    _check_limit("max_registers", max_registers, MAX_READ_REGISTERS)
    _check_limit("max_bits", max_bits, MAX_READ_BITS)
    if isinstance(max_gap, bool) or not isinstance(max_gap, int) or max_gap < 0:
        raise InvalidValue("max_gap", max_gap, "an integer >= 0")
    bit_gap = 16 * max_gap if max_bit_gap is None else max_bit_gap
    if isinstance(bit_gap, bool) or not isinstance(bit_gap, int) or bit_gap < 0:
        raise InvalidValue("max_bit_gap", bit_gap, "an integer >= 0")
    # Sorting by width too puts the narrower of two points at one address first; the
    # order among equal points is the caller's (sorted() is stable).
    ordered = sorted(points, key=lambda p: (p.unit, p.table.value, p.address, p.width))
    reads: list[PlannedRead] = []
    group: list[Point] = []
    end = 0

    def close() -> None:
        first = group[0]  # every point of a group shares its unit and table
        start = first.address
        slices = tuple(PointSlice(p, p.address - start, p.width) for p in group)
        reads.append(PlannedRead(first.unit, first.table, start, end - start, slices))

    for point in ordered:
        limit, gap = (max_bits, bit_gap) if point.table.is_bit else (max_registers, max_gap)
        if point.width > limit:
            raise InvalidValue(
                "max_registers", limit, f">= {point.width}", f"{point.name} is wider"
            )
        if group:
            first = group[0]
            same = (first.unit, first.table) == (point.unit, point.table)
            new_end = max(end, point.address + point.width)
            if same and point.address - end <= gap and new_end - first.address <= limit:
                group.append(point)
                end = new_end
                continue
            close()
        group = [point]
        end = point.address + point.width
    if group:
        close()
    return reads

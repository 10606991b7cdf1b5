"""Read planning for a profile: the fewest reads that cover a set of points, and the decoding
of their replies.

Points of one table are merged, in address order, while the unused elements between them stay
within the profile's `max_gap`, the read within its `max_block`, and no hole of the profile lies
between them (greedy from the lowest address, which is optimal for covering points in order).
A device may still refuse a merged read with exception 02 (a hole the profile does not know):
[`ReadPlan.refused`][aiortu.core.model.ReadPlan.refused] splits that read at its widest gap and
the plan keeps the pieces, so the hole costs one refused request once, not one per poll.

Decoding packs a reply's registers into bytes once and unpacks every point of the read with one
precompiled `struct` call per byte order, then scales: the general codec
([`decode_point`][aiortu.core.model.decode_point]) gives the same values, one point at a time.
"""

from __future__ import annotations

import struct
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass, field

from aiortu.core.model._addressing import Table
from aiortu.core.model._point_codec import coding, scaled, text_of
from aiortu.core.model._profile import PointType, Profile, ProfilePoint, Value

__all__ = ("BlockRead", "Raw", "ReadPlan", "describe", "plan_blocks")

Raw = int | float | bool | str
"""A point's value as read, before scaling."""


@dataclass(frozen=True, slots=True)
class _Unpacker:
    """One `struct` call over a reply's bytes: the points it yields, in order."""

    codec: struct.Struct
    little_endian_buffer: bool
    points: tuple[ProfilePoint, ...]
    converts: bool
    """Whether some raw values need converting (strings from bytes, bools from integers)."""


_CONVERTED = (PointType.STRING, PointType.BOOL)


def _unpackers(address: int, points: Sequence[ProfilePoint]) -> tuple[_Unpacker, ...]:
    # Planning runs once per plan, but for every point: a plain loop, no generator per point.
    groups: dict[tuple[bool, str], list[tuple[ProfilePoint, str]]] = {}
    for point in points:
        swapped, order, code = coding(point.type, point.layout, point.size)
        groups.setdefault((swapped, order), []).append((point, code))
    unpackers = []
    for (swapped, order), coded in groups.items():
        codes, at, members, converts = [], 0, [], False
        for point, code in coded:  # in address order, never overlapping
            start = 2 * (point.address - address)
            codes.append(f"{start - at}x{code}" if start > at else code)
            at = start + 2 * point.size
            members.append(point)
            converts = converts or point.type in _CONVERTED
        codec = struct.Struct(order + "".join(codes))
        unpackers.append(_Unpacker(codec, swapped, tuple(members), converts))
    return tuple(unpackers)


@dataclass(frozen=True, slots=True)
class BlockRead:
    """One read: `count` elements of `table` from `address`, serving `points` (address order)."""

    table: Table
    address: int
    count: int
    points: tuple[ProfilePoint, ...]
    _unpackers: tuple[_Unpacker, ...] = field(default=(), repr=False, compare=False)
    _big: struct.Struct = field(init=False, repr=False, compare=False)
    _little: struct.Struct = field(init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        if not self.table.is_bit:
            object.__setattr__(self, "_unpackers", _unpackers(self.address, self.points))
        object.__setattr__(self, "_big", struct.Struct(f">{self.count}H"))
        object.__setattr__(self, "_little", struct.Struct(f"<{self.count}H"))

    def decode(self, elements: Sequence[int | bool]) -> list[tuple[ProfilePoint, Raw]]:
        """Each point of the read with its raw value, from the reply's `elements`."""
        if self.table.is_bit:
            start = self.address
            return [(p, bool(elements[p.address - start])) for p in self.points]
        raws: list[tuple[ProfilePoint, Raw]] = []
        big = little = b""
        for unpacker in self._unpackers:
            if unpacker.little_endian_buffer:
                little = little or self._little.pack(*elements[: self.count])
                data = little
            else:
                big = big or self._big.pack(*elements[: self.count])
                data = big
            values = unpacker.codec.unpack_from(data)
            if unpacker.converts:
                values = tuple(map(_converted, unpacker.points, values))
            raws.extend(zip(unpacker.points, values, strict=True))
        return raws


def _converted(point: ProfilePoint, raw: int | float | bytes) -> Raw:
    if isinstance(raw, bytes):
        return text_of(point, raw)
    return bool(raw) if point.type is PointType.BOOL else raw


def _hole_in(holes: Sequence[tuple[int, int]], start: int, stop: int) -> bool:
    return any(hole_start < stop and start < hole_stop for hole_start, hole_stop in holes)


def plan_blocks(points: Iterable[ProfilePoint], profile: Profile) -> list[BlockRead]:
    """The reads that cover `points` within `profile`'s limits and around its holes, by table
    and address. Every point is in exactly one read."""
    reads: list[BlockRead] = []
    by_table: dict[Table, list[ProfilePoint]] = {}
    for point in points:
        by_table.setdefault(point.table, []).append(point)
    for table in sorted(by_table, key=lambda t: t.value):
        limit, gap = profile.limits.for_table(table)
        holes = [(h.start, h.stop) for h in profile.holes if h.table is table]
        group: list[ProfilePoint] = []
        first = end = 0
        for point in sorted(by_table[table], key=lambda p: p.address):
            address = point.address
            stop = point.stop if point.stop > end else end  # the group's span with it
            if (
                group
                and address - end <= gap
                and stop - first <= limit
                and not (holes and _hole_in(holes, end, address))
            ):
                group.append(point)
                end = stop
                continue
            if group:
                reads.append(_block(group, end))
            group, first, end = [point], address, point.stop
        reads.append(_block(group, end))
    return reads


def _block(points: Sequence[ProfilePoint], end: int) -> BlockRead:
    return BlockRead(points[0].table, points[0].address, end - points[0].address, tuple(points))


def _split(read: BlockRead) -> tuple[BlockRead, BlockRead]:
    """`read` in two at its widest gap between points (the middle one among equals)."""
    points = read.points
    gaps = [(points[i].address - points[i - 1].stop, i) for i in range(1, len(points))]
    middle = len(points) / 2
    _, cut = max(gaps, key=lambda g: (g[0], -abs(g[1] - middle)))
    first, second = points[:cut], points[cut:]
    return (
        _block(first, max(p.stop for p in first)),
        _block(second, max(p.stop for p in second)),
    )


class ReadPlan:
    """The reads of `points` of `profile` (every point, or a poll class's), and what a
    poll learns about the device.

    The points' scale factors are read too, whatever their poll class.
    """

    def __init__(self, profile: Profile, points: Iterable[ProfilePoint] | None = None) -> None:
        self.profile = profile
        chosen = {p.name: p for p in (profile.points if points is None else points)}
        for point in list(chosen.values()):
            if point.scale_factor is not None and point.scale_factor not in chosen:
                chosen[point.scale_factor] = profile.point(point.scale_factor)
        self.points: tuple[ProfilePoint, ...] = tuple(chosen.values())
        """The points read: those asked for, and their scale factors."""
        self._reads = plan_blocks(self.points, profile)
        self.splits = 0
        """How many merged reads the device refused and the plan split."""
        # Points whose value is the raw one: no scale, offset, factor or sentinel.
        self._plain = frozenset(
            p.name
            for p in self.points
            if p.type.is_number
            and p.scale is None
            and p.offset is None
            and p.scale_factor is None
            and p.not_available is None
        )

    @property
    def reads(self) -> tuple[BlockRead, ...]:
        """The reads, by table and address."""
        return tuple(self._reads)

    def refused(self, read: BlockRead) -> tuple[BlockRead, ...]:
        """`read` was refused with exception 02: the pieces that replace it in the plan (to
        read now), or none when it serves one point (that point is unreadable as it stands)."""
        if len(read.points) < 2:
            return ()
        index = self._reads.index(read)
        pieces = _split(read)
        self._reads[index : index + 1] = pieces
        self.splits += 1
        return pieces

    def values(self, raws: Mapping[str, Raw]) -> dict[str, Value]:
        """The value of every point of `raws` (raw values by point name, as the reads
        decoded them): scaled, with its scale factor's raw value from `raws`."""
        values: dict[str, Value] = {}
        plain = self._plain
        point_of = self.profile.point
        for name, raw in raws.items():
            if name in plain:
                values[name] = raw
                continue
            point = point_of(name)
            factor = point.scale_factor
            sf = raws.get(factor) if factor is not None else None
            values[name] = scaled(point, raw, sf if isinstance(sf, int) else None)
        return values


def describe(read: BlockRead) -> str:
    """`read` in words, for logs: `input_registers 0..79 (40 points)`."""
    kind = "points" if len(read.points) != 1 else "point"
    return (
        f"{read.table} {read.address}..{read.address + read.count - 1} ({len(read.points)} {kind})"
    )

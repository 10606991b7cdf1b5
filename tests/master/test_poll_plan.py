"""The poll planner: every point in exactly one read, reads within the spec, gaps merged."""

from __future__ import annotations

import itertools
import random

import pytest
from hypothesis import given
from hypothesis import strategies as st

from aiortu.core.model import (
    MAX_READ_BITS,
    MAX_READ_REGISTERS,
    Layout,
    Point,
    Table,
    ValueType,
    encode_value,
    plan_reads,
)
from aiortu.errors import InvalidValue


@st.composite
def points(draw: st.DrawFn) -> list[Point]:
    count = draw(st.integers(1, 60))
    found: list[Point] = []
    for index in range(count):
        table = draw(st.sampled_from(list(Table)))
        kind = ValueType.UINT16 if table.is_bit else draw(st.sampled_from(list(ValueType)))
        width = 1 if table.is_bit else kind.register_count
        # Clustered addresses, so that merging is exercised, with some far away.
        base = draw(st.sampled_from([0, 100, 3000, 65536 - 300]))
        address = base + draw(st.integers(0, 299 - width))
        unit = draw(st.integers(1, 3))
        found.append(Point(f"p{index}", unit, table, address, kind))
    return found


@given(points(), st.integers(0, 40), st.integers(1, 125), st.integers(1, 2000))
def test_every_point_in_exactly_one_read_within_the_limits(
    found: list[Point], max_gap: int, max_registers: int, max_bits: int
) -> None:
    max_registers = max(max_registers, 4)
    reads = plan_reads(found, max_gap=max_gap, max_registers=max_registers, max_bits=max_bits)
    covered = [s.point for read in reads for s in read.slices]
    assert sorted(covered, key=id) == sorted(found, key=id)
    assert len(covered) == len(found)
    for read in reads:
        limit = max_bits if read.table.is_bit else max_registers
        assert 1 <= read.count <= limit
        assert read.count <= (MAX_READ_BITS if read.table.is_bit else MAX_READ_REGISTERS)
        for s in read.slices:
            assert (s.point.unit, s.point.table) == (read.unit, read.table)
            assert s.offset == s.point.address - read.address
            assert s.offset >= 0
            assert s.offset + s.width <= read.count
        # The read starts at its first point and ends at its last element: no waste.
        assert min(s.offset for s in read.slices) == 0
        assert max(s.offset + s.width for s in read.slices) == read.count


@given(points(), st.integers(0, 40))
def test_points_within_max_gap_are_merged_unless_a_limit_forbids(
    found: list[Point], max_gap: int
) -> None:
    reads = plan_reads(found, max_gap=max_gap, max_bit_gap=max_gap)
    # Consecutive reads of one unit and table: the gap between them is over max_gap,
    # or merging them would exceed the limit.
    for a, b in itertools.pairwise(reads):
        if (a.unit, a.table) != (b.unit, b.table):
            continue
        gap = b.address - (a.address + a.count)
        limit = MAX_READ_BITS if a.table.is_bit else MAX_READ_REGISTERS
        first_of_b = min(s.point.address + s.width for s in b.slices if s.offset == 0)
        assert gap > max_gap or max(first_of_b, a.address + a.count) - a.address > limit
    # Within a read, no gap between covered elements is over max_gap.
    for read in reads:
        end = 0
        for s in sorted(read.slices, key=lambda s: s.offset):
            assert s.offset - end <= max_gap
            end = max(end, s.offset + s.width)


def test_an_example_plan_and_decoding() -> None:
    found = [
        Point.of("a", 1, "40001"),
        Point.of("b", 1, "40003", "float32", layout="CDAB"),
        Point.of("c", 1, "40020", "int16", scale=0.1),
        Point.of("d", 2, "40001"),
        Point.of("e", 1, "00005"),
        Point.of("f", 1, "00001"),
    ]
    reads = plan_reads(found, max_gap=5)
    assert [(r.unit, r.table, r.address, r.count) for r in reads] == [
        (1, Table.COILS, 0, 5),
        (1, Table.HOLDING_REGISTERS, 0, 4),
        (1, Table.HOLDING_REGISTERS, 19, 1),
        (2, Table.HOLDING_REGISTERS, 0, 1),
    ]
    registers = [7, 0, *encode_value(1.5, ValueType.FLOAT32, Layout.CDAB)]
    assert [(p.name, v) for p, v in reads[1].decode(registers)] == [("a", 7), ("b", 1.5)]
    assert reads[2].decode([0xFFF6]) == [(found[2], pytest.approx(-1.0))]
    assert [v for _, v in reads[0].decode([1, 0, 0, 0, 1])] == [True, True]


def test_bad_points_and_limits_are_refused() -> None:
    with pytest.raises(InvalidValue):
        Point("x", 0, Table.COILS, 0)
    with pytest.raises(InvalidValue):
        Point("x", 1, Table.HOLDING_REGISTERS, 65535, ValueType.FLOAT32)
    with pytest.raises(InvalidValue):
        Point.of("x", 1, "40001", "float16")
    with pytest.raises(InvalidValue):
        plan_reads([Point.of("x", 1, "40001")], max_registers=126)
    with pytest.raises(InvalidValue):
        plan_reads([Point.of("x", 1, "40001", "float64")], max_registers=3)


@given(points(), st.integers(0, 40), st.randoms(use_true_random=False))
def test_a_split_read_serves_each_point_once_with_the_same_value(
    found: list[Point], max_gap: int, rng: random.Random
) -> None:
    for read in plan_reads(found, max_gap=max_gap, max_bit_gap=max_gap):
        elements: list[int | bool] = [
            bool(rng.getrandbits(1)) if read.table.is_bit else rng.getrandbits(16)
            for _ in range(read.count)
        ]
        merged = read.decode(elements)
        parts = read.split()
        starts = sorted({s.point.address for s in read.slices})
        # One read per address a point starts at, in order, each within the merged read.
        assert [part.address for part in parts] == starts
        split: list[tuple[Point, bool | int | float]] = []
        for part in parts:
            assert (part.unit, part.table) == (read.unit, read.table)
            assert part.count == max(s.width for s in part.slices)
            assert all(s.offset == 0 for s in part.slices)
            offset = part.address - read.address
            split += part.decode(elements[offset : offset + part.count])
        # Compared by repr: a float32 or float64 NaN is never equal to itself.
        assert sorted(map(repr, split)) == sorted(map(repr, merged))
        if len(starts) == 1:
            assert parts == [read]

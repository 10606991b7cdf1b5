"""Read planning: every point in exactly one read, within the limits, never across a hole;
refused reads split once and remembered; the fast decoding equal to the general codec."""

from __future__ import annotations

import random
from pathlib import Path

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from aiortu.core.model import (
    DeviceInfo,
    Hole,
    Layout,
    PlanLimits,
    PointType,
    Profile,
    ProfilePoint,
    ReadPlan,
    Table,
    decode_point,
    encode_point,
    load_profile,
    plan_blocks,
    raw_of,
)

SDM630 = Path(__file__).parents[3] / "src/aiortu/core/model/profiles/eastron-sdm630.toml"
NUMERIC = [PointType.U16, PointType.I16, PointType.U32, PointType.I32, PointType.U64]
NUMERIC += [PointType.I64, PointType.F32, PointType.F64]
WIDTH = {"u16": 1, "i16": 1, "u32": 2, "i32": 2, "u64": 4, "i64": 4, "f32": 2, "f64": 4}


def make(points: list[ProfilePoint], holes: tuple[Hole, ...] = (), **limits: int) -> Profile:
    return Profile(
        "t.toml", DeviceInfo("ACME", "M1"), tuple(points), holes, limits=PlanLimits(**limits)
    )


@st.composite
def layouts_of_points(draw: st.DrawFn) -> list[ProfilePoint]:
    points, address = [], draw(st.integers(0, 50))
    for index in range(draw(st.integers(1, 40))):
        kind = draw(st.sampled_from([*NUMERIC, PointType.STRING, PointType.BOOL, PointType.ENUM]))
        size = draw(st.integers(1, 4)) if kind is PointType.STRING else WIDTH.get(kind.value, 1)
        layout = draw(st.sampled_from(list(Layout)))
        points.append(
            ProfilePoint(f"p{index}", Table.INPUT_REGISTERS, address, kind, size, layout=layout)
        )
        address += size + draw(st.integers(0, 30))
    return points


@settings(max_examples=200, deadline=None)
@given(
    points=layouts_of_points(),
    max_block=st.integers(4, 125),
    max_gap=st.integers(0, 40),
    hole_at=st.integers(0, 600),
    seed=st.integers(0, 2**32 - 1),
)
def test_plan_covers_each_point_once_within_limits(
    points: list[ProfilePoint], max_block: int, max_gap: int, hole_at: int, seed: int
) -> None:
    holes = tuple(
        Hole(Table.INPUT_REGISTERS, hole_at, 2)
        for _ in [0]
        if not any(p.address < hole_at + 2 and hole_at < p.stop for p in points)
    )
    profile = make(points, holes, max_block=max_block, max_gap=max_gap)
    reads = plan_blocks(points, profile)
    served = [p.name for read in reads for p in read.points]
    assert sorted(served) == sorted(p.name for p in points)
    for read in reads:
        assert read.count <= max_block
        assert read.address == read.points[0].address
        assert read.address + read.count == max(p.stop for p in read.points)
        for hole in holes:
            assert not (read.address < hole.stop and hole.start < read.address + read.count)
        for before, after in zip(read.points, read.points[1:], strict=False):
            assert after.address - before.stop <= max_gap
    # Differential: the plan's decoding equals the general codec, point by point.
    rng = random.Random(seed)
    registers = {a: rng.randrange(0x10000) for a in range(2000)}
    for read in reads:
        elements = [registers[read.address + i] for i in range(read.count)]
        for point, raw in read.decode(elements):
            own = [registers[point.address + i] for i in range(point.size)]
            expected = raw_of(point, own)
            assert raw == expected or (raw != raw and expected != expected), (point, seed)


def test_a_gap_or_a_block_of_exactly_the_limit_is_read_in_one() -> None:
    def spans(*addresses: int, **limits: int) -> list[tuple[int, int]]:
        points = [
            ProfilePoint(f"p{a}", Table.HOLDING_REGISTERS, a, PointType.U16, 1) for a in addresses
        ]
        return [(read.address, read.count) for read in plan_blocks(points, make(points, **limits))]

    assert spans(0, 4, max_gap=3) == [(0, 5)]  # 3 registers between: within the gap
    assert spans(0, 5, max_gap=3) == [(0, 1), (5, 1)]
    assert spans(0, 9, max_block=10) == [(0, 10)]  # 10 registers: the largest read
    assert spans(0, 10, max_block=10, max_gap=20) == [(0, 1), (10, 1)]


def test_greedy_merge_is_fewest_reads_for_the_sdm630() -> None:
    profile = load_profile(SDM630)
    measurements = [p for p in profile.points if p.table is Table.INPUT_REGISTERS]
    assert len(measurements) >= 80
    reads = ReadPlan(profile, measurements).reads
    assert len(reads) <= 4
    assert {r.table for r in reads} == {Table.INPUT_REGISTERS}


def test_a_hole_is_never_read_across() -> None:
    points = [
        ProfilePoint("a", Table.HOLDING_REGISTERS, 0, PointType.U16, 1),
        ProfilePoint("b", Table.HOLDING_REGISTERS, 3, PointType.U16, 1),
    ]
    assert len(plan_blocks(points, make(points))) == 1
    hole = Hole(Table.HOLDING_REGISTERS, 2, 1)
    assert [(r.address, r.count) for r in plan_blocks(points, make(points, (hole,)))] == [
        (0, 1),
        (3, 1),
    ]
    other_table = Hole(Table.INPUT_REGISTERS, 2, 1)
    assert len(plan_blocks(points, make(points, (other_table,)))) == 1


def poll(plan: ReadPlan, unmapped: set[int]) -> tuple[int, int]:
    """One poll against a device that refuses reads touching `unmapped`: (requests, refused)."""
    requests = refused = 0
    pending = list(plan.reads)
    while pending:
        read = pending.pop(0)
        requests += 1
        if any(read.address <= a < read.address + read.count for a in unmapped):
            refused += 1
            pending[:0] = plan.refused(read)
    return requests, refused


@pytest.mark.parametrize("seed", range(20))
def test_an_unknown_hole_costs_refusals_in_the_first_poll_only(seed: int) -> None:
    rng = random.Random(seed)
    points, address = [], 0
    for index in range(rng.randrange(2, 60)):
        points.append(ProfilePoint(f"p{index}", Table.HOLDING_REGISTERS, address, PointType.U16, 1))
        address += 1 + rng.randrange(0, 4)
    used = {p.address for p in points}
    unmapped = {a for a in range(address) if a not in used and rng.random() < 0.1}
    plan = ReadPlan(make(points, max_gap=3))
    first_requests, first_refused = poll(plan, unmapped)
    second_requests, second_refused = poll(plan, unmapped)
    assert second_refused == 0, f"seed {seed}"
    assert second_requests == first_requests - first_refused, f"seed {seed}"
    assert plan.splits == first_refused, f"seed {seed}"
    assert sorted(p.name for r in plan.reads for p in r.points) == sorted(p.name for p in points)


def test_a_single_point_refused_stays_as_it_is() -> None:
    point = ProfilePoint("a", Table.HOLDING_REGISTERS, 0, PointType.U16, 1)
    plan = ReadPlan(make([point]))
    assert plan.refused(plan.reads[0]) == ()
    assert len(plan.reads) == 1


def test_values_apply_scale_offset_factor_and_sentinel() -> None:
    points = [
        ProfilePoint("w", Table.HOLDING_REGISTERS, 0, PointType.I16, 1, scale_factor="w_sf"),
        ProfilePoint("w_sf", Table.HOLDING_REGISTERS, 1, PointType.I16, 1, poll="slow"),
        ProfilePoint("t", Table.HOLDING_REGISTERS, 2, PointType.U16, 1, scale=0.1, offset=-40),
        ProfilePoint("n", Table.HOLDING_REGISTERS, 3, PointType.U16, 1, not_available=0xFFFF),
        ProfilePoint("e", Table.HOLDING_REGISTERS, 4, PointType.ENUM, 1, values={2: "on"}),
        ProfilePoint("f", Table.HOLDING_REGISTERS, 5, PointType.BITFIELD, 1, bits={1: "x"}),
    ]
    profile = make(points)
    plan = ReadPlan(profile, [points[0]])  # its scale factor comes along
    assert {p.name for p in plan.points} == {"w", "w_sf"}
    read = ReadPlan(profile).reads[0]
    raws = {p.name: raw for p, raw in read.decode([1234, 0xFFFE, 650, 0xFFFF, 2, 0b110])}
    values = ReadPlan(profile).values(raws)
    assert values["w"] == pytest.approx(12.34)
    assert values["t"] == pytest.approx(25.0)
    assert values["n"] is None
    assert values["e"] == "on"
    assert values["f"] == ("x", "2")
    del raws["w_sf"]
    assert ReadPlan(profile).values(raws)["w"] is None


def test_an_empty_string_is_no_value_only_where_its_not_available_value_is_0() -> None:
    # SunSpec's rule: a string of NULs (or padding only) is "not implemented".
    unset = ProfilePoint("s", Table.HOLDING_REGISTERS, 0, PointType.STRING, 2, not_available=0)
    plain = ProfilePoint("s", Table.HOLDING_REGISTERS, 0, PointType.STRING, 2)
    assert decode_point(unset, [0, 0]) is None
    assert decode_point(unset, [0x4142, 0x2000]) == "AB"
    assert decode_point(plain, [0, 0]) == ""


@settings(max_examples=300, deadline=None)
@given(
    kind=st.sampled_from(NUMERIC),
    layout=st.sampled_from(list(Layout)),
    value=st.integers(-(2**15), 2**15 - 1),
)
def test_encode_then_decode_gives_the_value_back(
    kind: PointType, layout: Layout, value: int
) -> None:
    if kind.value.startswith("u"):
        value = abs(value)
    point = ProfilePoint("p", Table.HOLDING_REGISTERS, 0, kind, WIDTH[kind.value], layout=layout)
    registers = encode_point(point, value)
    assert decode_point(point, registers) == value

"""FaultPlan validation and FaultInjector rates, counts and reproducibility."""

from __future__ import annotations

import itertools
import math

import pytest
from hypothesis import given
from hypothesis import strategies as st

from aiortu.errors import InvalidValue
from aiortu.testing import FaultInjector, FaultPlan


@pytest.mark.parametrize(
    "kwargs",
    [
        {"bit_error_rate": -0.1},
        {"drop_rate": 1.5},
        {"garbage_rate": math.nan},
        {"gap_rate": True},
        {"gap_rate": 0.1},  # no gap length
        {"gap": -1.0},
        {"delay": (0.2, 0.1)},
        {"delay": -0.5},
        {"garbage_max": 0},
        {"seed": "x"},
    ],
)
def test_bad_plans_are_refused(kwargs):
    with pytest.raises(InvalidValue):
        FaultPlan(**kwargs)


def test_clean_plan():
    assert FaultPlan().is_clean
    assert not FaultPlan(drop_rate=0.1).is_clean
    injector = FaultInjector(FaultPlan())
    assert injector.corrupt(b"abc") == b"abc"


def _within(count: int, trials: int, rate: float, sigmas: float = 5.0) -> bool:
    expected = trials * rate
    return abs(count - expected) <= sigmas * math.sqrt(trials * rate * (1 - rate))


def test_drop_rate_over_100k_bytes():
    injector = FaultInjector(FaultPlan(drop_rate=0.01, seed=1))
    data = bytes(100_000)
    received = b"".join(injector.corrupt(data[i : i + 100]) for i in range(0, len(data), 100))
    assert injector.stats.bytes_dropped == len(data) - len(received)
    assert _within(injector.stats.bytes_dropped, len(data), 0.01)


def test_bit_error_rate_flips_that_many_bits():
    injector = FaultInjector(FaultPlan(bit_error_rate=0.001, seed=2))
    data = bytes(100_000)
    received = injector.corrupt(data)
    flipped = sum(bin(byte).count("1") for byte in received)
    assert flipped == injector.stats.bits_flipped
    assert _within(flipped, 8 * len(data), 0.001)


def test_garbage_and_gap_rates():
    injector = FaultInjector(FaultPlan(garbage_rate=0.1, garbage_max=4, gap_rate=0.02, gap=0.01))
    total = 0
    pauses = 0
    for _ in range(10_000):
        chunk = injector.apply(b"0123456789", char_time=0.001)
        total += len(chunk.data)
        pauses += sum(1 for item in chunk.items if isinstance(item, float))
    stats = injector.stats
    assert _within(stats.garbage_insertions, 10_000, 0.1)
    assert stats.garbage_insertions <= stats.garbage_bytes <= 4 * stats.garbage_insertions
    assert total == 100_000 + stats.garbage_bytes
    assert _within(stats.gaps, 100_000, 0.02)
    assert 0 < pauses <= stats.gaps


def test_dropped_byte_leaves_its_wire_time():
    injector = FaultInjector(FaultPlan(drop_rate=1.0))
    chunk = injector.apply(b"ab", char_time=0.001)
    assert chunk.data == b""
    assert sum(item for item in chunk.items if isinstance(item, float)) == pytest.approx(0.002)


def test_delay_range():
    injector = FaultInjector(FaultPlan(delay=(0.01, 0.02)))
    delays = [injector.apply(b"x").delay for _ in range(200)]
    assert all(0.01 <= d <= 0.02 for d in delays)
    assert len(set(delays)) > 100
    assert FaultInjector(FaultPlan(delay=0.05)).apply(b"x").delay == 0.05


def test_same_seed_same_faults_other_seed_other_faults():
    plan = FaultPlan(bit_error_rate=0.01, drop_rate=0.01, garbage_rate=0.2, seed=42)
    data = bytes(range(256)) * 20
    first = FaultInjector(plan).corrupt(data)
    assert FaultInjector(plan).corrupt(data) == first
    other = FaultPlan(bit_error_rate=0.01, drop_rate=0.01, garbage_rate=0.2, seed=43)
    assert FaultInjector(other).corrupt(data) != first


def test_unseeded_plan_reports_its_seed():
    injector = FaultInjector(FaultPlan(drop_rate=0.1, seed=None))
    data = bytes(1000)
    again = FaultInjector(FaultPlan(drop_rate=0.1, seed=injector.seed))
    assert injector.corrupt(data) == again.corrupt(data)


@given(cuts=st.lists(st.integers(0, 2000), max_size=30), seed=st.integers(0, 2**32))
def test_per_byte_faults_do_not_depend_on_chunking(cuts, seed):
    plan = FaultPlan(bit_error_rate=0.002, drop_rate=0.01, seed=seed)
    data = bytes(range(256)) * 8
    whole = FaultInjector(plan).corrupt(data)
    injector = FaultInjector(plan)
    bounds = [0, *sorted(cuts), len(data)]
    pieces = [injector.corrupt(data[a:b]) for a, b in itertools.pairwise(bounds)]
    assert b"".join(pieces) == whole

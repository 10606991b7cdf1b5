"""The concurrency torture suite, short run: seeded storms against the master and the slave.

Each seed draws a whole scenario (see ``scenarios.py``) and the run checks every invariant
(see ``master_storm.py`` and ``slave_storm.py``). A failure names its seed; run that seed
alone with ``AIORTU_TORTURE_SEED=<seed> pytest tests/torture``. The long run is
``benchmarks/soak_torture.py``.
"""

from __future__ import annotations

import os

import pytest

from .master_storm import run_master_scenario
from .scenarios import master_scenario, slave_scenario
from .slave_storm import run_slave_scenario

pytestmark = pytest.mark.timeout(120)


def _seeds(count: int) -> list[int]:
    chosen = os.environ.get("AIORTU_TORTURE_SEED")
    return [int(chosen)] if chosen else list(range(count))


@pytest.mark.parametrize("seed", _seeds(20))
async def test_the_master_survives_a_storm(seed: int) -> None:
    scenario = master_scenario(seed)
    report = await run_master_scenario(scenario)
    assert not report.violations, report.message()
    # Every call ended and was counted: with a result, a typed error or its cancellation.
    assert report.operations == scenario.operations, report.message()


@pytest.mark.parametrize("seed", _seeds(10))
async def test_the_slave_survives_a_storm(seed: int) -> None:
    report = await run_slave_scenario(slave_scenario(seed))
    assert not report.violations, report.message()
    assert report.outcomes["ok"] > 0, report.message()


def test_a_seed_always_draws_the_same_scenario() -> None:
    assert master_scenario(123) == master_scenario(123)
    assert slave_scenario(123) == slave_scenario(123)
    assert master_scenario(123) != master_scenario(124)


def test_the_seeds_cover_what_the_suite_promises() -> None:
    """Over the soak's seeds, every kind of line, device, call and cancellation occurs."""
    scenarios = [master_scenario(seed) for seed in range(300)]
    assert {s.line for s in scenarios} == {"virtual", "pty"}
    rates = {s.baudrate for s in scenarios}
    assert {None, 300, 115200} <= rates
    assert {d.behaviour for s in scenarios for d in s.devices} == {
        "good", "slow", "late", "dead", "wrong_unit"
    }  # fmt: skip
    calls = [c for s in scenarios for caller in s.callers for c in caller.calls]
    assert {c.kind for c in calls} == {
        "read_own",
        "read_constant",
        "write",
        "write_one",
        "broadcast",
    }
    assert {c.cancel for c in calls} == {"none", "scope", "move_on"}
    assert max(len(s.callers) for s in scenarios) == 200
    assert min(len(s.callers) for s in scenarios) == 1
    assert any(s.unplugs for s in scenarios)
    assert any(s.faults is not None for s in scenarios)
    slaves = [slave_scenario(seed) for seed in range(100)]
    assert any(s.restarts and s.in_request for s in slaves)

"""A misbehaving device against the master: every fault gives the caller the right
answer or a typed error, never wrong values or a hang, and the next call is right.

``benchmarks/soak_faults.py`` runs the same operations, randomized, for minutes.
"""

from __future__ import annotations

import random

import pytest

from .master_scenarios import FAULTS, master_rig

SEED = 20261124


@pytest.mark.parametrize("retries", [0, 1])
async def test_every_fault_gives_a_typed_error_or_the_answer_and_the_next_call_is_right(
    retries: int,
) -> None:
    rng = random.Random(SEED + retries)
    async with master_rig(rng, retries) as rig:
        for fault in FAULTS * 2:
            problems = await rig.operation(fault)
            assert problems == [], f"seed {SEED + retries}: {problems}"
    outcomes = rig.outcomes
    if retries == 0:
        # Without retries each fault shows as the error it is.
        assert outcomes.get("silent: ResponseTimeout") == 2
        assert outcomes.get("wrong unit: ResponseTimeout") == 2
        assert outcomes.get("short pdu: MalformedPDU") == 2
    else:
        # A retry is answered right.
        assert outcomes.get("silent: right answer") == 2
        assert outcomes.get("late: right answer") == 2

"""Replies the master takes, skips or fails on, end to end through the engine."""

from __future__ import annotations

import anyio
import pytest

from aiortu.core.pdu import Request
from aiortu.errors import MalformedPDU
from tests.master.fakes import FakeSlave, line


async def _one_register(slave: FakeSlave, unit: int, request: Request) -> None:
    await slave.reply(unit, bytes((0x03, 0x02, 0x00, 0x07)))  # one register, two asked


async def test_a_misshapen_reply_from_the_unit_asked_fails_at_once() -> None:
    # The response timeout is long: the caller hears MalformedPDU long before it.
    async with line(default=_one_register, timeout=30.0, retries=0) as (master, slave, _):
        with anyio.fail_after(10), pytest.raises(MalformedPDU):
            await master.read_holding_registers(1, 0, 2)
        stats = master.unit_stats(1)
        assert (stats.requests, stats.frame_errors, stats.failures) == (1, 1, 1)
        assert stats.skipped_frames == 0
        assert len(slave.seen) == 1

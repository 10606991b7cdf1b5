"""The late-reply guard between attempts: after a failed attempt (timeout or frame
error) nothing goes out, its retry included, until the line has been silent for
``late_reply_guard``."""

from __future__ import annotations

import itertools
import math

import anyio
import pytest

from aiortu.core.pdu import Request
from aiortu.core.rtu import crc16
from aiortu.errors import ResponseTimeout
from aiortu.master import Master
from aiortu.master._attempt import guard_ends
from tests.master.fakes import FakeSlave, answer, line, silent
from tests.virtual_clock import on_virtual_clock

TIMEOUT = 0.05
GUARD = 0.4


def test_the_guard_ends_a_guard_after_the_failure_or_after_the_last_byte_once() -> None:
    failed = 10.0
    until = failed + 1.0
    assert guard_ends(until, 9.0, 1.0) == until  # silent since before the failure
    assert guard_ends(until, 10.5, 1.0) == 11.5  # a byte in the guard starts it again
    assert guard_ends(until, 50.0, 1.0) == 12.0  # never more than twice over
    assert guard_ends(-math.inf, 50.0, 1.0) == -math.inf  # no guard pending


@on_virtual_clock
async def test_a_reply_late_for_its_attempt_is_not_taken_for_the_retrys() -> None:
    # Unit 1 answers the first request only once the master has decided to retry it:
    # back to back, the retry would be on the wire and take that reply as its own.
    master_of: list[Master] = []
    replied: list[float] = []

    async def late(slave: FakeSlave, unit: int, request: Request) -> None:
        with anyio.fail_after(2):
            while master_of[0].unit_stats(1).retries == 0:  # noqa: ASYNC110
                await anyio.sleep(0.001)
        replied.append(anyio.current_time())
        await slave.reply(unit, bytes.fromhex("030400aa00bb"))

    options = {"timeout": TIMEOUT, "retries": 1, "late_reply_guard": GUARD}
    async with line(script={0: late}, default=silent, **options) as (master, slave, _):
        master_of.append(master)
        with pytest.raises(ResponseTimeout):
            await master.read_holding_registers(1, 0, 2)
        assert len(slave.seen) == 2
        # The late reply came during the guard, which then began again.
        assert slave.seen[1].time >= replied[0] + GUARD
        stats = master.unit_stats(1)
        assert (stats.requests, stats.retries, stats.timeouts, stats.failures) == (1, 1, 2, 1)


@on_virtual_clock
async def test_every_retry_after_a_timeout_waits_the_guard() -> None:
    options = {"timeout": TIMEOUT, "retries": 2, "late_reply_guard": GUARD}
    async with line(default=silent, **options) as (master, slave, _):
        with pytest.raises(ResponseTimeout):
            await master.read_holding_registers(1, 0, 2)
        times = [seen.time for seen in slave.seen]
        assert len(times) == 3
        for earlier, later in itertools.pairwise(times):
            assert later - earlier >= TIMEOUT + GUARD


async def _garbled(slave: FakeSlave, unit: int, request: Request) -> None:
    body = bytes.fromhex("01030400010002")
    crc = crc16(body) ^ 0xFFFF  # a reply, garbled
    await slave.send_raw(body + bytes((crc & 0xFF, crc >> 8)))


@on_virtual_clock
async def test_a_retry_after_a_frame_error_waits_the_guard_after_the_bad_bytes() -> None:
    options = {"timeout": 1.0, "retries": 1, "late_reply_guard": GUARD}
    async with line(default=_garbled, script={1: answer}, **options) as (master, slave, _):
        assert await master.read_holding_registers(1, 0, 2) == [1000, 1001]
        grace = master.engine.machine.frame_error_grace
        assert slave.seen[1].time - slave.seen[0].time >= grace + GUARD
        assert master.unit_stats(1).crc_errors == 1


@on_virtual_clock
async def test_a_refused_attempt_is_retried_without_the_guard() -> None:
    # An exception reply is an answer: nothing late can follow it.
    async def busy(slave: FakeSlave, unit: int, request: Request) -> None:
        await slave.reply(unit, bytes((0x83, 0x06)))

    options = {"timeout": 1.0, "retries": 1, "late_reply_guard": 5.0, "retry_on": [6]}
    async with line(script={0: busy}, **options) as (master, _, _):
        with anyio.fail_after(2):  # not the 5 s guard
            assert await master.read_holding_registers(1, 0, 2) == [1000, 1001]


async def test_a_unit_answered_only_on_retries_goes_offline() -> None:
    # Every first attempt times out and its retry is answered: three such transactions in a
    # row are three failures for the unit's health, although each got its reply.
    late_only = dict.fromkeys(range(0, 6, 2), silent)
    options = {"timeout": TIMEOUT, "retries": 1, "late_reply_guard": 0.001, "offline_after": 3}
    async with line(script=late_only, default=answer, **options) as (master, _, _):
        for _ in range(2):
            assert await master.read_holding_registers(1, 0, 2) == [1000, 1001]
            assert master.unit_stats(1).online
        assert await master.read_holding_registers(1, 0, 2) == [1000, 1001]
        stats = master.unit_stats(1)
        assert not stats.online
        assert (stats.successes, stats.late_successes, stats.failures) == (3, 3, 0)
        # A reply to a first attempt brings it back.
        assert await master.read_holding_registers(1, 0, 2) == [1000, 1001]
        assert master.unit_stats(1).online
        assert master.unit_stats(1).consecutive_failures == 0

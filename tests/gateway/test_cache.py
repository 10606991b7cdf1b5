"""The per-block read cache: reads answered again within the maximum age, writes never cached
and dropping every block they touch; counted in messages on the slave, on a fake clock, and
by default on the event loop's (a virtual clock here)."""

from __future__ import annotations

import time

import anyio
import pytest

from aiortu.errors import InvalidValue
from aiortu.gateway import Gateway
from aiortu.gateway._cache import ReadCache
from aiortu.master import Master
from aiortu.testing import VirtualBus
from tests.gateway.helpers import UNIT, client, line, memory_client
from tests.virtual_clock import on_virtual_clock

pytestmark = pytest.mark.timeout(30)

READ_03 = bytes.fromhex("03 0000 0003")
REPLY_03 = bytes.fromhex("03 06 1234 ABCD 0007")


class Clock:
    def __init__(self) -> None:
        self.now = 100.0

    def __call__(self) -> float:
        return self.now


def _cache() -> tuple[ReadCache, Clock]:
    clock = Clock()
    return ReadCache(0.5, clock), clock


def test_a_read_is_answered_within_its_age_and_not_after() -> None:
    cache, clock = _cache()
    cache.put(UNIT, READ_03, REPLY_03, cache.generation(UNIT))
    clock.now += 0.5
    assert cache.get(UNIT, READ_03) == REPLY_03
    assert cache.get(UNIT + 1, READ_03) is None
    assert cache.get(UNIT, bytes.fromhex("03 0000 0004")) is None
    clock.now += 0.001
    assert cache.get(UNIT, READ_03) is None


@pytest.mark.parametrize(
    ("write", "dropped"),
    [
        ("06 0002 0009", True),  # the block's last register
        ("06 0003 0009", False),  # just after it
        ("10 0002 0002 04 0001 0002", True),  # overlapping its end
        ("16 0000 FF00 0011", True),
        ("17 0010 0001 0001 0001 02 00AA", True),  # the write half: address 1
        ("17 0000 0001 0005 0001 02 00AA", False),  # reads 0, writes 5
        ("05 0000 FF00", False),  # a coil: another table
        ("41 00", True),  # a code the cache cannot place: the unit's every block
    ],
)
def test_a_write_drops_the_blocks_it_touches(write: str, dropped: bool) -> None:
    cache, _ = _cache()
    cache.put(UNIT, READ_03, REPLY_03, cache.generation(UNIT))
    cache.invalidate(UNIT, bytes.fromhex(write))
    assert (cache.get(UNIT, READ_03) is None) is dropped


def test_writes_to_another_unit_and_reads_drop_nothing() -> None:
    cache, _ = _cache()
    cache.put(UNIT, READ_03, REPLY_03, cache.generation(UNIT))
    cache.invalidate(UNIT + 1, bytes.fromhex("06 0000 0009"))
    cache.invalidate(UNIT, bytes.fromhex("03 0000 0001"))
    assert cache.get(UNIT, READ_03) == REPLY_03


def test_a_reply_read_while_a_write_was_sent_is_not_kept() -> None:
    cache, _ = _cache()
    generation = cache.generation(UNIT)
    cache.invalidate(UNIT, bytes.fromhex("06 0007 0009"))  # anywhere: the read was in flight
    cache.put(UNIT, READ_03, REPLY_03, generation)
    assert cache.get(UNIT, READ_03) is None
    generation = cache.generation(UNIT)
    cache.clear()  # a broadcast
    cache.put(UNIT, READ_03, REPLY_03, generation)
    assert cache.get(UNIT, READ_03) is None


def test_exceptions_are_not_kept() -> None:
    cache, _ = _cache()
    cache.put(UNIT, READ_03, bytes.fromhex("83 02"), cache.generation(UNIT))
    assert cache.get(UNIT, READ_03) is None


async def test_through_the_gateway_reads_hit_the_cache_until_a_write_or_the_age() -> None:
    clock = Clock()
    async with line(cache_ms=500, clock=clock) as bench, client(bench.gateway) as tcp:
        first = await tcp.request("03 0000 0003")
        before = bench.messages
        assert await tcp.request("03 0000 0003") == first
        assert await tcp.request("03 0000 0003") == first
        assert bench.messages == before  # two reads, nothing on the line
        assert bench.gateway.counters.cache_hits == 2
        assert await tcp.request("06 0001 0042") == "06 00 01 00 42"
        assert await tcp.request("03 0000 0003") == "03 06 12 34 00 42 00 07"
        assert bench.messages == before + 2  # the write, and the read after it
        await tcp.request("03 0000 0003")
        assert bench.messages == before + 2
        clock.now += 0.501
        await tcp.request("03 0000 0003")
        assert bench.messages == before + 3  # too old: read again


@on_virtual_clock
async def test_by_default_the_cache_ages_on_the_event_loops_clock() -> None:
    async with line(cache_ms=500, listen=()) as bench:
        # Made by `gateway` (the bench's), and made directly.
        for server in (bench.gateway, Gateway(bench.master, cache_ms=500)):
            async with memory_client(server) as tcp:
                assert await tcp.request("03 0000 0003") == "03 06 12 34 AB CD 00 07"
                on_the_line = bench.messages
                await anyio.sleep(0.5)
                await tcp.request("03 0000 0003")
                assert bench.messages == on_the_line  # 500 ms old: still answered
                await anyio.sleep(0.001)
                await tcp.request("03 0000 0003")
                assert bench.messages == on_the_line + 1


def test_a_gateway_made_outside_an_event_loop_ages_its_cache_on_asyncios_clock() -> None:
    # No loop to ask: asyncio's clock, time.monotonic (not an error, and never no clock).
    made = Gateway(Master(VirtualBus(2).endpoints[0]), cache_ms=500)
    cache = made._lines[0].cache
    assert cache is not None
    assert cache._clock is time.monotonic


async def test_without_cache_ms_every_read_goes_on_the_line() -> None:
    async with line() as bench, client(bench.gateway) as tcp:
        await tcp.request("03 0000 0003")
        before = bench.messages
        await tcp.request("03 0000 0003")
        assert bench.messages == before + 1
        assert bench.gateway.counters.cache_hits == 0


async def test_a_negative_cache_ms_is_refused_in_one_sentence() -> None:
    async with line() as bench:
        with pytest.raises(InvalidValue) as raised:
            Gateway(bench.master, cache_ms=-1)
    assert str(raised.value) == "cache_ms must be a number of milliseconds, 0 or more, not -1"


@pytest.mark.parametrize(
    ("read", "write"),
    [
        ("03 0001 0003", "06 0000 0009"),  # a register
        ("01 0001 0003", "05 0000 FF00"),  # a coil
    ],
)
def test_a_single_write_just_before_a_block_leaves_it(read: str, write: str) -> None:
    cache, _ = _cache()
    pdu = bytes.fromhex(read)
    reply = bytes.fromhex("03 06 1234 ABCD 0007" if read[:2] == "03" else "01 01 05")
    cache.put(UNIT, pdu, reply, cache.generation(UNIT))
    cache.invalidate(UNIT, bytes.fromhex(write))  # one address, the block's first minus one
    assert cache.get(UNIT, pdu) == reply

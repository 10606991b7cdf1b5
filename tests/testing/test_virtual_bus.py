"""VirtualBus: delivery, broadcast, pacing, chunking, faults, collisions, trace, closing."""

from __future__ import annotations

import itertools

import anyio
import pytest
from hypothesis import given
from hypothesis import strategies as st

from aiortu.core.serial import LineSettings
from aiortu.errors import InvalidValue
from aiortu.line import WakeTimer
from aiortu.testing import FaultPlan, VirtualBus, virtual_pair

pytestmark = pytest.mark.timeout(30)


async def receive_exactly(endpoint, count: int) -> bytes:
    data = b""
    with anyio.fail_after(5):
        while len(data) < count:
            data += await endpoint.receive()
    return data


def run(coro_fn, *args):
    return anyio.run(coro_fn, *args, backend="asyncio")


@given(chunks=st.lists(st.binary(min_size=0, max_size=300), max_size=20))
def test_bytes_arrive_intact_and_in_order(chunks):
    async def main() -> None:
        a, b = virtual_pair()
        for chunk in chunks:
            await a.send(chunk)
        expected = b"".join(chunks)
        assert await receive_exactly(b, len(expected)) == expected
        assert b.pending == 0

    run(main)


async def test_broadcast_reaches_all_others_and_never_the_sender(virtual_bus):
    bus = virtual_bus(ports=3)
    for sender in bus:
        await sender.send(b"from %d" % sender.index)
        for other in bus:
            if other is not sender:
                assert await receive_exactly(other, 6) == b"from %d" % sender.index
        assert sender.pending == 0


async def test_pacing_at_9600_8e1():
    settings = LineSettings(9600, parity="E")
    async with VirtualBus(2, settings=settings) as bus:
        a, b = bus
        started = anyio.current_time()
        await a.send(bytes(1000))
        await receive_exactly(b, 1000)
        elapsed = anyio.current_time() - started
    expected = 1000 * 11 / 9600
    assert expected == pytest.approx(1.1458, abs=1e-3)
    assert elapsed == pytest.approx(expected, rel=0.05)


async def test_paced_bytes_do_not_arrive_early():
    a, b = virtual_pair(settings=LineSettings(19200))
    started = anyio.current_time()
    await a.send(bytes(20))
    first = await b.receive()
    assert anyio.current_time() - started >= LineSettings(19200).char_time * len(first) - 1e-4
    assert len(first) < 20


async def test_adapter_chunks_at_most_chunk_size():
    a, b = virtual_pair(settings=LineSettings(19200), chunk_size=16, latency=0.016)
    await a.send(bytes(range(64)))
    pieces = []
    with anyio.fail_after(2):
        while sum(map(len, pieces)) < 64:
            pieces.append(await b.receive())
    assert b"".join(pieces) == bytes(range(64))
    assert all(len(piece) <= 16 for piece in pieces)
    assert len(pieces) == 4


async def test_adapter_latency_holds_a_short_frame():
    settings = LineSettings(19200)
    a, b = virtual_pair(settings=settings, latency=0.016)
    started = anyio.current_time()
    await a.send(bytes(8))
    assert await b.receive() == bytes(8)
    assert anyio.current_time() - started >= 0.016 + settings.char_time


async def test_unpaced_chunking_with_latency():
    a, b = virtual_pair(latency=0.01)
    started = anyio.current_time()
    await a.send(b"abc")
    await a.send(b"def")
    assert await b.receive() == b"abcdef"
    assert anyio.current_time() - started >= 0.01


async def test_trace_is_paced_and_non_overlapping():
    settings = LineSettings(38400)
    async with VirtualBus(2, settings=settings) as bus:
        a, b = bus
        for _ in range(3):
            await a.send(bytes(8))
            await receive_exactly(b, 8)
            await anyio.sleep(settings.t3_5)
            await b.send(bytes(11))
            await receive_exactly(a, 11)
            await anyio.sleep(settings.t3_5)
    trace = list(bus.trace)
    assert [entry.sender for entry in trace] == [0, 1] * 3
    for entry in trace:
        assert entry.end - entry.start == pytest.approx(len(entry.data) * settings.char_time)
    for before, after in itertools.pairwise(trace):
        assert after.start - before.end >= settings.t3_5
    assert bus.collisions == 0


async def test_continuation_of_one_sender_is_one_burst():
    settings = LineSettings(9600)
    a, b = virtual_pair(settings=settings)
    await a.send(b"\x11\x03\x00")
    await a.send(b"\x6b\x00\x03\x76\x87")
    assert await receive_exactly(b, 8) == b"\x11\x03\x00\x6b\x00\x03\x76\x87"
    (entry,) = a.bus.trace
    assert entry.data == b"\x11\x03\x00\x6b\x00\x03\x76\x87"
    assert entry.end - entry.start == pytest.approx(8 * settings.char_time)


async def test_collision_is_counted_and_queued_after():
    settings = LineSettings(19200)
    bus = VirtualBus(3, settings=settings)
    a, b, c = bus
    await a.send(b"A" * 20)
    await b.send(b"B" * 5)
    assert bus.collisions == 1
    assert await receive_exactly(c, 25) == b"A" * 20 + b"B" * 5
    first, second = bus.trace
    assert second.start == pytest.approx(first.end)
    assert await receive_exactly(a, 5) == b"B" * 5
    assert await receive_exactly(b, 20) == b"A" * 20


async def test_drop_rate_through_the_bus():
    bus = VirtualBus(2, faults=FaultPlan(drop_rate=0.01, seed=3), receive_buffer_size=200_000)
    a, b = bus
    for _ in range(100):
        await a.send(bytes(1000))
    received = b.pending
    assert received == 100_000 - bus.injector.stats.bytes_dropped
    assert abs(bus.injector.stats.bytes_dropped - 1000) < 5 * 31.5


async def test_same_seed_same_faults_on_the_bus():
    plan = FaultPlan(bit_error_rate=0.01, garbage_rate=0.3, drop_rate=0.02, seed=9)

    async def once() -> bytes:
        a, b = virtual_pair(faults=plan)
        for i in range(50):
            await a.send(bytes([i]) * 17)
        return await b.receive(10**6)

    assert await once() == await once()


async def test_gap_fault_pauses_inside_a_frame():
    settings = LineSettings(19200)
    plan = FaultPlan(gap_rate=1.0, gap=0.02)
    a, b = virtual_pair(settings=settings, faults=plan)
    # Timed from before the send: a receiver that wakes late cannot shorten the gap.
    started = anyio.current_time()
    await a.send(b"xy")
    assert await b.receive() == b"x"
    assert await b.receive() == b"y"
    assert anyio.current_time() - started >= 0.02


async def test_overrun_drops_the_oldest_bytes():
    bus = VirtualBus(2, receive_buffer_size=10)
    a, b = bus
    await a.send(bytes(range(25)))
    assert await b.receive() == bytes(range(15, 25))
    assert b.overrun_bytes == 15


async def test_closing_an_endpoint():
    a, b = virtual_pair()
    await a.send(b"last words")
    await a.aclose()
    with pytest.raises(anyio.ClosedResourceError):
        await a.send(b"more")
    with pytest.raises(anyio.ClosedResourceError):
        await a.receive()
    assert await b.receive() == b"last words"
    with pytest.raises(anyio.EndOfStream):
        await b.receive()


async def test_closing_the_bus_wakes_receivers():
    bus = VirtualBus(3)
    outcome = []

    async def wait(endpoint) -> None:
        try:
            await endpoint.receive()
        except anyio.ClosedResourceError:
            outcome.append(endpoint.index)

    async with anyio.create_task_group() as tg:
        for endpoint in bus:
            tg.start_soon(wait, endpoint)
        await anyio.wait_all_tasks_blocked()
        await bus.aclose()
    assert sorted(outcome) == [0, 1, 2]


async def test_send_eof_is_not_supported(virtual_pair):
    a, _ = virtual_pair
    with pytest.raises(NotImplementedError):
        await a.send_eof()


@pytest.mark.parametrize(
    "kwargs",
    [{"ports": 0}, {"chunk_size": 0}, {"latency": -1}, {"receive_buffer_size": 0}],
)
def test_bad_options(kwargs):
    with pytest.raises(InvalidValue):
        VirtualBus(**kwargs)


async def test_send_waits_when_the_wire_backlog_is_full():
    settings = LineSettings(115200)
    a, b = virtual_pair(settings=settings)
    a.bus._send_backlog = 100 * settings.char_time
    started = anyio.current_time()
    await a.send(bytes(300))
    await a.send(bytes(10))
    assert anyio.current_time() - started >= 200 * settings.char_time - 1e-3
    assert len(await receive_exactly(b, 310)) == 310


@pytest.mark.parametrize("baudrate", [9600, 115200])
async def test_last_byte_of_a_frame_arrives_on_time_never_before(baudrate):
    # Under asyncio the bus wakes its receivers with a timer of its own, so the last byte
    # of a frame comes at its due time, not up to a millisecond later as the loop's timers
    # would hand it over; the middle of the frame may come in pieces, never early.
    settings = LineSettings(baudrate)
    a, b = virtual_pair(settings=settings)
    lateness = []
    for frame in range(20):
        size = 8 + frame
        await anyio.sleep(0.002)
        await a.send(bytes(size))
        start = a.bus.trace[-1].start
        received = 0
        with anyio.fail_after(5):
            while received < size:
                received += len(await b.receive())
                now = anyio.current_time()
                assert now >= start + received * settings.char_time - 1e-9
        lateness.append(now - (start + size * settings.char_time))
    assert min(lateness) >= -1e-9
    if isinstance(a.bus._timer, WakeTimer):
        assert sorted(lateness)[len(lateness) // 2] < 0.0005

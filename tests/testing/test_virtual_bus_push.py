"""The push extension on VirtualBus endpoints: only where nothing is held on the wire,
handed over in a later loop pass, the end reported once; and a master and a slave on it
behave exactly as on the plain byte stream."""

from __future__ import annotations

import os
import random
from collections.abc import Callable
from dataclasses import asdict
from typing import Any

import anyio
import pytest

import aiortu
from aiortu.core.serial import LineSettings
from aiortu.testing import FaultPlan, VirtualBus, virtual_pair

pytestmark = pytest.mark.timeout(30)

PUSH_METHODS = ("set_receiver", "send_nowait")
SEEDS = [int(os.environ["AIORTU_PUSH_SEED"])] if "AIORTU_PUSH_SEED" in os.environ else [1, 2, 3]
"""The scenarios compared pushed and streamed; ``AIORTU_PUSH_SEED=N`` runs seed N alone."""


@pytest.mark.parametrize(
    ("options", "pushes"),
    [
        ({}, True),
        ({"faults": FaultPlan()}, True),  # a plan without faults holds nothing
        ({"settings": LineSettings(19200)}, False),
        ({"chunk_size": 8}, False),
        ({"latency": 0.001}, False),
        ({"faults": FaultPlan(drop_rate=0.1, seed=1)}, False),
    ],
)
def test_only_a_bus_that_holds_nothing_pushes(options: dict[str, Any], pushes: bool) -> None:
    bus = VirtualBus(2, **options)
    assert bus.pushes is pushes
    for endpoint in bus:
        assert [hasattr(endpoint, name) for name in PUSH_METHODS] == [pushes, pushes]


async def test_a_transmission_reaches_the_receiver_in_a_later_loop_pass() -> None:
    a, b = virtual_pair()
    chunks: list[bytes] = []
    b.set_receiver(chunks.append)
    assert a.send_nowait(b"\x01\x03\x00\x00")
    assert a.send_nowait(b"\x00\x0a\xc5\xcd")
    assert chunks == []  # never inside the sender's call
    assert b.pending == 8
    await anyio.sleep(0.01)
    assert chunks == [b"\x01\x03\x00\x00\x00\x0a\xc5\xcd"]  # one loop pass, one chunk
    assert b.pending == 0
    await a.send(b"by the stream")
    await anyio.sleep(0.01)
    assert chunks[1:] == [b"by the stream"]
    trace = a.bus.trace
    assert {entry.sender for entry in trace} == {0}
    assert (
        b"".join(entry.data for entry in trace) == b"\x01\x03\x00\x00\x00\x0a\xc5\xcdby the stream"
    )


@pytest.mark.parametrize("backend", ["asyncio", "trio"])
def test_the_hand_over_runs_on_either_event_loop(backend: str) -> None:
    async def main() -> list[bytes]:
        a, b = virtual_pair()
        chunks: list[bytes] = []
        b.set_receiver(chunks.append)
        a.send_nowait(b"frame")
        assert chunks == []
        await anyio.sleep(0.01)
        return chunks

    assert anyio.run(main, backend=backend) == [b"frame"]


async def test_bytes_kept_before_go_at_once_and_receive_gets_them_again_without() -> None:
    a, b = virtual_pair()
    await a.send(b"kept")
    chunks: list[bytes] = []
    b.set_receiver(chunks.append)
    assert chunks == [b"kept"]
    b.set_receiver(None)
    assert a.send_nowait(b"later")
    await anyio.sleep(0.01)
    assert chunks == [b"kept"]
    with anyio.fail_after(5):
        assert await b.receive() == b"later"


async def test_the_end_is_reported_once_after_the_last_bytes() -> None:
    a, b = virtual_pair()
    chunks: list[bytes] = []
    lost: list[str] = []
    b.set_receiver(chunks.append, lambda: lost.append("lost"))
    a.send_nowait(b"last words")
    a.close()
    assert lost == []  # the bytes sent before the close come first
    await anyio.sleep(0.01)
    assert (chunks, lost) == ([b"last words"], ["lost"])
    with pytest.raises(anyio.EndOfStream):
        await b.receive()
    b.close()
    assert lost == ["lost"]
    assert not a.send_nowait(b"after the close")


async def test_closing_the_endpoint_itself_reports_the_end_at_once() -> None:
    _, b = virtual_pair()
    lost: list[str] = []
    b.set_receiver(lambda chunk: None, lambda: lost.append("lost"))
    b.close()
    assert lost == ["lost"]
    already: list[str] = []
    b.set_receiver(lambda chunk: None, lambda: already.append("lost"))
    assert already == ["lost"]
    (alone,) = VirtualBus(1)  # nobody else on the bus: receive() would end at once
    alone.set_receiver(lambda chunk: None, lambda: already.append("alone"))
    assert already == ["lost", "alone"]


@pytest.mark.parametrize(
    ("options", "pushes"), [({}, True), ({"settings": LineSettings(115200)}, False)]
)
async def test_the_master_and_the_slave_take_the_push_path_where_there_is_one(
    options: dict[str, Any], pushes: bool
) -> None:
    bus = VirtualBus(2, **options)
    store = aiortu.MemoryStore(holding_registers={0: [7, 8, 9]})
    async with aiortu.Slave(bus[1], {1: store}) as slave, aiortu.Master(bus[0]) as master:
        assert await master.read_holding_registers(1, 0, 3) == [7, 8, 9]
        assert (master.link.loop is not None, slave.link.loop is not None) == (pushes, pushes)


# --- the same scenarios pushed and streamed -----------------------------------------------


def scenario(seed: int) -> list[tuple[str, tuple[Any, ...]]]:
    """A seeded sequence of calls: reads, writes, exception responses, a silent unit."""
    rng = random.Random(seed)
    calls: list[tuple[str, tuple[Any, ...]]] = []
    for _ in range(60):
        unit = rng.choice([1] * 10 + [2] * 4 + [9])  # unit 9 does not answer
        address = rng.randrange(0, 24)  # 20 and up are outside the blocks: exception 02
        kind = rng.randrange(5)
        if kind == 0:
            calls.append(("read_holding_registers", (unit, address, rng.randrange(1, 5))))
        elif kind == 1:
            calls.append(("write_register", (unit, address, rng.randrange(65536))))
        elif kind == 2:
            calls.append(("read_coils", (unit, address, rng.randrange(1, 9))))
        elif kind == 3:
            values = [rng.randrange(65536) for _ in range(rng.randrange(1, 4))]
            calls.append(("write_registers", (unit, address, values)))
        else:
            calls.append(("read_input_registers", (unit, address, 2)))
    return calls


async def run_scenario(bus: VirtualBus, calls: list[tuple[str, tuple[Any, ...]]]) -> dict[str, Any]:
    stores = {
        unit: aiortu.MemoryStore(
            holding_registers={0: list(range(unit, unit + 20))},
            input_registers={0: list(range(100, 120))},
            coils={0: [n % 3 == 0 for n in range(20)]},
        )
        for unit in (1, 2)
    }
    results: list[object] = []
    slave = aiortu.Slave(bus[1], stores, frame_gap=0)
    # Units 1 and 2 always answer: a timeout no load can reach. Unit 9 never does: its
    # short timeout only saves time, and it times out whatever the load.
    master = aiortu.Master(bus[0], frame_gap=0, timeout=5, retries=1, late_reply_guard=0.01)
    async with slave, master:
        for name, args in calls:
            method: Callable[..., Any] = getattr(master, name)
            timeout = 0.05 if args[0] == 9 else None
            try:
                results.append(await method(*args, timeout=timeout))
            except aiortu.ModbusError as error:
                results.append(type(error).__name__)
        statistics = {
            unit: {
                k: v for k, v in asdict(stats).items() if "latency" not in k and k != "last_probe"
            }
            for unit, stats in master.statistics.items()
        }
        counters = asdict(slave.counters)
    wire = [(entry.sender, entry.data) for entry in bus.trace]
    return {"results": results, "statistics": statistics, "counters": counters, "wire": wire}


@pytest.mark.parametrize("seed", SEEDS)
async def test_pushed_and_streamed_lines_give_the_same_results_and_wire(seed: int) -> None:
    calls = scenario(seed)
    pushed = VirtualBus(2, trace_size=10_000)
    streamed = VirtualBus(2, chunk_size=256, trace_size=10_000)  # same wire, no push
    assert pushed.pushes
    assert not streamed.pushes
    outcome = await run_scenario(pushed, calls)
    expected = await run_scenario(streamed, calls)
    for key in expected:
        assert outcome[key] == expected[key], f"{key} differ (seed {seed}: AIORTU_PUSH_SEED={seed})"
    assert "ResponseTimeout" in expected["results"] or 9 not in {c[1][0] for c in calls}

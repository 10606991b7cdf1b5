"""The direct link (a pushed stream of whole frames with no frame gap: `Link.direct`) against the
same pushed stream on the link's general route, differentially.

Seeded scripts of register reads to a raw Modbus TCP server that answers each request by a plan
drawn for it (the usual reply, the same reply again, other values, an exception, none, a late
reply joined to the right one, stale and unknown transaction ids, a reply split across writes or
joined with a stray ADU, a misshapen or short reply, another unit's, a malformed header that
closes the connection mid-request) run twice: with the direct route, and with the predicate
forced off. Both runs must give the same results, unit statistics, stream and link counters,
and requests on the wire. The server reacts to what it receives, not to the clock.
"""

from __future__ import annotations

import dataclasses
import itertools
import random
from typing import Any

import anyio
import anyio.abc
import pytest

import aiortu
from aiortu.core.mbap import Adu, encode_adu
from aiortu.line import _link as link_module
from aiortu.transport import PushConnectionStream
from aiortu.transport import _tcp_push as tcp_push_module
from tests.master.test_tcp_master import fake_server, registers, until, url

pytestmark = pytest.mark.timeout(60)

SEEDS = range(4)
OPERATIONS = 24
SHAPES = ((1, 0, 2), (1, 4, 3), (2, 0, 2))
"""(unit, address, count) of the reads: replies of two lengths, from two units."""
PLANS = (
    "usual",
    "usual",
    "usual",
    "other values",
    "exception",
    "silent",
    "late, joined",
    "stale and unknown ids first",
    "split",
    "joined with a stray",
    "misshapen",
    "short",
    "another unit",
    "malformed header",
)
TIMEOUT = 0.25
"""Long enough for a split reply's second half (sent 10 ms after the first) under load."""


@pytest.fixture(autouse=True)
def pushed(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(tcp_push_module, "push_connections", lambda: True)


def _plan_reply(rng: random.Random, plan: str, adu: Adu, before: Adu | None) -> list[bytes]:
    """What the server writes for request `adu` under `plan`, write by write."""
    count = adu.pdu[4]
    usual = registers(adu, *range(7, 7 + count))
    if plan == "usual":
        return [usual]
    if plan == "other values":
        return [registers(adu, *(rng.randrange(65536) for _ in range(count)))]
    if plan == "exception":
        return [encode_adu(adu.transaction_id, adu.unit, bytes((0x83, 2)))]
    if plan == "silent":
        return []
    if plan == "late, joined":
        late = [registers(before, 666, 666)] if before is not None else []
        return [b"".join([*late, usual])]
    if plan == "stale and unknown ids first":
        stale = Adu((adu.transaction_id - 1) & 0xFFFF, adu.unit, adu.pdu)
        unknown = Adu(0xBEEF, adu.unit, adu.pdu)
        return [registers(stale, *range(count)) + registers(unknown, *range(count)), usual]
    if plan == "split":
        cut = rng.randrange(1, len(usual))
        return [usual[:cut], usual[cut:]]
    if plan == "joined with a stray":
        return [usual + registers(Adu(0xBEEF, adu.unit, adu.pdu), *range(count))]
    if plan == "misshapen":  # the function code of the usual reply, one register too many
        return [registers(adu, *range(count + 1))]
    if plan == "short":  # the first bytes of the usual reply, one register missing
        return [encode_adu(adu.transaction_id, adu.unit, usual[7:-2])]
    if plan == "another unit":
        return [registers(Adu(adu.transaction_id, adu.unit ^ 3, adu.pdu), *range(count))]
    assert plan == "malformed header"
    return [b"\x00\x00\x00\x07\x00\x03\x01\x03\x00"]


async def _run(seed: int) -> tuple[Any, ...]:
    """One run of the script: what the master got, what it counted, and what it sent."""
    rng = random.Random(seed)
    seen: list[tuple[int, int, bytes]] = []
    before: list[Adu] = []

    async def answer(stream: anyio.abc.SocketStream, adu: Adu) -> None:
        seen.append((adu.transaction_id, adu.unit, adu.pdu))
        writes = _plan_reply(rng, rng.choice(PLANS), adu, before[-1] if before else None)
        before.append(adu)
        for number, data in enumerate(writes):
            if number:
                await anyio.sleep(0.01)
            await stream.send(data)

    options = {"timeout": TIMEOUT, "retries": 1, "reconnect_delay": (0.01, 0.05)}
    results: list[Any] = []
    directs: set[bool] = set()
    async with fake_server(answer) as port, aiortu.open_master(url(port), **options) as master:
        for _ in range(OPERATIONS):
            unit, address, count = SHAPES[rng.randrange(len(SHAPES))]
            await master.connection.wait_connected()
            reconnects = master.connection.reconnects
            try:
                results.append(await master.read_holding_registers(unit, address, count))
                directs.add(master.link.direct)  # the link is open once it has answered
            except aiortu.ConnectionLost:
                results.append("ConnectionLost")
                await until(lambda: master.connection.reconnects > reconnects)  # noqa: B023
            except aiortu.ModbusError as error:
                results.append(type(error).__name__)
        link = master.link
        stream = link.stream
        assert isinstance(stream, PushConnectionStream)
        stats = {
            unit: {
                name: value
                for name, value in dataclasses.asdict(master.unit_stats(unit)).items()
                if "latency" not in name and name != "last_probe"
            }
            for unit in (1, 2)
        }
        link_counters = (link.frames_sent, link.frames_received, link.writes_begun)
        return (
            results,
            stats,
            dataclasses.asdict(stream.counters),
            link_counters,
            dict(link.discarded),
            seen,
            master.connection.reconnects,
            directs,
        )


@pytest.mark.parametrize("seed", SEEDS)
async def test_the_direct_link_and_the_general_route_agree(
    seed: int, monkeypatch: pytest.MonkeyPatch
) -> None:
    direct = await _run(seed)
    monkeypatch.setattr(link_module, "_direct", lambda link: False)
    general = await _run(seed)
    assert direct[-1] == {True}, "the direct route ran"
    assert general[-1] == {False}, "the general route ran"
    assert direct[:-1] == general[:-1], f"seed {seed}"
    results = direct[0]
    assert any(isinstance(result, list) for result in results), f"seed {seed}"


async def test_a_modbus_tcp_master_with_a_frame_gap_is_not_direct_and_keeps_the_gap() -> None:
    arrivals: list[float] = []

    async def answer(stream: anyio.abc.SocketStream, adu: Adu) -> None:
        arrivals.append(anyio.current_time())
        await stream.send(registers(adu, 1))

    options = {"timeout": 2.0, "retries": 0, "frame_gap": 0.05}
    async with fake_server(answer) as port, aiortu.open_master(url(port), **options) as master:
        for _ in range(3):
            assert await master.read_holding_registers(1, 0, 1) == [1]
        assert not master.link.direct
    # Each request leaves at least the gap after the reply before it, which came after the
    # request before it reached the server.
    assert min(later - earlier for earlier, later in itertools.pairwise(arrivals)) >= 0.05

"""Modbus UDP's pushed master stream against the general path: the master-side tests of
test_udp.py run again with the general path forced, and one scripted exchange (a lost request,
a late reply, a stranger, a malformed datagram, a duplicated reply, good replies) gives the same
results, counters and requests on the wire through both."""

from __future__ import annotations

import dataclasses
import random
from typing import Any

import anyio
import anyio.abc
import pytest

import aiortu
from aiortu.core.mbap import Adu, encode_adu
from aiortu.transport import ModbusTcpStream, PushDatagramStream
from aiortu.transport import _udp as udp_module
from tests.transport.test_udp import (
    READ_REPLY,
    fake_server,
    test_a_datagram_from_a_stranger_is_dropped_and_counted,
    test_a_lost_datagram_is_retried_and_a_late_reply_never_taken,
    test_a_malformed_datagram_is_refused_and_the_good_one_taken,
    test_a_master_and_a_server_talk_modbus_udp,
    test_nothing_answering_is_a_response_timeout,
    test_the_counters_go_on_across_streams,
)

pytestmark = pytest.mark.timeout(30)

__all__ = (  # run again here, on the general path
    "test_a_datagram_from_a_stranger_is_dropped_and_counted",
    "test_a_lost_datagram_is_retried_and_a_late_reply_never_taken",
    "test_a_malformed_datagram_is_refused_and_the_good_one_taken",
    "test_a_master_and_a_server_talk_modbus_udp",
    "test_nothing_answering_is_a_response_timeout",
    "test_the_counters_go_on_across_streams",
)


@pytest.fixture(autouse=True)
def general_path(monkeypatch: pytest.MonkeyPatch) -> None:
    """The general path (a datagram socket read by the link's task), on asyncio too."""
    monkeypatch.setattr(udp_module, "push_datagrams", lambda: False)


async def _scripted(seed: int) -> tuple[list[Any], dict[str, int], list[int]]:
    """One run of the scripted exchange; what the master got, its counters and the
    transaction ids the server saw."""
    rng = random.Random(seed)
    seen: list[int] = []
    stranger = await anyio.create_udp_socket(local_host="127.0.0.1")

    async def respond(sock: anyio.abc.UDPSocket, adu: Adu, source: tuple[str, int]) -> None:
        seen.append(adu.transaction_id)
        reply = encode_adu(adu.transaction_id, adu.unit, READ_REPLY)
        turn = rng.randrange(5)
        if turn == 0:
            return  # lost
        if turn == 1 and len(seen) > 1:
            await sock.sendto(encode_adu(seen[-2], adu.unit, bytes.fromhex("03 02 FF FF")), *source)
        if turn == 2:
            await stranger.sendto(reply, *source)
        if turn == 3:
            await sock.sendto(reply[:-1], *source)
        await sock.sendto(reply, *source)
        if turn == 4 and rng.random() < 0.5:
            await sock.sendto(reply, *source)  # duplicated: dropped, whatever it looks like

    results: list[Any] = []
    async with stranger, fake_server(respond) as port:
        url = f"udp://127.0.0.1:{port}"
        async with aiortu.open_master(url, timeout=0.1, retries=2, late_reply_guard=0) as master:
            for _ in range(12):
                try:
                    results.append(await master.read_holding_registers(1, 0, 3))
                except aiortu.ResponseTimeout:
                    results.append("timeout")
            counters = dataclasses.asdict(master.link.stream.counters)
    return results, counters, seen


@pytest.mark.parametrize("seed", [1, 2, 3])
async def test_the_pushed_stream_and_the_general_path_agree(
    seed: int, monkeypatch: pytest.MonkeyPatch
) -> None:
    general = await _scripted(seed)
    monkeypatch.setattr(udp_module, "push_datagrams", lambda: True)
    pushed = await _scripted(seed)
    assert pushed == general, f"seed {seed}"


async def test_asyncio_gets_the_pushed_stream(monkeypatch: pytest.MonkeyPatch) -> None:
    store = aiortu.MemoryStore(holding_registers={0: [4, 5]})
    async with aiortu.serve("udp://127.0.0.1:0", {1: store}) as server:
        url = f"udp://127.0.0.1:{server.port}"
        async with aiortu.open_master(url, timeout=1.0) as master:
            assert isinstance(master.link.stream, ModbusTcpStream)  # forced here
        monkeypatch.setattr(udp_module, "push_datagrams", lambda: True)
        async with aiortu.open_master(url, timeout=1.0) as master:
            assert isinstance(master.link.stream, PushDatagramStream)
            assert await master.read_holding_registers(1, 0, 2) == [4, 5]
            assert master.link.stream.counters.replies == 1

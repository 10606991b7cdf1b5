"""Seeded random traffic from several pipelining clients: each client's reads see exactly its
own earlier writes, shared reads see the shared block, and no reply reaches the wrong client."""

from __future__ import annotations

import os
import random

import anyio
import pytest

from aiortu.gateway import Gateway
from aiortu.slave import Block, MemoryStore
from tests.gateway.helpers import UNIT, TcpClient, client, line

pytestmark = pytest.mark.timeout(60)

SHARED = [0x5A5A, 0x1234, 0xBEEF, 0x0001]
"""Registers 16..19, read by every client and written by none."""

SEEDS = [int(os.environ["GATEWAY_SEED"])] if "GATEWAY_SEED" in os.environ else [1, 2, 3]


async def _session(tcp: TcpClient, index: int, rng: random.Random, seed: int) -> None:
    """Send 40 requests, up to 4 in flight; check every reply against a model of the registers
    this client owns (4 * index .. 4 * index + 3)."""
    own = [0, 0, 0, 0]
    expected: dict[int, bytes] = {}
    pending = 0
    for transaction_id in range(40):
        kind = rng.choice(("write", "read own", "read shared"))
        if kind == "write":
            offset, value = rng.randrange(4), rng.randrange(0x10000)
            own[offset] = value
            pdu = f"06 {4 * index + offset:04X} {value:04X}"
            expected[transaction_id] = bytes.fromhex(pdu)
        elif kind == "read own":
            pdu = f"03 {4 * index:04X} 0004"
            expected[transaction_id] = bytes([3, 8]) + b"".join(v.to_bytes(2) for v in own)
        else:
            pdu = "03 0010 0004"
            expected[transaction_id] = bytes([3, 8]) + b"".join(v.to_bytes(2) for v in SHARED)
        await tcp.send(pdu, UNIT, transaction_id)
        pending += 1
        if pending == 4 or transaction_id == 39:
            for _ in range(pending):
                reply = await tcp.receive()
                assert reply is not None, f"seed {seed}: client {index}: no reply"
                want = expected.pop(reply.transaction_id)
                assert reply.pdu == want, f"seed {seed}: client {index}: {reply}"
            pending = 0
    assert not expected, f"seed {seed}: client {index}: unanswered {sorted(expected)}"


async def _client(server: Gateway, index: int, rng: random.Random, seed: int) -> None:
    async with client(server) as tcp:
        await _session(tcp, index, rng, seed)


@pytest.mark.parametrize("seed", SEEDS)
async def test_random_pipelined_clients_each_see_their_own_writes(seed: int) -> None:
    store = MemoryStore(holding_registers=[Block(0, 16), Block(16, 4, SHARED)])
    rng = random.Random(seed)
    async with line({UNIT: store}) as bench:
        async with anyio.create_task_group() as tasks:
            for index in range(4):
                tasks.start_soon(_client, bench.gateway, index, random.Random(rng.random()), seed)
        assert bench.gateway.counters.requests == 160
        transactions = bench.gateway.counters.transactions
        assert transactions + bench.gateway.counters.coalesced == 160, f"seed {seed}"

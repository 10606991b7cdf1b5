"""The gateway's read shortcut (a read answered from its future's done-callback, with no task)
against the general path (a worker awaits it), differentially.

Seeded random sessions of several pipelining clients (reads of their own block and of a
block they all read, so that reads coalesce; writes; exception replies; a unit that does not
answer) run twice on the same kind of line, once with the shortcut and once with every read
on a worker (`answered_from_callback` false); and with the `tcp://` listener's connections
pushed (requests taken in the read callback where `accepted_in_callback` allows) and on anyio's
streams (`push_listener` false: the reader task takes every request). Each client must get the
same replies to the same transaction ids, and the registers must end the same. (The order of a
Modbus TCP client's replies is not promised: a read answered from a callback may overtake one
on a worker, and which other client's read a read joins depends on timing.) Each client reads
and writes its own block (and all read one no one writes), so its replies do not depend on how
the clients interleave.
"""

from __future__ import annotations

import os
import random
from typing import Any

import anyio
import pytest

import aiortu.gateway._open
import aiortu.gateway._server
from aiortu.slave import MemoryStore
from tests.gateway.helpers import UNIT, client, line

SEED = int(os.environ.get("AIORTU_GATEWAY_DIFFERENTIAL_SEED", "1126"))
CLIENTS = 4
ABSENT = 30
"""A unit no device answers: 0B after the timeout, then at once (the master fails fast)."""


def _store() -> MemoryStore:
    return MemoryStore(
        holding_registers={0: list(range(100))},
        input_registers={0: list(range(1000, 1020))},
        coils={0: [1, 0] * 8},
    )


def _session(rng: random.Random, index: int) -> list[list[tuple[int, str]]]:
    """Bursts of (unit, request PDU in hex) for client `index`, sent pipelined."""
    own = 10 + 10 * index
    choices = [
        (UNIT, "03 0000 0002"),  # the block every client reads: coalesced reads
        (UNIT, f"03 {own:04X} 0003"),
        (UNIT, f"04 {index:04X} 0002"),
        (UNIT, "01 0000 0008"),
        (UNIT, "03 0100 0001"),  # beyond the store: exception 02
    ]
    bursts = []
    for _ in range(6):
        burst = []
        for _ in range(rng.randint(1, 3)):
            roll = rng.random()
            if roll < 0.2:
                burst.append((UNIT, f"06 {own + rng.randrange(3):04X} {rng.randrange(65536):04X}"))
            elif roll < 0.23:
                burst.append((ABSENT, "03 0000 0001"))
            else:
                burst.append(rng.choice(choices))
        bursts.append(burst)
    return bursts


async def _run(
    seed: int, shortcut: bool, monkeypatch: pytest.MonkeyPatch, *, pushed: bool = False
) -> tuple[object, ...]:
    if not shortcut:
        monkeypatch.setattr(aiortu.gateway._server, "answered_from_callback", lambda _: False)
    taken = 0
    if pushed:
        predicate = aiortu.gateway._server.accepted_in_callback

        def counted(connection: Any, chunk: bytes) -> Any:
            nonlocal taken
            adu = predicate(connection, chunk)
            taken += adu is not None
            return adu

        monkeypatch.setattr(aiortu.gateway._server, "accepted_in_callback", counted)
    else:
        monkeypatch.setattr(aiortu.gateway._open, "push_listener", lambda _: False)
    rng = random.Random(seed)
    sessions = [_session(rng, index) for index in range(CLIENTS)]
    store = _store()
    replies: list[list[tuple[int, int, str]]] = [[] for _ in range(CLIENTS)]
    async with line({UNIT: store}, max_in_flight=3) as bench:

        async def play(index: int) -> None:
            async with client(bench.gateway) as tcp:
                transaction_id = 0
                for burst in sessions[index]:
                    for unit, pdu in burst:
                        transaction_id += 1
                        await tcp.send(pdu, unit, transaction_id)
                    for _ in burst:
                        reply = await tcp.receive()
                        assert reply is not None
                        replies[index].append((reply.transaction_id, reply.unit, reply.pdu.hex()))

        with anyio.fail_after(20):
            async with anyio.create_task_group() as group:
                for index in range(CLIENTS):
                    group.start_soon(play, index)
        counters = bench.gateway.counters
        handed = counters.transactions + counters.coalesced
        registers = store.get("holding_registers", 0, 100)
    monkeypatch.undo()
    if pushed:
        assert taken > 0, "the read callback took no request"
    return replies, counters.requests, handed, registers


@pytest.mark.parametrize("offset", range(3))
async def test_reads_answered_from_callbacks_agree_with_reads_on_workers(
    offset: int, monkeypatch: pytest.MonkeyPatch
) -> None:
    seed = SEED + offset
    try:
        shortcut = await _run(seed, True, monkeypatch)
        general = await _run(seed, False, monkeypatch)
        assert _by_id(shortcut) == _by_id(general)
    except BaseException:
        print(f"gateway differential seed {seed} (AIORTU_GATEWAY_DIFFERENTIAL_SEED={seed})")
        raise


def _by_id(outcome: tuple[object, ...]) -> tuple[object, ...]:
    """`outcome` with each client's replies in transaction id order."""
    replies, *rest = outcome
    assert isinstance(replies, list)
    return ([sorted(each) for each in replies], *rest)


@pytest.mark.parametrize("offset", range(3))
async def test_requests_taken_in_the_read_callback_agree_with_the_reader_task(
    offset: int, monkeypatch: pytest.MonkeyPatch
) -> None:
    # The `tcp://` listener's pushed connections (the read callback takes a request when
    # `accepted_in_callback` allows) against anyio's streams (the reader task takes them all),
    # with the read shortcut on and off.
    seed = SEED + offset
    try:
        for shortcut in (True, False):
            pushed = await _run(seed, shortcut, monkeypatch, pushed=True)
            general = await _run(seed, shortcut, monkeypatch)
            assert _by_id(pushed) == _by_id(general)
    except BaseException:
        print(f"gateway differential seed {seed} (AIORTU_GATEWAY_DIFFERENTIAL_SEED={seed})")
        raise

"""The pushed connections' own TLS layer against the general path (anyio's TLS stream and
listener), both ends and both mixes: the same seeded scripts of requests by role give the same
replies, refusals, counters and final registers on all four pairs; a refused certificate gives
the same error wherever the server is the same, and names the reason wherever the server is the
pushed one (it sends the alert, anyio's listener does not).

The seed is printed in every failure; `TLS_DIFF_SEED=N` replays one."""

from __future__ import annotations

import os
import random
import re
from typing import Any

import pytest

import aiortu
from aiortu.transport import _push_server as push_server_module
from aiortu.transport import _tcp_push as tcp_push_module
from tests.transport.test_tls import _first_request, pki, tls_master, tls_server

pytestmark = pytest.mark.timeout(120)

__all__ = ("pki",)

PAIRS = [(master, server) for master in (True, False) for server in (True, False)]
"""(the master pushed, the server pushed): the first is asyncio's default."""


def _use(monkeypatch: pytest.MonkeyPatch, master: bool, server: bool) -> None:
    monkeypatch.setattr(tcp_push_module, "push_connections", lambda: master)
    monkeypatch.setattr(push_server_module, "loop_pushes", lambda: server)


def _script(rng: random.Random) -> list[tuple[str, list[tuple[Any, ...]]]]:
    """Sessions: a role and its steps (an operation and its arguments)."""
    sessions = []
    for _ in range(4):
        steps: list[tuple[Any, ...]] = []
        for _ in range(rng.randint(5, 25)):
            unit, address = rng.choice((1, 2)), rng.randint(0, 12)
            kind = rng.choice(("read", "read", "write", "writes", "coils", "coil"))
            if kind == "read":
                steps.append(("read", unit, address, rng.randint(1, 4)))
            elif kind == "write":
                steps.append(("write", unit, address, rng.randint(0, 0xFFFF)))
            elif kind == "writes":
                count = rng.randint(1, 3)
                steps.append(("writes", unit, address, [rng.randint(0, 9) for _ in range(count)]))
            elif kind == "coils":
                steps.append(("coils", unit, rng.randint(0, 18), rng.randint(1, 3)))
            else:
                steps.append(("coil", unit, rng.randint(0, 18), rng.random() < 0.5))
        sessions.append((rng.choice(("operator", "viewer", "unit1")), steps))
    return sessions


async def _step(master: aiortu.Master, step: tuple[Any, ...]) -> Any:
    kind, unit, address, arg = step
    try:
        if kind == "read":
            return await master.read_holding_registers(unit, address, arg)
        if kind == "write":
            return await master.write_register(unit, address, arg)
        if kind == "writes":
            return await master.write_registers(unit, address, arg)
        if kind == "coils":
            return await master.read_coils(unit, address, arg)
        return await master.write_coil(unit, address, arg)
    except aiortu.ExceptionResponse as error:
        return ("exception", error.code)


async def _run(pki: dict[str, Any], script: list[tuple[str, list[tuple[Any, ...]]]]) -> list[Any]:
    seen: list[Any] = []
    async with tls_server(pki) as server:
        for role, steps in script:
            async with tls_master(pki, server, role) as master:
                seen.append([await _step(master, step) for step in steps])
        async with tls_master(pki, server, "operator") as master:
            for unit in (1, 2):
                seen.append(await master.read_holding_registers(unit, 0, 10))
                seen.append(await master.read_coils(unit, 0, 16))
        seen.append((server.denied, server.counters.requests, server.handshake_failures))
        seen.append(server.machine.counters)
    return seen


@pytest.mark.parametrize("round_", range(3))
async def test_the_four_pairs_give_the_same_replies(
    pki: dict[str, Any], monkeypatch: pytest.MonkeyPatch, round_: int
) -> None:
    seed = int(os.environ.get("TLS_DIFF_SEED", random.randrange(2**32)))
    script = _script(random.Random(seed))
    results = {}
    for pair in PAIRS:
        _use(monkeypatch, *pair)
        results[pair] = await _run(pki, script)
    first = results[PAIRS[0]]
    for pair, seen in results.items():
        assert seen == first, f"seed {seed}: (master pushed, server pushed) {pair} differs"
    assert any(isinstance(step, list) for session in first[:4] for step in session), (
        f"seed {seed}: no read at all"
    )


@pytest.mark.parametrize("who", ["expired", "untrusted"])
async def test_a_refused_certificate_is_told_alike_and_named_by_every_server(
    pki: dict[str, Any], monkeypatch: pytest.MonkeyPatch, who: str
) -> None:
    told = {}
    for pair in PAIRS:
        _use(monkeypatch, *pair)
        async with tls_server(pki) as server:
            error = await _first_request(pki, server.port, who)
            assert server.handshake_failures == 1
        assert type(error) is aiortu.ConnectionLost, (pair, repr(error))
        told[pair] = re.sub(r"127\.0\.0\.1:\d+", "SERVER", str(error))
    # The pushed server's own TLS layer and anyio's stream both send the alert first.
    assert len(set(told.values())) == 1, told
    assert "the server refused this client's certificate: " in told[PAIRS[0]], told

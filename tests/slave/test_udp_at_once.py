"""The Modbus UDP server's answer-at-once changes nothing but its cost: a differential test,
and the shortcut's conditions one by one.

Seeded random bursts of request datagrams (every function code, broadcasts, unit aliases, a
unit nobody serves, a unit whose store takes no fast path, malformed PDUs, listen-only mode,
a handler that awaits and one whose reply waits, hooks and a trace switched on and off) go to
the same server three ways: pushed with the shortcut on, pushed with it off (every request by
the general route, through the server's task), and on a socket read by a task
(`serve_datagrams`, as under trio). Every run must give the same replies in the same order,
the same stores, counters and comm event log.

A failure names its seed; ``AIORTU_DIFFERENTIAL_SEED=N`` runs that seed alone.
"""

from __future__ import annotations

import dataclasses
import logging
import random
from typing import Any

import anyio
import anyio.abc
import pytest

import aiortu
from aiortu.core.codes import FunctionCode
from aiortu.core.mbap import Adu, decode_adu, encode_adu
from aiortu.core.pdu import RawPDU
from aiortu.slave import BUILTIN_HANDLERS, MemoryStore, ModbusUdpServer, Reply, Table
from aiortu.slave import _udp_server as udp_server_module
from aiortu.transport import DatagramCounters, DatagramServer
from tests.slave.test_fast_path_differential import SEEDS, _pdu, _SlowStore, _store

pytestmark = pytest.mark.timeout(60)

FAST = 17
"""A unit whose MemoryStore the fast paths serve (also answered as unit id 255)."""
SLOW = 18
"""A unit whose store (a MemoryStore subclass) always takes the general route."""
NOBODY = 5
"""A unit id the server does not serve: exception 0B, whatever the server's mode."""
BURSTS = 100


async def _awaiting(request: Any, context: Any) -> Any:
    """A handler that awaits: the machine is mid-request while later datagrams arrive."""
    await anyio.sleep(0.002)
    return RawPDU(0x41, b"\x01")


def _delayed(request: Any, context: Any) -> Any:
    """Write single coil with a reply that waits: the request is done, its reply not sent."""
    return Reply(BUILTIN_HANDLERS[FunctionCode.WRITE_SINGLE_COIL](request, context), delay=0.002)


def _datagram(rng: random.Random, transaction_id: int) -> bytes:
    roll = rng.random()
    if roll < 0.02:
        return encode_adu(transaction_id, FAST, bytes.fromhex("08 0004 0000"))  # listen-only
    if roll < 0.07:
        return encode_adu(transaction_id, FAST, bytes.fromhex("08 0001 0000"))  # restart
    unit = rng.choices((FAST, SLOW, 0, 255, NOBODY), (70, 12, 6, 6, 6))[0]
    pdu = bytes.fromhex(_pdu(rng))
    if roll < 0.12:
        pdu = pdu[:-1] if len(pdu) > 1 and rng.random() < 0.5 else (pdu + b"\x00")[:253]
    return encode_adu(transaction_id, unit, pdu)


@dataclasses.dataclass
class _Run:
    """What one run gave: the replies of each burst in the order they came, and the
    server's state at the end."""

    replies: list[list[Adu]]
    tables: list[Any]
    machine_counters: Any
    events: list[int]
    requests: int
    datagrams: DatagramCounters
    answered_at_once: int


async def _run(seed: int, way: str, monkeypatch: pytest.MonkeyPatch) -> _Run:
    rng = random.Random(seed)
    monkeypatch.setattr(udp_server_module, "push_datagrams", lambda: way != "socket read by a task")
    units = {FAST: _store(), SLOW: _store(_SlowStore)}
    options: dict[str, Any] = {"unit_aliases": {255: FAST}, "serial_line_codes": True}
    handlers = {0x41: _awaiting, FunctionCode.WRITE_SINGLE_COIL: _delayed}
    replies: list[list[Adu]] = []
    async with aiortu.serve("udp://127.0.0.1:0", units, handlers=handlers, **options) as server:
        assert isinstance(server, ModbusUdpServer)
        server._at_once.enabled = way == "pushed, shortcut on"
        server._hook_removers = []  # type: ignore[attr-defined]
        sock = await anyio.create_udp_socket(local_host="127.0.0.1")
        async with sock:
            transaction_id = 0
            for _ in range(BURSTS):
                _toggle(server, rng)
                for _ in range(rng.choice((1, 1, 2, 3, 5))):
                    transaction_id += 1
                    datagram = _datagram(rng, transaction_id)
                    await sock.sendto(datagram, "127.0.0.1", server.port)
                transaction_id += 1  # answered 0B in every mode, after all the others
                await sock.sendto(
                    encode_adu(transaction_id, NOBODY, bytes.fromhex("03 0000 0001")),
                    "127.0.0.1",
                    server.port,
                )
                replies.append(await _replies_until(sock, transaction_id, seed))
        return _Run(
            replies,
            [
                [b.values for b in store.blocks(table)]
                for store in units.values()
                for table in Table
            ],
            dataclasses.asdict(server.machine.counters),
            server.machine.event_log.events(),
            server.counters.requests,
            server.datagrams,
            server._at_once.answered,
        )


def _toggle(server: ModbusUdpServer, rng: random.Random) -> None:
    """Now and then a hook or a trace for one burst: the general route's alone."""
    server.trace = None
    for remove in server._hook_removers:  # type: ignore[attr-defined]
        remove()
    server._hook_removers = []  # type: ignore[attr-defined]
    roll = rng.random()
    if roll < 0.06:
        server.trace = lambda kind, data: None
    elif roll < 0.12:
        remove = server.before_request(lambda request, context: None)
        server._hook_removers.append(remove)  # type: ignore[attr-defined]


async def _replies_until(sock: anyio.abc.UDPSocket, last: int, seed: int) -> list[Adu]:
    got: list[Adu] = []
    with anyio.fail_after(5):
        while not got or got[-1].transaction_id != last:
            data, _ = await sock.receive()
            got.append(decode_adu(data))
    assert got, f"seed {seed}"
    return got


WAYS = ("pushed, shortcut on", "pushed, shortcut off", "socket read by a task")


@pytest.mark.parametrize("seed", SEEDS)
async def test_the_shortcut_and_the_general_route_agree(
    seed: int, monkeypatch: pytest.MonkeyPatch
) -> None:
    runs = {way: await _run(seed, way, monkeypatch) for way in WAYS}
    on = runs["pushed, shortcut on"]
    for way in WAYS[1:]:
        other = runs[way]
        for burst, (mine, theirs) in enumerate(zip(on.replies, other.replies, strict=True)):
            assert mine == theirs, f"seed {seed}, burst {burst}: {way}"
        assert dataclasses.replace(other, answered_at_once=on.answered_at_once) == on, (
            f"seed {seed}: {way}"
        )
        assert other.answered_at_once == 0, f"seed {seed}: {way}"
    assert on.answered_at_once > BURSTS // 4, f"seed {seed}"


# -- the conditions, one by one ---------------------------------------------------------


def _fresh() -> ModbusUdpServer:
    return ModbusUdpServer({FAST: _store(), SLOW: _store(_SlowStore)}, unit_aliases={255: FAST})


REFUSALS: dict[str, Any] = {
    "a request waiting for the task": lambda s: s._waiting.append(None),
    "a request under way": lambda s: s.machine.frame_received(FAST, 0x03),
    "listen-only mode": lambda s: setattr(s.machine, "listen_only", True),
    "a trace callback": lambda s: setattr(s, "trace", lambda kind, data: None),
    "a before hook": lambda s: s.before_request(lambda request, context: None),
    "an after hook": lambda s: s.after_request(lambda request, context, result: None),
    "the user's handler for the code": lambda s: s.set_handler(0x03, lambda r, c: None),
    "a route on the unit": lambda s: s.route("coils", range(1), lambda access: None),
    "switched off": lambda s: setattr(s._at_once, "enabled", False),
}


@pytest.mark.parametrize("refusal", sorted(REFUSALS))
def test_each_condition_refuses_on_its_own(refusal: str) -> None:
    server = _fresh()
    assert server._at_once.may_answer(FAST, 0x03)
    REFUSALS[refusal](server)
    assert not server._at_once.may_answer(FAST, 0x03)


@pytest.mark.parametrize(
    ("unit", "function_code"),
    [(SLOW, 0x03), (0, 0x03), (NOBODY, 0x03), (255, 0x03), (FAST, 0x05)],
    ids=["not the built-in store", "a broadcast", "not served", "an alias unmapped", "05"],
)
def test_the_predicate_refuses_other_stores_units_and_codes(unit: int, function_code: int) -> None:
    assert not _fresh()._at_once.may_answer(unit, function_code)


def test_a_trace_that_fails_is_detached_and_the_shortcut_comes_back() -> None:
    server = _fresh()

    def failing(kind: str, data: bytes) -> None:
        raise RuntimeError("the trace is broken")

    server.trace = failing
    assert not server._at_once.may_answer(FAST, 0x03)
    server._traced("received", b"\x00")
    assert server.trace is None
    assert server._at_once.may_answer(FAST, 0x03)


async def test_a_read_behind_a_waiting_reply_is_answered_after_it() -> None:
    """A delayed reply's request is done (the machine IDLE) but its reply not sent: a read
    that could be answered at once waits its turn."""
    store = MemoryStore(coils={0: [0] * 8}, holding_registers={0: [4, 5]})
    handlers = {FunctionCode.WRITE_SINGLE_COIL: _delayed}
    async with (
        aiortu.serve("udp://127.0.0.1:0", {1: store}, handlers=handlers) as server,
        await anyio.create_udp_socket(local_host="127.0.0.1") as sock,
    ):
        assert isinstance(server, ModbusUdpServer)
        await sock.sendto(encode_adu(1, 1, bytes.fromhex("05 0000 FF00")), "127.0.0.1", server.port)
        await sock.sendto(encode_adu(2, 1, bytes.fromhex("03 0000 0002")), "127.0.0.1", server.port)
        with anyio.fail_after(5):
            first, second = [decode_adu((await sock.receive())[0]) for _ in range(2)]
    assert (first.transaction_id, second.transaction_id) == (1, 2)
    assert second.pdu == bytes.fromhex("03 04 0004 0005")
    assert server._at_once.answered == 0


async def test_a_read_is_answered_in_the_datagram_callback() -> None:
    store = MemoryStore(holding_registers={0: [4, 5]})
    async with (
        aiortu.serve("udp://127.0.0.1:0", {1: store}) as server,
        aiortu.open_master(f"udp://127.0.0.1:{server.port}", timeout=2.0) as master,
    ):
        assert isinstance(server, ModbusUdpServer)
        assert await master.read_holding_registers(1, 0, 2) == [4, 5]
        assert await master.read_holding_registers(255, 0, 2) == [4, 5]  # an alias
        with pytest.raises(aiortu.ExceptionResponse):
            await master.read_holding_registers(1, 7, 1)  # 02, from the fast path too
    assert server._at_once.answered == 3
    assert server.counters.requests == 3
    assert (server.datagrams.received, server.datagrams.replies) == (3, 3)
    assert server.machine.counters.bus_exception_error_count == 1


async def test_requests_over_the_backlog_are_refused_and_counted(
    caplog: pytest.LogCaptureFixture,
) -> None:
    release = anyio.Event()
    answered: list[int] = []

    async def answer(adu: Adu) -> bytes | None:
        await release.wait()
        answered.append(adu.transaction_id)
        return encode_adu(adu.transaction_id, adu.unit, b"\x03\x00")

    counters = DatagramCounters()
    server = DatagramServer(answer, counters, backlog=4)
    host, port = await server.bind("127.0.0.1", 0)
    caplog.set_level(logging.DEBUG, logger="aiortu")
    async with (
        anyio.create_task_group() as group,
        await anyio.create_udp_socket(local_host="127.0.0.1") as sock,
    ):
        group.start_soon(server.serve)
        for transaction_id in range(7):
            await sock.sendto(encode_adu(transaction_id, 1, b"\x03\x00\x00\x00\x01"), host, port)
        with anyio.fail_after(5):
            while counters.received < 7:  # noqa: ASYNC110 - plain counters, polled
                await anyio.sleep(0.01)
        assert len(server.pending) == 4
        release.set()
        with anyio.fail_after(5):
            got = [decode_adu((await sock.receive())[0]).transaction_id for _ in range(4)]
        group.cancel_scope.cancel()
    assert got == answered == [0, 1, 2, 3]
    assert (counters.received, counters.refused, counters.replies) == (7, 3, 4)
    refusals = [r for r in caplog.records if "fill the backlog" in r.getMessage()]
    assert [r.levelno for r in refusals] == [logging.WARNING, logging.DEBUG, logging.DEBUG]
    assert server.socket is not None
    assert server.socket.closed

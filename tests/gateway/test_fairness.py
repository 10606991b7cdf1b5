"""Round-robin between connections, and identical reads in flight at once coalesced.

Latency is asserted as the number of transactions on the wire, never as time. Tests that give
the gateway time to do what it must not run on a virtual clock, their clients on in-memory
streams."""

from __future__ import annotations

import asyncio
import socket
import struct
from collections.abc import Callable
from contextlib import AsyncExitStack

import anyio
import anyio.abc
import pytest

from aiortu.errors import InvalidValue
from aiortu.gateway import Gateway, Listen, gateway
from aiortu.slave import RequestContext
from tests.gateway.helpers import (
    UNIT,
    Line,
    TcpClient,
    client,
    line,
    memory_client,
    memory_stream,
)
from tests.virtual_clock import on_virtual_clock

pytestmark = pytest.mark.timeout(30)


def _requests_on_wire(bench: Line) -> list[bytes]:
    """The master's frames on the wire so far (unit, function code, ...), oldest first."""
    return [entry.data for entry in bench.bus.trace if entry.sender == 0]


async def _flood(tcp: TcpClient, pipelined: int, stop: anyio.Event) -> None:
    """Keep `pipelined` reads of addresses 0..9 in flight until `stop`."""
    sent = 0
    for _ in range(pipelined):
        await tcp.send(f"03 {sent % 10:04X} 0001", UNIT, sent)
        sent += 1
    while not stop.is_set():
        assert await tcp.receive() is not None
        await tcp.send(f"03 {sent % 10:04X} 0001", UNIT, sent & 0xFFFF)
        sent += 1


class Gate:
    """Holds the slave's next request until opened, so the test sees the queue at rest."""

    def __init__(self) -> None:
        self.opened = anyio.Event()
        self.opened.set()
        self.held = 0

    async def __call__(self, request: object, context: RequestContext) -> None:
        if not self.opened.is_set():
            self.held += 1  # only requests that wait: one let through does not count
            await self.opened.wait()

    def close(self) -> None:
        self.opened = anyio.Event()


async def _until(condition: Callable[[], bool]) -> None:
    # Polls: the conditions are counters of several objects, none of which signals.
    while not condition():  # noqa: ASYNC110
        await anyio.sleep(0.001)


async def test_a_flooding_client_cannot_starve_a_quiet_one() -> None:
    # The flooding client may keep 16 requests waiting; the quiet one sends one at a time.
    gate = Gate()
    slow = {"timeout": 10.0}  # the gate, not a timeout, decides when a request is answered
    async with line(max_in_flight=16, coalesce=False, master_options=slow) as bench:
        bench.slave.before_request(gate)
        async with client(bench.gateway) as flood, client(bench.gateway) as quiet:
            stop = anyio.Event()
            waits = []
            async with anyio.create_task_group() as tasks:
                tasks.start_soon(_flood, flood, 16, stop)
                for round_ in range(5):
                    # The line stuck on one of the flood's requests, its others queued...
                    gate.close()
                    held = gate.held
                    await _until(
                        lambda h=held: gate.held > h and bench.gateway.counters.requests >= 16
                    )
                    # ... the quiet client's request arrives.
                    requests = bench.gateway.counters.requests
                    await quiet.send("03 000F 0001", UNIT, 900 + round_)
                    await _until(lambda r=requests: bench.gateway.counters.requests > r)
                    before = len(_requests_on_wire(bench))
                    gate.opened.set()
                    reply = await quiet.receive()
                    assert reply is not None
                    assert reply.pdu.hex(" ") == "03 02 00 00"
                    wire = _requests_on_wire(bench)
                    # The quiet read's place among the requests sent since it was queued.
                    quiet_frame = next(i for i in range(before, len(wire)) if wire[i][3] == 0x0F)
                    waits.append(quiet_frame - before)
                stop.set()
        # The quiet read takes the line's current turn: it goes next, before every queued
        # request of the flooding client (never behind its whole queue of 16).
        assert max(waits) == 0, waits


async def test_identical_reads_in_flight_at_once_are_one_transaction() -> None:
    gate = Gate()
    clients = 8
    async with line(master_options={"timeout": 10.0}) as bench:
        bench.slave.before_request(gate)
        async with AsyncExitStack() as stack:
            tcps = [await stack.enter_async_context(client(bench.gateway)) for _ in range(clients)]
            gate.close()
            for index, tcp in enumerate(tcps):
                await tcp.send("03 0000 0003", UNIT, 100 + index)
            # Every read but the first joins the one on the line.
            await _until(lambda: bench.gateway.counters.coalesced == clients - 1)
            gate.opened.set()
            for index, tcp in enumerate(tcps):
                reply = await tcp.receive()
                assert reply is not None
                assert reply.transaction_id == 100 + index
                assert reply.pdu.hex(" ").upper() == "03 06 12 34 AB CD 00 07"
        assert bench.messages == 1
        assert bench.gateway.counters.transactions == 1


async def test_writes_are_never_coalesced_and_end_the_sharing() -> None:
    async with line() as bench, client(bench.gateway) as a, client(bench.gateway) as b:
        for tcp, transaction_id in ((a, 1), (b, 2), (a, 3)):
            await tcp.send("06 0000 0001", UNIT, transaction_id)
        for tcp in (a, b, a):
            reply = await tcp.receive()
            assert reply is not None
            assert reply.pdu.hex() == "0600000001"
        assert bench.messages == 3
        assert bench.gateway.counters.coalesced == 0


@on_virtual_clock
async def test_pipelining_is_bounded_per_connection() -> None:
    gate = Gate()
    async with line(max_in_flight=2, master_options={"timeout": 10.0}, listen=()) as bench:
        bench.slave.before_request(gate)
        async with memory_client(bench.gateway) as tcp:
            gate.close()
            for transaction_id in range(5):
                await tcp.send("03 0000 0001", UNIT, transaction_id)
            await _until(lambda: bench.gateway.counters.requests == 2)
            await anyio.sleep(5)  # time for a third to be taken, were it allowed
            assert bench.gateway.counters.requests == 2
            gate.opened.set()
            replies = [await tcp.receive() for _ in range(5)]
            assert [reply.transaction_id for reply in replies if reply] == [0, 1, 2, 3, 4]


async def test_a_connection_runs_its_requests_on_at_most_max_in_flight_tasks(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    tasks: set[asyncio.Task[object] | None] = set()
    request = Gateway._request

    async def spied(self: Gateway, *args: object) -> None:
        tasks.add(asyncio.current_task())
        await request(self, *args)  # type: ignore[arg-type]

    monkeypatch.setattr(Gateway, "_request", spied)
    async with line(max_in_flight=3) as bench:
        async with client(bench.gateway) as tcp:
            # Writes: a read the engine runs itself is answered from a callback, on no task.
            for transaction_id in range(10):
                assert await tcp.request("06 0000 0001", UNIT, transaction_id)
            assert len(tasks) == 1  # one after the other: one worker
            for _ in range(5):
                for transaction_id in range(6):
                    await tcp.send("06 0000 0001", UNIT, transaction_id)
                replies = [await tcp.receive() for _ in range(6)]
                assert [reply.transaction_id for reply in replies if reply] == list(range(6))
            assert len(tasks) <= 3
        assert bench.gateway.counters.requests == 40


async def test_reads_on_a_line_with_an_event_loop_run_on_no_task(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    # The engine runs each read itself (the fast path, or its line task) and completes a
    # future: the gateway answers from its done-callback, and no worker awaits a request (a
    # pushed connection keeps one parked, for the requests its read callback hands on).
    workers: list[object] = []
    request = Gateway._request

    async def spied(self: Gateway, *args: object) -> None:
        workers.append(args)
        await request(self, *args)  # type: ignore[arg-type]

    monkeypatch.setattr(Gateway, "_request", spied)
    async with line(max_in_flight=3) as bench:
        async with client(bench.gateway) as a, client(bench.gateway) as b:
            for _ in range(5):
                for transaction_id in range(3):
                    await a.send(f"03 {transaction_id:04X} 0001", UNIT, transaction_id)
                    await b.send(f"04 {transaction_id:04X} 0001", UNIT, transaction_id)
                for tcp in (a, b):
                    replies = [await tcp.receive() for _ in range(3)]
                    assert [reply.transaction_id for reply in replies if reply] == [0, 1, 2]
        assert bench.gateway.counters.requests == 30
        assert bench.gateway.counters.transactions == 30
    assert workers == []


async def test_a_listener_with_a_lower_priority_value_goes_first() -> None:
    gate = Gate()
    listens = (Listen("tcp://127.0.0.1:0"), Listen("tcp://127.0.0.1:0", priority=-1))
    slow = {"timeout": 10.0}
    async with line(listen=listens, max_in_flight=8, coalesce=False, master_options=slow) as bench:
        bench.slave.before_request(gate)
        port = bench.gateway.local_addresses[1][1]
        async with client(bench.gateway) as busy, await anyio.connect_tcp("127.0.0.1", port) as raw:
            urgent = TcpClient(raw)
            gate.close()
            for transaction_id in range(8):
                await busy.send(f"03 {transaction_id:04X} 0001", UNIT, transaction_id)
            await _until(lambda: gate.held == 1 and bench.gateway.counters.requests == 8)
            await urgent.send("03 000F 0001", UNIT, 99)
            await _until(lambda: bench.gateway.counters.requests == 9)
            before = len(_requests_on_wire(bench))
            gate.opened.set()
            assert (await urgent.receive()) is not None
            wire = _requests_on_wire(bench)
            urgent_frame = next(i for i in range(before, len(wire)) if wire[i][3] == 0x0F)
            # Nothing goes before it but the request on the line: the busy listener's
            # queued requests all wait in the engine's queue behind it.
            assert urgent_frame - before == 0


@pytest.mark.parametrize("priority", ["1", 1.5, True, None])
async def test_a_priority_that_is_no_int_is_refused_before_anything_opens(priority: object) -> None:
    listen = Listen("tcp://127.0.0.1:0", priority=priority)  # type: ignore[arg-type]
    refused = r"^priority must be an int \(lower values go first\), not "
    with pytest.raises(InvalidValue, match=refused):
        async with gateway("/dev/null-not-opened", [listen]):
            pass


@on_virtual_clock
async def test_a_read_sent_after_a_write_never_joins_a_read_from_before_it() -> None:
    # Every request is handed to the engine as it comes: a read arrives while an identical one
    # is on the line and a write waits between them; it must not share the older read's reply.
    gate = Gate()
    async with line(master_options={"timeout": 10.0}, listen=()) as bench:
        bench.slave.before_request(gate)
        async with (
            memory_client(bench.gateway) as x,
            memory_client(bench.gateway) as a,
            memory_client(bench.gateway) as b,
        ):
            gate.close()
            await x.send("03 0000 0001", UNIT, 1)
            await _until(lambda: gate.held == 1)
            await a.send("06 0000 0042", UNIT, 2)
            await _until(lambda: bench.gateway.counters.transactions == 2)
            await b.send("03 0000 0001", UNIT, 3)
            await _until(lambda: bench.gateway.counters.requests == 3)
            await anyio.sleep(5)  # time for the read to be handed on
            gate.opened.set()
            old, new = await x.receive(), await b.receive()
            assert old is not None
            assert new is not None
            assert (old.pdu.hex(" "), new.pdu.hex(" ")) == ("03 02 12 34", "03 02 00 42")
            assert bench.gateway.counters.coalesced == 0


async def test_a_client_that_resets_has_its_queued_reads_dropped_before_the_line() -> None:
    # A's read holds the line; B's reads queue behind it, answered from callbacks; B resets
    # its connection: none of them reaches the line, and the line goes on.
    gate = Gate()
    async with line(max_in_flight=4, master_options={"timeout": 10.0}) as bench:
        bench.slave.before_request(gate)
        async with client(bench.gateway) as a:
            gate.close()
            await a.send("03 0000 0001", UNIT, 1)
            await _until(lambda: gate.held == 1)
            stream = await anyio.connect_tcp("127.0.0.1", bench.gateway.port)
            b = TcpClient(stream)
            for transaction_id in range(3):
                await b.send(f"03 {transaction_id + 1:04X} 0001", UNIT, transaction_id)
            await _until(lambda: bench.master.engine.queued == 3)
            raw = stream.extra(anyio.abc.SocketAttribute.raw_socket)
            raw.setsockopt(socket.SOL_SOCKET, socket.SO_LINGER, struct.pack("ii", 1, 0))
            await stream.aclose()  # a reset, not an end of stream
            await _until(lambda: bench.gateway.connections == 1)
            gate.opened.set()
            assert await a.receive() is not None
            assert await a.request("03 0005 0001", UNIT, 2)
        assert bench.messages == 2  # A's two reads; none of B's
        assert not bench.master.engine.busy


async def test_a_read_that_joined_another_is_not_answered_once_its_client_reset() -> None:
    # A's read holds the line; B's identical read joins it; B resets: A's reply is the only
    # one counted (and sent).
    gate = Gate()
    async with line(master_options={"timeout": 10.0}) as bench:
        bench.slave.before_request(gate)
        async with client(bench.gateway) as a:
            gate.close()
            await a.send("03 0000 0001", UNIT, 1)
            await _until(lambda: gate.held == 1)
            stream = await anyio.connect_tcp("127.0.0.1", bench.gateway.port)
            await TcpClient(stream).send("03 0000 0001", UNIT, 7)
            await _until(lambda: bench.gateway.counters.coalesced == 1)
            raw = stream.extra(anyio.abc.SocketAttribute.raw_socket)
            raw.setsockopt(socket.SOL_SOCKET, socket.SO_LINGER, struct.pack("ii", 1, 0))
            await stream.aclose()
            await _until(lambda: bench.gateway.connections == 1)
            gate.opened.set()
            assert await a.receive() is not None
        statistics = bench.gateway.statistics
        (unit,) = statistics.units.values()
        assert (unit.requests, unit.replies) == (2, 1)
        assert statistics.clients["127.0.0.1"].replies == 1


async def test_requests_sent_one_by_one_never_overfill_the_window() -> None:
    # The line is held; the client sends six reads, each in a segment of its own, which a
    # pushed connection's read callback sees one by one: the gateway takes three (its window)
    # and reads nothing more until one is answered.
    gate = Gate()
    async with line(max_in_flight=3, coalesce=False, master_options={"timeout": 10.0}) as bench:
        bench.slave.before_request(gate)
        async with client(bench.gateway) as tcp:
            gate.close()
            for transaction_id in range(6):
                await tcp.send(f"03 {transaction_id:04X} 0001", UNIT, transaction_id)
                await anyio.sleep(0.02)  # a segment of its own (at least, most likely)
            await _until(lambda: bench.gateway.counters.requests == 3)
            await anyio.sleep(0.1)  # time to take more, were the window not kept
            assert bench.gateway.counters.requests == 3
            gate.opened.set()
            replies = [await tcp.receive() for _ in range(6)]
            assert sorted(reply.transaction_id for reply in replies if reply) == list(range(6))
        assert bench.gateway.counters.requests == 6


async def test_a_connection_served_without_a_priority_goes_before_priority_1() -> None:
    gate = Gate()
    slow = {"timeout": 10.0}
    async with line(listen=(), max_in_flight=8, coalesce=False, master_options=slow) as bench:
        bench.slave.before_request(gate)
        async with (
            memory_client(bench.gateway) as busy,
            memory_stream(bench.gateway, priority=1) as far,
        ):
            late = TcpClient(far)
            gate.close()
            for transaction_id in range(8):
                await busy.send(f"03 {transaction_id:04X} 0001", UNIT, transaction_id)
            await _until(lambda: gate.held == 1 and bench.gateway.counters.requests == 8)
            await late.send("03 000F 0001", UNIT, 99)
            await _until(lambda: bench.gateway.counters.requests == 9)
            before = len(_requests_on_wire(bench))
            gate.opened.set()
            assert (await late.receive()) is not None
            wire = _requests_on_wire(bench)
            # The default priority is 0: the seven queued requests of the connection served
            # without one all go before the priority-1 request, fair turns notwithstanding.
            assert next(i for i in range(before, len(wire)) if wire[i][3] == 0x0F) == before + 7

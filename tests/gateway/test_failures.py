"""Exceptions 0B and 0A, and the clients the gateway closes: malformed, idle, one too many.

The tests of times run on a virtual clock, their clients on in-memory streams; the limit on
connections is the listener's, over TCP."""

from __future__ import annotations

import anyio
import anyio.abc
import pytest

from aiortu.core.mbap import encode_adu
from aiortu.slave import Slave
from aiortu.testing import VirtualBus
from tests.gateway.helpers import UNIT, Line, client, device, line, memory_client
from tests.virtual_clock import on_virtual_clock

pytestmark = pytest.mark.timeout(30)

DEAD = 18


def _frames_to(bench: Line, unit: int) -> int:
    return sum(1 for entry in bench.bus.trace if entry.sender == 0 and entry.data[0] == unit)


@on_virtual_clock
async def test_a_dead_unit_gets_0b_after_its_timeout_then_at_once_while_offline() -> None:
    health = {"offline_after": 2, "probe_interval": 60.0}
    async with line(master_options=health, listen=()) as bench, memory_client(bench.gateway) as tcp:
        # The response timeout starts once the request has left the wire; the second
        # request goes out after the silence kept after a failure.
        wire = 8 * bench.master.settings.char_time
        waits = bench.master.timeout + wire
        guard = bench.master.config.timings.late_reply_guard
        for transaction_id, expected in ((1, waits), (2, guard + waits)):
            asked = anyio.current_time()
            assert await tcp.request("03 0000 0001", DEAD, transaction_id) == "83 0B"
            assert anyio.current_time() - asked == pytest.approx(expected, abs=1e-9)
        assert _frames_to(bench, DEAD) == 2
        assert not bench.master.is_online(DEAD)
        # Offline: refused at once, without a transaction on the line.
        asked = anyio.current_time()
        assert await tcp.request("03 0000 0001", DEAD, 3) == "83 0B"
        assert await tcp.request("10 0000 0001 02 0001", DEAD, 4) == "90 0B"
        assert anyio.current_time() == asked
        assert _frames_to(bench, DEAD) == 2
        # The unit that answers is not held up by the dead one.
        assert await tcp.request("03 0000 0001", UNIT, 5) == "03 02 12 34"


@on_virtual_clock
async def test_a_port_gone_gets_0a() -> None:
    async with line(listen=()) as bench, memory_client(bench.gateway) as tcp:
        assert await tcp.request("03 0000 0001", UNIT, 1) == "03 02 12 34"
        bench.bus.endpoints[0].close()  # the master's port disappears
        with anyio.fail_after(5):
            # The master has no event for it; the line task notices soon.
            while bench.master.connected:  # noqa: ASYNC110
                await anyio.sleep(0.01)
        asked = anyio.current_time()
        assert await tcp.request("03 0000 0001", UNIT, 2) == "83 0A"
        assert await tcp.request("41 00", UNIT, 3) == "C1 0A"
        assert anyio.current_time() == asked  # at once, not after a timeout


@pytest.mark.parametrize(
    "header",
    [
        "0001 0001 0006 11",  # protocol id 1
        "0001 0000 0200 11",  # length 512: longer than any ADU
        "0001 0000 0001 11",  # length 1: no PDU
    ],
)
async def test_a_malformed_header_closes_that_connection_only(header: str) -> None:
    async with line() as bench, client(bench.gateway) as good, client(bench.gateway) as bad:
        await bad.stream.send(bytes.fromhex(header) + bytes(8))
        assert await bad.closed_by_server()
        assert bench.gateway.counters.connections_malformed == 1
        assert await good.request("03 0001 0001", UNIT, 9) == "03 02 AB CD"
        assert bench.messages == 1


async def test_connections_over_the_limit_are_closed_at_once() -> None:
    async with line(max_connections=1) as bench, client(bench.gateway) as first:
        assert await first.request("03 0000 0001", UNIT) == "03 02 12 34"
        async with client(bench.gateway) as second:
            assert await second.closed_by_server()
        assert bench.gateway.counters.connections_refused == 1
        assert await first.request("03 0000 0001", UNIT) == "03 02 12 34"


@on_virtual_clock
async def test_an_idle_connection_is_closed_after_exactly_idle_timeout() -> None:
    idle = 0.1
    async with line(idle_timeout=idle, listen=()) as bench, memory_client(bench.gateway) as tcp:
        await anyio.sleep(0.75 * idle)
        assert await tcp.request("03 0000 0001", UNIT) == "03 02 12 34"
        answered = anyio.current_time()
        assert await tcp.closed_by_server()
        # Silent since its reply: closed idle_timeout after it, not after it connected.
        assert anyio.current_time() - answered == pytest.approx(idle, abs=1e-9)
        assert bench.gateway.counters.connections_idle == 1


@on_virtual_clock
async def test_a_reply_goes_only_to_the_connection_that_asked() -> None:
    # Two clients use the same transaction id for different reads: each gets its own.
    async with (
        line(listen=()) as bench,
        memory_client(bench.gateway) as a,
        memory_client(bench.gateway) as b,
    ):
        await a.stream.send(encode_adu(7, UNIT, bytes.fromhex("03 0000 0001")))
        await b.stream.send(encode_adu(7, UNIT, bytes.fromhex("03 0001 0001")))
        reply_a, reply_b = await a.receive(), await b.receive()
        assert reply_a is not None
        assert reply_b is not None
        assert (reply_a.pdu.hex(), reply_b.pdu.hex()) == ("03021234", "0302abcd")
        assert await a.receive(wait=0.2) is None
        assert await b.receive(wait=0.2) is None
        assert bench.messages == 2


@on_virtual_clock
async def test_0a_at_once_while_the_port_is_reopened_then_served_again() -> None:
    # The port comes back as a new line with the same device on it, when the test says so.
    spare = VirtualBus(2)
    back = anyio.Event()

    async def reopen() -> anyio.abc.ByteStream:
        await back.wait()
        return spare.endpoints[0]

    options = {"opener": reopen, "reconnect": True, "reconnect_delay": (0.01, 0.01)}
    async with (
        line(master_options=options, listen=()) as bench,
        memory_client(bench.gateway) as tcp,
        Slave(spare.endpoints[1], {UNIT: device()}, frame_gap=0.0),
    ):
        assert await tcp.request("03 0000 0001", UNIT, 1) == "03 02 12 34"
        bench.bus.endpoints[0].close()  # the adapter is unplugged
        with anyio.fail_after(5):
            while bench.master.connected:  # noqa: ASYNC110  # no event to wait on
                await anyio.sleep(0.01)
        asked = anyio.current_time()
        for transaction_id in (2, 3):
            assert await tcp.request("03 0000 0001", UNIT, transaction_id) == "83 0A"
        assert anyio.current_time() == asked  # at once, while the port is reopened
        back.set()
        with anyio.fail_after(5):
            while not bench.master.connected:  # noqa: ASYNC110
                await anyio.sleep(0.01)
        await anyio.sleep(0.02)  # the new line's receivers past their first silence
        assert await tcp.request("03 0000 0001", UNIT, 4) == "03 02 12 34"


@on_virtual_clock
async def test_a_request_that_may_not_be_broadcast_is_not_sent_to_unit_0() -> None:
    async with line(listen=()) as bench, memory_client(bench.gateway) as tcp:
        await tcp.send("03 0000 0001", unit=0, transaction_id=1)
        asked = anyio.current_time()
        reply = await tcp.receive(wait=0.3)
        assert reply is not None
        assert anyio.current_time() == asked  # at once, not a wait
        assert reply.pdu.hex(" ") == "83 01"
        assert bench.gateway.counters.broadcasts == 0
        assert not [entry for entry in bench.bus.trace if entry.sender == 0]

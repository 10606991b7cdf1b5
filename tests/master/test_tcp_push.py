"""The pushed Modbus TCP master stream against the general path: the master-side tests of
test_tcp_master.py run again with the general path forced, one scripted exchange (lost replies,
stale and unknown transaction ids, replies split across writes and joined in one, a malformed
header) gives the same results, counters and requests on the wire through both, and a server
that stops reading holds the pushed stream's writes back."""

from __future__ import annotations

import dataclasses
import random
from typing import Any

import anyio
import anyio.abc
import pytest

import aiortu
from aiortu.core.mbap import Adu
from aiortu.errors import PortNotFound
from aiortu.transport import ModbusTcpCounters, ModbusTcpStream, PushConnectionStream
from aiortu.transport import _tcp_push as tcp_push_module
from tests.master.test_tcp_master import (
    FAST,
    fake_server,
    registers,
    test_a_late_reply_after_a_timeout_never_answers_the_next_request,
    test_a_malformed_header_closes_the_connection_and_the_master_reconnects,
    test_a_reply_with_another_transaction_id_is_dropped_and_counted,
    test_a_server_that_never_answers_times_out,
    test_every_master_method_against_the_modbus_tcp_server,
    test_many_callers_share_one_connection,
    test_nothing_listening_is_a_port_error,
    test_the_master_reconnects_when_the_server_closes_the_connection,
    test_unit_ids_255_and_0_are_unicasts_over_modbus_tcp,
    until,
    url,
)

pytestmark = pytest.mark.timeout(30)

__all__ = (  # run again here, on the general path
    "test_a_late_reply_after_a_timeout_never_answers_the_next_request",
    "test_a_malformed_header_closes_the_connection_and_the_master_reconnects",
    "test_a_reply_with_another_transaction_id_is_dropped_and_counted",
    "test_a_server_that_never_answers_times_out",
    "test_every_master_method_against_the_modbus_tcp_server",
    "test_many_callers_share_one_connection",
    "test_nothing_listening_is_a_port_error",
    "test_the_master_reconnects_when_the_server_closes_the_connection",
    "test_unit_ids_255_and_0_are_unicasts_over_modbus_tcp",
)


@pytest.fixture(autouse=True)
def general_path(monkeypatch: pytest.MonkeyPatch) -> None:
    """The general path (anyio's stream read by the link's task), on asyncio too."""
    monkeypatch.setattr(tcp_push_module, "push_connections", lambda: False)


async def _scripted(seed: int) -> tuple[list[Any], dict[str, int], list[int], int]:
    """One run of the scripted exchange: what the master got, its counters, the transaction
    ids the server saw and the master's reconnects."""
    rng = random.Random(seed)
    seen: list[int] = []

    async def answer(stream: anyio.abc.SocketStream, adu: Adu) -> None:
        seen.append(adu.transaction_id)
        reply = registers(adu, adu.transaction_id, len(seen))
        turn = rng.randrange(6)
        if len(seen) == 5:  # a malformed header: the connection closes
            await stream.send(b"\x00\x00\x00\x07\x00\x03\x01\x03\x00")
            return
        if turn == 0:
            return  # lost: the master times out, and retries
        if turn == 1 and len(seen) > 1:  # a late reply to the request before, then this one
            late = Adu(seen[-2], adu.unit, adu.pdu)
            await stream.send(registers(late, 666, 666) + reply)
            return
        if turn == 2:  # an id never sent
            await stream.send(registers(Adu(0xBEEF, adu.unit, adu.pdu), 7, 7))
        if turn == 3:  # split across two writes
            await stream.send(reply[:5])
            await anyio.sleep(0.01)
            await stream.send(reply[5:])
            return
        await stream.send(reply)

    results: list[Any] = []
    async with (
        fake_server(answer) as port,
        aiortu.open_master(url(port), **{**FAST, "timeout": 0.1, "retries": 2}) as master,
    ):
        for _ in range(16):
            await master.connection.wait_connected()
            try:
                results.append(await master.read_holding_registers(1, 0, 2))
            except aiortu.ResponseTimeout:
                results.append("ResponseTimeout")
            except aiortu.ConnectionLost:
                results.append("ConnectionLost")
                await until(lambda: master.connection.reconnects == 1)
        stream = master.link.stream
        assert isinstance(stream, ModbusTcpStream | PushConnectionStream)
        counters = dataclasses.asdict(stream.counters)
        reconnects = master.connection.reconnects
    return results, counters, seen, reconnects


@pytest.mark.parametrize("seed", [1, 2, 3, 4])
async def test_the_pushed_stream_and_the_general_path_agree(
    seed: int, monkeypatch: pytest.MonkeyPatch
) -> None:
    general = await _scripted(seed)
    monkeypatch.setattr(tcp_push_module, "push_connections", lambda: True)
    pushed = await _scripted(seed)
    assert pushed == general, f"seed {seed}"
    results, _, _, reconnects = pushed
    assert "ConnectionLost" in results
    assert reconnects == 1
    assert sum(isinstance(result, list) for result in results) >= 8


async def test_asyncio_gets_the_pushed_stream(monkeypatch: pytest.MonkeyPatch) -> None:
    store = aiortu.MemoryStore(holding_registers={0: [4, 5]})
    async with aiortu.serve("tcp://127.0.0.1:0", {1: store}) as server:
        async with aiortu.open_master(url(server.port), timeout=1.0) as master:
            assert isinstance(master.link.stream, ModbusTcpStream)  # forced here
        monkeypatch.setattr(tcp_push_module, "push_connections", lambda: True)
        async with aiortu.open_master(url(server.port), timeout=1.0) as master:
            assert isinstance(master.link.stream, PushConnectionStream)
            assert await master.read_holding_registers(1, 0, 2) == [4, 5]
            assert master.link.stream.counters.replies == 1


async def test_a_server_that_stops_reading_holds_the_pushed_writes_back(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """Writes go out at once while the transport's buffer is below its high-water mark;
    above it `send_nowait` declines and `send()` waits for the drain, and sends it then."""
    monkeypatch.setattr(tcp_push_module, "push_connections", lambda: True)
    received = bytearray()
    reading = anyio.Event()
    both = anyio.Event()

    async def serve(stream: anyio.abc.SocketStream) -> None:
        await reading.wait()
        async with stream:
            while len(received) < 12 * 2:
                received.extend(await stream.receive())
            both.set()
            await anyio.sleep_forever()

    listener = await anyio.create_tcp_listener(local_host="127.0.0.1", local_port=0)
    port = listener.extra(anyio.abc.SocketAttribute.local_port)
    async with listener, anyio.create_task_group() as group:
        group.start_soon(listener.serve, serve)
        stream = await aiortu.transport.open_modbus_tcp("127.0.0.1", port)
        assert isinstance(stream, PushConnectionStream)
        async with stream:
            frame = bytes.fromhex("01 03 0000 0001 840A")
            assert stream.send_nowait(frame)
            stream.protocol.pause_writing()  # as the transport says above its high-water mark
            assert not stream.send_nowait(frame)
            assert stream.counters == ModbusTcpCounters(next_transaction_id=1, requests=1)
            with anyio.move_on_after(0.2) as waited:
                await stream.send(frame)
            assert waited.cancelled_caught, "send() waits for the drain"
            stream.protocol.resume_writing()
            await stream.send(frame)
            reading.set()
            with anyio.fail_after(5):
                await both.wait()
        group.cancel_scope.cancel()
    assert bytes(received[:12]).hex() == "000000000006010300000001"
    assert bytes(received[12:24]).hex() == "000100000006010300000001"


async def test_every_address_of_a_host_is_tried_and_a_refusal_said_in_one_sentence(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """A host with two addresses: the first refuses, the second listens; then both refuse."""
    monkeypatch.setattr(tcp_push_module, "push_connections", lambda: True)
    closed = await anyio.create_tcp_listener(local_host="127.0.0.1", local_port=0)
    refusing = closed.extra(anyio.abc.SocketAttribute.local_port)
    await closed.aclose()
    listener = await anyio.create_tcp_listener(local_host="127.0.0.1", local_port=0)
    listening = listener.extra(anyio.abc.SocketAttribute.local_port)
    real = anyio.getaddrinfo

    async def two_addresses(host: str, port: int, **options: Any) -> Any:
        assert host == "plc.test"
        found = await real("127.0.0.1", refusing, **options)
        return [*found, *await real("127.0.0.1", port, **options)]

    monkeypatch.setattr(anyio, "getaddrinfo", two_addresses)
    async with listener:
        stream = await aiortu.transport.open_modbus_tcp("plc.test", listening)
        assert isinstance(stream, PushConnectionStream)
        await stream.aclose()
        with pytest.raises(PortNotFound) as caught:
            await aiortu.transport.open_modbus_tcp("plc.test", refusing)
    assert str(caught.value) == (
        f"tcp://plc.test:{refusing}: connection refused: nothing listens on that port"
    )

"""Modbus UDP: the master's datagram stream and the server, on loopback."""

from __future__ import annotations

import logging
import random
import re
from collections.abc import AsyncIterator, Awaitable, Callable
from contextlib import asynccontextmanager
from pathlib import Path

import anyio
import anyio.abc
import pytest

import aiortu
from aiortu.core.mbap import Adu, decode_adu, encode_adu
from aiortu.errors import FrameError, PortNotFound, ResponseTimeout
from aiortu.slave import ModbusUdpServer
from aiortu.transport import (
    ModbusTcpAddress,
    ModbusTcpCounters,
    check_datagram,
    open_stream,
    parse_listen_url,
    parse_port_url,
)
from tests.cli.cli_helpers import run_aiortu, start_aiortu, stop

pytestmark = pytest.mark.timeout(30)

READ_REPLY = bytes.fromhex("03 06 00 01 00 02 00 03")

Responder = Callable[[anyio.abc.UDPSocket, Adu, tuple[str, int]], Awaitable[None]]


@asynccontextmanager
async def fake_server(respond: Responder) -> AsyncIterator[int]:
    """A UDP peer on loopback that hands each request to `respond`; yields its port."""
    sock = await anyio.create_udp_socket(local_host="127.0.0.1")
    port = sock.extra(anyio.abc.SocketAttribute.local_port)

    async def loop() -> None:
        async for data, source in sock:
            await respond(sock, decode_adu(data), source)

    async with sock, anyio.create_task_group() as group:
        group.start_soon(loop)
        yield port
        group.cancel_scope.cancel()


def _store() -> aiortu.MemoryStore:
    return aiortu.MemoryStore(holding_registers={0: [1, 2, 3, 0, 0]}, coils={0: [0] * 16})


def test_the_urls_parse() -> None:
    assert parse_port_url("udp://plc:502") == ModbusTcpAddress("plc", 502, "udp")
    assert parse_port_url("TLS://[::1]:802") == ModbusTcpAddress("::1", 802, "tls")
    assert str(parse_port_url("udp://[::1]:1502")) == "udp://[::1]:1502"
    assert parse_listen_url("udp://0.0.0.0:0", ("udp",)).scheme == "udp"
    with pytest.raises(aiortu.InvalidValue, match=r"listens on a tcp:// or rtu\+tcp:// URL"):
        parse_listen_url("udp://0.0.0.0:0")  # the gateway does not listen on UDP yet


async def test_a_master_and_a_server_talk_modbus_udp() -> None:
    store = _store()
    async with aiortu.serve("udp://127.0.0.1:0", {17: store}) as server:
        assert isinstance(server, ModbusUdpServer)
        async with aiortu.open_master(f"udp://127.0.0.1:{server.port}", timeout=1.0) as master:
            await master.write_registers(17, 1, [7, 8])
            assert await master.read_holding_registers(17, 0, 3) == [1, 7, 8]
            with pytest.raises(aiortu.ExceptionResponse) as caught:
                await master.read_holding_registers(17, 100, 1)
            assert caught.value.code == aiortu.ExceptionCode.ILLEGAL_DATA_ADDRESS
            counters = master.link.stream.counters
            assert (counters.requests, counters.replies, counters.strangers) == (3, 3, 0)
        assert (server.datagrams.received, server.datagrams.replies) == (3, 3)
        assert server.counters.requests == 3


async def test_a_datagram_from_a_stranger_is_dropped_and_counted(
    caplog: pytest.LogCaptureFixture,
) -> None:
    stranger = await anyio.create_udp_socket(local_host="127.0.0.1")

    async def respond(sock: anyio.abc.UDPSocket, adu: Adu, source: tuple[str, int]) -> None:
        # The same reply, first from another address, then from the server's.
        reply = encode_adu(adu.transaction_id, adu.unit, READ_REPLY)
        await stranger.sendto(reply, *source)
        await anyio.sleep(0.05)
        await sock.sendto(reply, *source)

    async with stranger, fake_server(respond) as port:
        caplog.set_level(logging.WARNING, logger="aiortu")
        async with aiortu.open_master(f"udp://127.0.0.1:{port}", timeout=1.0) as master:
            assert await master.read_holding_registers(1, 0, 3) == [1, 2, 3]
            counters = master.link.stream.counters
            assert (counters.strangers, counters.replies) == (1, 1)
    (line,) = [r.getMessage() for r in caplog.records if "not the server" in r.getMessage()]
    assert line.startswith(f"udp://127.0.0.1:{port}: dropped a datagram from udp://127.0.0.1:")


@pytest.mark.parametrize(
    "bad",
    [
        pytest.param(lambda reply: reply[:-1], id="truncated"),
        pytest.param(lambda reply: reply + b"\x00", id="longer than its length field"),
        pytest.param(lambda reply: reply + bytes(300), id="oversize"),
        pytest.param(lambda reply: reply[:2] + b"\x00\x01" + reply[4:], id="protocol id"),
    ],
)
async def test_a_malformed_datagram_is_refused_and_the_good_one_taken(
    bad: Callable[[bytes], bytes],
) -> None:
    async def respond(sock: anyio.abc.UDPSocket, adu: Adu, source: tuple[str, int]) -> None:
        reply = encode_adu(adu.transaction_id, adu.unit, READ_REPLY)
        await sock.sendto(bad(reply), *source)
        await sock.sendto(reply, *source)

    async with (
        fake_server(respond) as port,
        aiortu.open_master(f"udp://127.0.0.1:{port}", timeout=1.0) as master,
    ):
        assert await master.read_holding_registers(1, 0, 3) == [1, 2, 3]
        counters = master.link.stream.counters
        assert (counters.refused, counters.replies) == (1, 1)


async def test_a_lost_datagram_is_retried_and_a_late_reply_never_taken() -> None:
    seen: list[int] = []

    async def respond(sock: anyio.abc.UDPSocket, adu: Adu, source: tuple[str, int]) -> None:
        seen.append(adu.transaction_id)
        if len(seen) == 1:
            return  # the first request is lost
        if len(seen) == 3:
            # A reply to the first request, late, before the third's own reply.
            await sock.sendto(encode_adu(seen[0], adu.unit, bytes.fromhex("03 02 FF FF")), *source)
        await sock.sendto(encode_adu(adu.transaction_id, adu.unit, READ_REPLY), *source)

    async with (
        fake_server(respond) as port,
        aiortu.open_master(
            f"udp://127.0.0.1:{port}", timeout=0.2, retries=1, late_reply_guard=0
        ) as master,
    ):
        assert await master.read_holding_registers(1, 0, 3) == [1, 2, 3]
        assert await master.read_holding_registers(1, 0, 3) == [1, 2, 3]
        counters = master.link.stream.counters
    assert seen == [0, 1, 2]
    assert (counters.requests, counters.replies, counters.dropped) == (3, 2, 1)


async def test_nothing_answering_is_a_response_timeout() -> None:
    async def respond(sock: anyio.abc.UDPSocket, adu: Adu, source: tuple[str, int]) -> None:
        pass

    async with (
        fake_server(respond) as port,
        aiortu.open_master(f"udp://127.0.0.1:{port}", timeout=0.1, retries=0) as master,
    ):
        with pytest.raises(ResponseTimeout):
            await master.read_holding_registers(1, 0, 3)


async def test_an_unknown_host_is_a_port_error() -> None:
    with pytest.raises(PortNotFound, match=r"^udp://no-such-host.invalid:502: unknown host"):
        await open_stream("udp://no-such-host.invalid:502")
    with pytest.raises(TypeError, match="Modbus UDP takes no option connect_timeout"):
        await open_stream("udp://127.0.0.1:502", connect_timeout=1)


def test_check_datagram_says_what_is_wrong_in_one_sentence() -> None:
    good = encode_adu(1, 17, bytes.fromhex("03 00 00 00 01"))
    assert check_datagram(good) == Adu(1, 17, bytes.fromhex("03 00 00 00 01"))
    for bad, words in [
        (good[:-1], "length field says 6 bytes follow it, but 5 do"),
        (good + bytes(300), "at most 260 bytes, not 312"),
        (good[:5], "at least 8 bytes"),
    ]:
        with pytest.raises(FrameError, match=words) as caught:
            check_datagram(bad)
        assert "\n" not in str(caught.value)


async def _exchange(sock: anyio.abc.UDPSocket, port: int, datagram: bytes) -> bytes | None:
    await sock.sendto(datagram, "127.0.0.1", port)
    with anyio.move_on_after(0.5):
        data, _ = await sock.receive()
        return data
    return None


async def test_the_server_answers_each_datagram_to_its_source() -> None:
    async with aiortu.serve("udp://127.0.0.1:0", {17: _store()}) as server:
        first = await anyio.create_udp_socket(local_host="127.0.0.1")
        second = await anyio.create_udp_socket(local_host="127.0.0.1")
        async with first, second:
            await first.sendto(
                encode_adu(7, 17, bytes.fromhex("03 00 00 00 01")), "127.0.0.1", server.port
            )
            await second.sendto(
                encode_adu(9, 17, bytes.fromhex("03 00 01 00 01")), "127.0.0.1", server.port
            )
            with anyio.fail_after(2):
                one, _ = await first.receive()
                two, _ = await second.receive()
    assert decode_adu(one) == Adu(7, 17, bytes.fromhex("03 02 00 01"))
    assert decode_adu(two) == Adu(9, 17, bytes.fromhex("03 02 00 02"))


async def test_the_server_refuses_malformed_datagrams_and_keeps_serving(
    caplog: pytest.LogCaptureFixture,
) -> None:
    caplog.set_level(logging.DEBUG, logger="aiortu")
    rng = random.Random(21)
    request = encode_adu(5, 17, bytes.fromhex("03 00 00 00 03"))
    async with aiortu.serve("udp://127.0.0.1:0", {17: _store()}) as server:
        assert isinstance(server, ModbusUdpServer)
        sock = await anyio.create_udp_socket(local_host="127.0.0.1")
        async with sock:
            assert await _exchange(sock, server.port, request[:-1]) is None
            assert await _exchange(sock, server.port, request + bytes(400)) is None
            sent_bad = 2
            for _ in range(200):  # seeded garbage: refused or answered, never a crash
                size = rng.choice([0, 1, 7, 8, 12, 261, 600])
                garbage = bytes(rng.randrange(256) for _ in range(size))
                await sock.sendto(garbage, "127.0.0.1", server.port)
            reply = await _exchange(sock, server.port, request)
            while reply is not None and decode_adu(reply).transaction_id != 5:
                with anyio.move_on_after(0.5):
                    reply, _ = await sock.receive()
            assert reply is not None, "seed 21: the server stopped answering"
            assert decode_adu(reply).pdu == bytes.fromhex("03 06 00 01 00 02 00 03")
        counts = server.datagrams
        assert counts.refused >= sent_bad
        # Datagrams may be lost in a flood (the socket's queue is bounded); none unaccounted.
        assert counts.received <= 203
        assert counts.received == counts.refused + counts.replies
    warnings = [r for r in caplog.records if r.levelno >= logging.WARNING]
    assert len(warnings) == 1, "a flood of bad datagrams logs one warning, then counts"
    assert "Modbus UDP: refused a datagram from udp://127.0.0.1:" in warnings[0].getMessage()


async def test_the_counters_go_on_across_streams() -> None:
    counters = ModbusTcpCounters(next_transaction_id=65535)

    async def respond(sock: anyio.abc.UDPSocket, adu: Adu, source: tuple[str, int]) -> None:
        await sock.sendto(encode_adu(adu.transaction_id, adu.unit, READ_REPLY), *source)

    async with fake_server(respond) as port:
        for _ in range(2):
            stream = await open_stream(f"udp://127.0.0.1:{port}", counters=counters)
            async with stream:
                await stream.send(bytes.fromhex("01 03 00 00 00 03 05 CB"))
                with anyio.fail_after(2):
                    assert (await stream.receive())[:2] == b"\x01\x03"
    assert (counters.next_transaction_id, counters.replies) == (1, 2)


@pytest.mark.parametrize("backend", ["asyncio", "trio"])
def test_modbus_udp_runs_on_both_backends(backend: str) -> None:
    async def scenario() -> None:
        with anyio.fail_after(10):
            async with (
                aiortu.serve("udp://127.0.0.1:0", {17: _store()}) as server,
                aiortu.open_master(f"udp://127.0.0.1:{server.port}", retries=0) as master,
            ):
                await master.write_register(17, 4, 9)
                assert await master.read_holding_registers(17, 2, 3) == [3, 0, 9]

    anyio.run(scenario, backend=backend)


def test_the_command_serves_and_reads_modbus_udp(tmp_path: Path) -> None:
    config = tmp_path / "device.toml"
    config.write_text(
        "[[slave]]\nunit = 17\n[[slave.holding_registers]]\nstart = 0\nvalues = [5, 6, 7]\n",
        encoding="utf-8",
    )
    server = start_aiortu("serve", "udp://127.0.0.1:0", "--config", str(config))
    try:
        assert server.stderr is not None
        first = server.stderr.readline()
        found = re.search(r"on udp://127\.0\.0\.1:0 \(port (\d+)\)", first)
        assert found, first
        read = run_aiortu(
            "read", f"udp://127.0.0.1:{found[1]}", "--unit", "17", "--table", "holding",
            "--address", "0", "--count", "3",
        )  # fmt: skip
        assert read.returncode == 0, read.stderr
        assert read.stdout.split() == ["0", "5", "1", "6", "2", "7"]
    finally:
        stop(server)


async def test_modbus_udp_over_ipv6_loopback() -> None:
    async with (
        aiortu.serve("udp://[::1]:0", {17: _store()}) as server,
        aiortu.open_master(f"udp://[::1]:{server.port}", timeout=1.0) as master,
    ):
        assert await master.read_holding_registers(17, 0, 3) == [1, 2, 3]
        assert master.link.stream.counters.strangers == 0

"""Every listener attacked on loopback, each attack kept as a test (docs/security.md has the
matrix): floods of good requests and of garbage, connections beyond the limit, clients from
thousands of addresses, slowloris, clients that never read, malformed frames of every kind,
TLS on a plain port and plaintext on a TLS port.

Each test asserts what the code guarantees, not what a quiet machine shows: connections refused
beyond the limit, bytes taken under the kernel's buffers, log lines per attack counted, no
traceback, and a well-behaved client answered after the attack (and during it where the limit
leaves room). The attackers are blocking sockets in a worker thread; every loop is bounded."""

from __future__ import annotations

import contextlib
import functools
import logging
import random
import resource
import socket
import ssl
import struct
import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

import anyio
import pytest

from aiortu.core.ascii import encode_ascii_frame
from aiortu.core.mbap import encode_adu
from aiortu.core.rtu import encode_frame
from tests.attacks.listeners import (
    MAX_CONNECTIONS,
    MODBUS_STREAMS,
    NAMES,
    READ_ALL,
    STREAMS,
    Records,
    Target,
    ask,
    listener,
    open_client,
    records,
)
from tests.slave.tcp_helpers import UNIT
from tests.tcp_flood import kernel_buffers, send_until_blocked

pytestmark = pytest.mark.timeout(60)

WARNINGS_PER_ATTACK = 3
"""The most warning lines one attack may cost a listener (the first of a kind is a warning,
the rest go to debug level)."""


async def _answers(target: Target) -> None:
    """A well-behaved client is answered."""
    reply = await anyio.to_thread.run_sync(ask, target)
    assert reply.startswith(target.reply()), f"{target.name}: {reply!r}"


async def _until(condition: Callable[[], bool], seconds: float = 10.0) -> None:
    with anyio.fail_after(seconds):
        while not condition():  # noqa: ASYNC110 - counters of several objects, none signals
            await anyio.sleep(0.01)


def _bounded(target: Target, log: Records) -> None:
    """The attack cost at most `WARNINGS_PER_ATTACK` warnings and no traceback."""
    loud = log.at_least(logging.WARNING)
    assert len(loud) <= WARNINGS_PER_ATTACK, [each.getMessage() for each in loud]
    assert not log.tracebacks, log.tracebacks[0].getMessage()


def _open(target: Target) -> int:
    """The connections the listener serves now."""
    return int(target.server.connections)


@contextmanager
def _file_limit(count: int) -> Iterator[None]:
    """At least `count` file descriptors for this process while the block runs."""
    soft, hard = resource.getrlimit(resource.RLIMIT_NOFILE)
    wanted = min(hard, max(soft, count))
    resource.setrlimit(resource.RLIMIT_NOFILE, (wanted, hard))
    try:
        yield
    finally:
        resource.setrlimit(resource.RLIMIT_NOFILE, (soft, hard))


def _connect_many(target: Target, count: int, hosts: int = 1) -> list[socket.socket]:
    """`count` plain connections to `target`, held open, from `hosts` loopback addresses
    (127.0.x.y); those the backlog cannot take time out and are left out."""
    held = []
    family = socket.AF_UNIX if target.kind == "unix" else socket.AF_INET
    for index in range(count):
        sock = socket.socket(family)
        sock.settimeout(1.0)
        try:
            if hosts > 1:
                host = 2 + index % hosts
                sock.bind((f"127.0.{host >> 8}.{host & 0xFF}", 0))
            sock.connect(target.address)
        except OSError:
            sock.close()
            continue
        held.append(sock)
    return held


def _closed_by_server(held: list[socket.socket]) -> int:
    """How many of `held` the server has closed (an end of stream or a reset waits)."""
    closed = 0
    for sock in held:
        sock.setblocking(False)
        try:
            closed += sock.recv(1, socket.MSG_PEEK) == b""
        except BlockingIOError:
            pass
        except OSError:
            closed += 1
    return closed


def _close_all(held: list[socket.socket]) -> None:
    for sock in held:
        sock.close()


# -- floods -------------------------------------------------------------------------------


def _pipeline(target: Target, count: int) -> int:
    """Send `count` good requests at once on one connection; return the replies read."""
    requests = b"".join(target.request(index) for index in range(count))
    expected = b"".join(target.reply(index) for index in range(count))
    with open_client(target, 10.0) as sock:
        sock.sendall(requests)
        data = b""
        while len(data) < len(expected) and (chunk := sock.recv(65536)):
            data += chunk
    assert data == expected
    return count


@pytest.mark.parametrize("name", MODBUS_STREAMS)
async def test_a_flood_of_good_requests_is_answered_in_full(name: str, tmp_path: Path) -> None:
    async with listener(tmp_path, name) as target:
        with records() as log:
            async with anyio.create_task_group() as tasks:
                for _ in range(4):
                    tasks.start_soon(anyio.to_thread.run_sync, _pipeline, target, 500)
                await _answers(target)  # during the flood
        await _answers(target)
        _bounded(target, log)


@pytest.mark.parametrize("name", ["serve udp", "gateway udp"])
async def test_a_flood_of_datagrams_costs_datagrams_not_memory(name: str, tmp_path: Path) -> None:
    """20,000 requests from one source, none read: the server drops what its backlog cannot
    hold, counts it, and still answers another client."""

    def flood() -> None:
        with open_client(target) as sock:
            for index in range(20_000):
                sock.send(target.request(index & 0xFFFF))

    async with listener(tmp_path, name) as target:
        with records() as log:
            await anyio.to_thread.run_sync(flood)
            await _answers(target)
        counters = target.server.datagrams if name == "serve udp" else None
        if counters is not None:
            assert counters.received <= 20_001
            assert counters.replies + counters.refused + counters.unsent <= counters.received
        _bounded(target, log)


# -- garbage and malformed frames ---------------------------------------------------------

MALFORMED = {
    "mbap": [
        bytes.fromhex("0001 0001 0006 11 03 0000 0001"),  # protocol id 1
        bytes.fromhex("0001 0000 0000 11"),  # length 0
        bytes.fromhex("0001 0000 0001 11"),  # length 1: a unit and no function code
        bytes.fromhex("0001 0000 FFFF 11 03"),  # length 65535
        bytes.fromhex("0001 0000 0106") + bytes(262),  # length 262, over the ADU's 260
        encode_adu(1, UNIT, bytes.fromhex("03 0000")),  # a truncated read
        encode_adu(1, UNIT, bytes.fromhex("00")),  # function code 0
        encode_adu(1, UNIT, bytes.fromhex("80 01")),  # an exception code as a request
        encode_adu(1, UNIT, bytes.fromhex("10 0000 0002 09") + bytes(9)),  # byte count wrong
        encode_adu(1, UNIT, bytes.fromhex("2B 0E 09 00")),  # a bad read device id code
    ],
    "rtu": [
        encode_frame(UNIT, bytes.fromhex("03 0000 0001"))[:-1] + b"\x00",  # a bad CRC
        encode_frame(UNIT, bytes.fromhex("03 0000")),  # a truncated read with its CRC
        encode_frame(UNIT, bytes.fromhex("00")),  # function code 0
        encode_frame(UNIT, bytes.fromhex("41") + bytes(250)),  # a user code, the longest
        encode_frame(UNIT, bytes.fromhex("10 0000 0002 09") + bytes(9)),
        bytes(300),  # zeros past the longest frame
    ],
    "ascii": [
        b":1103000000Z1EB\r\n",  # not hex
        b":11030000000\r\n",  # odd length
        b":110300000001EC\r\n",  # a wrong LRC
        b":" + b"11" * 300 + b"\r\n",  # over the 513 characters
        b":\r\n",  # empty
        b"::::\r\n\r\n",
        encode_ascii_frame(UNIT, bytes.fromhex("00")),
    ],
    "http": [
        b"POST /metrics HTTP/1.0\r\n\r\n",
        b"GET /" + b"x" * 9000 + b" HTTP/1.0\r\n\r\n",
        b"\xff\xfe\r\n\r\n",
        b"GET /metrics\r\n\r\n",
    ],
}


def _send_and_drain(target: Target, data: bytes, seconds: float = 1.0, raw: bool = False) -> None:
    """Send `data` on a new connection (or as one datagram; over TLS inside the session unless
    `raw`) and read what comes back until the server closes or `seconds` of silence."""
    if raw and target.kind == "tls":
        target = Target(target.name, "tcp", target.framing, target.address, target.server)
    try:
        with open_client(target, seconds) as sock:
            sock.sendall(data)
            while sock.recv(65536):
                pass
    except (TimeoutError, ConnectionError, ssl.SSLError):
        pass


async def _drain(target: Target, data: bytes, raw: bool) -> None:
    await anyio.to_thread.run_sync(_send_and_drain, target, data, 0.3, raw)


@pytest.mark.parametrize("name", NAMES)
async def test_malformed_frames_of_every_kind_cost_no_traceback(name: str, tmp_path: Path) -> None:
    async with listener(tmp_path, name) as target:
        with records() as log:
            async with anyio.create_task_group() as tasks:
                for frame in MALFORMED[target.framing]:
                    tasks.start_soon(_drain, target, frame, False)
            await _answers(target)
        assert not log.tracebacks, log.tracebacks[0].getMessage()
        assert len(log.at_least(logging.WARNING)) <= len(MALFORMED[target.framing])


@pytest.mark.parametrize("name", NAMES)
async def test_a_flood_of_garbage_costs_a_few_log_lines(name: str, tmp_path: Path) -> None:
    """Random bytes from 60 clients (seeded): each is closed or ignored, the log holds a few
    warnings, not one per client, and a good client is answered."""
    seed = random.randrange(1 << 32)
    generator = random.Random(seed)
    chunks = [generator.randbytes(generator.randrange(1, 600)) for _ in range(60)]
    async with listener(tmp_path, name) as target:
        with records() as log:
            async with anyio.create_task_group() as tasks:
                for chunk in chunks:
                    tasks.start_soon(_drain, target, chunk, True)
            await _answers(target)
        loud = [each.getMessage() for each in log.at_least(logging.WARNING)]
        assert len(loud) <= WARNINGS_PER_ATTACK, f"seed {seed}: {loud}"
        assert not log.tracebacks, f"seed {seed}"


# -- connections --------------------------------------------------------------------------


@pytest.mark.parametrize("name", STREAMS)
async def test_thousands_of_connections_beyond_the_limit_are_refused(
    name: str, tmp_path: Path
) -> None:
    async with listener(tmp_path, name) as target:
        with _file_limit(4096), records() as log:
            held = await anyio.to_thread.run_sync(_connect_many, target, 2000)
            try:
                assert len(held) > 1000
                await _until(lambda: _closed_by_server(held) >= len(held) - target.max_connections)
                if name != "gateway metrics":  # its own limit, whose count is not public
                    assert _open(target) <= target.max_connections
                    counters = target.server.counters  # idle ones close and make room
                    assert counters.connections_refused + counters.connections_accepted >= len(held)
            finally:
                _close_all(held)
            await _until(lambda: _open(target) == 0)
            await _answers(target)
        _bounded(target, log)


@pytest.mark.parametrize("name", ["serve tcp", "gateway tcp", "gateway rtu+tcp"])
async def test_thousands_of_client_addresses_are_served_within_bounds(
    name: str, tmp_path: Path
) -> None:
    """2,000 connections from 2,000 addresses of 127.0.0.0/8 in turn, each asking once: all
    answered, and the gateway's statistics keep a bounded number of clients."""

    def each_once() -> int:
        answered = 0
        for index in range(2000):
            host = 2 + index
            reply = ask(target, source=f"127.0.{host >> 8}.{host & 0xFF}")
            answered += reply.startswith(target.reply())
        return answered

    async with listener(tmp_path, name) as target:
        with records() as log:
            assert await anyio.to_thread.run_sync(each_once) == 2000
        if name.startswith("gateway"):
            statistics = target.server.statistics
            assert len(statistics.clients) <= statistics.max_clients + 1
            assert sum(each.requests for each in statistics.clients.values()) == 2000
        _bounded(target, log)


@pytest.mark.parametrize("name", ["serve udp", "gateway udp"])
async def test_thousands_of_source_addresses_of_datagrams_stay_bounded(
    name: str, tmp_path: Path
) -> None:
    def from_everywhere() -> None:
        for index in range(3000):
            host = 2 + index
            with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as sock:
                sock.bind((f"127.0.{host >> 8}.{host & 0xFF}", 0))
                sock.sendto(target.request(), target.address)

    async with listener(tmp_path, name) as target:
        with records() as log:
            await anyio.to_thread.run_sync(from_everywhere)
            if name == "gateway udp":
                assert _open(target) <= MAX_CONNECTIONS
                statistics = target.server.statistics
                assert len(statistics.clients) <= statistics.max_clients + 1
            await _answers(target)
        _bounded(target, log)


# -- clients that never read, slowloris, half-sent headers --------------------------------


_flood = functools.partial(send_until_blocked, quiet=0.3)
"""Send until the server has taken nothing for 0.3 s, closed, or 64 MiB went."""


def _held_to_its_window(target: Target) -> None:
    """The gateway has taken in no more requests than it answered and its window holds:
    `max_in_flight` (one over RTU framing, which has no transaction ids), whatever the kernel
    holds for it. One that reads on regardless takes requests faster than its line answers
    them, hundreds at once: far fewer bytes than the kernel's buffers hold, so the bytes
    alone would not tell."""
    window = 1 if target.framing == "rtu" else target.server.max_in_flight
    clients = target.server.statistics.clients.values()
    unanswered = sum(each.requests - each.replies for each in clients)
    assert 0 <= unanswered <= window, f"{unanswered} requests taken and not answered"


@pytest.mark.parametrize("name", MODBUS_STREAMS)
async def test_a_pipelining_client_that_never_reads_is_held_back(name: str, tmp_path: Path) -> None:
    """Requests streamed without reading a reply: the server takes no more than the kernel's
    buffers and a window of its own (the gateway: `max_in_flight` requests beyond the replies
    it wrote), and the client's connection is closed within the idle timeout once its replies
    cannot be written. Each request reads 125 registers: its reply, 21 times its size, fills
    the server's sending side after a few thousand requests, not hundreds of thousands."""

    bound = kernel_buffers() + (1 << 20)
    async with listener(tmp_path, name) as target:
        with records() as log:
            connect = functools.partial(open_client, target, receive_buffer=4096)
            sock = await anyio.to_thread.run_sync(connect)
            with sock:
                sent = await anyio.to_thread.run_sync(
                    _flood, sock, target.request(pdu=READ_ALL) * 2048
                )
                await _answers(target)
                if name.startswith("gateway"):
                    _held_to_its_window(target)
                # Reset: the requests the kernel holds go with it, not through the server.
                sock.setsockopt(socket.SOL_SOCKET, socket.SO_LINGER, struct.pack("ii", 1, 0))
        assert 0 < sent <= bound, f"{sent} bytes taken, more than the {bound} TCP can hold"
        await _until(lambda: _open(target) == 0)
        _bounded(target, log)


@pytest.mark.parametrize("backend", ["asyncio", "trio"])
@pytest.mark.parametrize("name", ["serve tcp", "serve tls", "serve rtu+tcp", "serve ascii+tcp"])
def test_a_client_that_never_reads_its_replies_is_closed(
    name: str, backend: str, tmp_path: Path
) -> None:
    """Reads of 125 registers, replies never read: once a reply cannot be written for the
    idle timeout, the connection is closed and counted idle, though the client stays."""

    async def scenario() -> None:
        async with listener(tmp_path, name) as target:
            connect = functools.partial(open_client, target, receive_buffer=4096)
            with await anyio.to_thread.run_sync(connect) as sock:
                read = target.request(pdu=READ_ALL) * 1024
                for _ in range(24):  # 300,000 requests' worth of replies: 6 MiB
                    await anyio.to_thread.run_sync(_flood, sock, read)
                    if target.server.counters.connections_idle:
                        break
                await _until(lambda: target.server.counters.connections_idle == 1)
                await _until(lambda: _open(target) == 0)
                await _answers(target)

    anyio.run(scenario, backend=backend)


def _trickle(target: Target, data: bytes, gap: float) -> bytes:
    """Send `data` one byte at a time, `gap` seconds apart; return what comes back then."""
    with open_client(target, 5.0) as sock:
        for byte in data:
            sock.send(bytes((byte,)))
            time.sleep(gap)
        try:
            return sock.recv(65536)
        except TimeoutError:
            return b""


@pytest.mark.parametrize("name", MODBUS_STREAMS)
async def test_slowloris_is_one_connection_of_the_limit(name: str, tmp_path: Path) -> None:
    """Clients that send one byte at a time hold at most `max_connections`: those beyond the
    limit are refused; after them, a request sent a byte every 20 ms is answered (over RTU,
    where 20 ms of silence ends a frame, a request sent whole)."""
    async with listener(tmp_path, name) as target:
        with records() as log:
            held = await anyio.to_thread.run_sync(_connect_many, target, MAX_CONNECTIONS + 4)
            try:
                for sock in held:  # half a header each
                    # A Unix socket the server has already refused breaks the pipe at once
                    # (TCP takes the bytes and resets later): refused is what is counted.
                    with contextlib.suppress(BrokenPipeError, ConnectionResetError):
                        sock.send(target.request()[:3])
                await _until(lambda: _closed_by_server(held) >= 4)
                assert _open(target) <= MAX_CONNECTIONS
            finally:
                _close_all(held)
            await _until(lambda: _open(target) == 0)
            if target.framing == "rtu":  # 20 ms of silence ends an RTU frame: sent whole
                await _answers(target)
            else:
                reply = await anyio.to_thread.run_sync(_trickle, target, target.request(), 0.02)
                assert reply == target.reply()
        _bounded(target, log)


@pytest.mark.parametrize("name", MODBUS_STREAMS)
async def test_a_half_sent_request_is_closed_as_idle(name: str, tmp_path: Path) -> None:
    """Half a request, then silence: closed after the idle timeout (0.5 s here; over RTU the
    half frame is dropped as noise after 20 ms of silence first)."""
    async with listener(tmp_path, name) as target:
        with records() as log:
            sock = await anyio.to_thread.run_sync(open_client, target)
            with sock:
                sock.sendall(target.request()[:5])
                await _until(lambda: target.server.counters.connections_idle == 1, 5.0)
                await _until(lambda: _open(target) == 0)
            await _answers(target)
        _bounded(target, log)


@pytest.mark.parametrize("name", MODBUS_STREAMS)
async def test_a_client_that_never_sends_is_closed_as_idle(name: str, tmp_path: Path) -> None:
    """Connected, then nothing at all: closed after the idle timeout and counted idle."""
    async with listener(tmp_path, name) as target:
        with records() as log:
            sock = await anyio.to_thread.run_sync(open_client, target)
            with sock:
                await _until(lambda: target.server.counters.connections_idle == 1, 5.0)
                await _until(lambda: _open(target) == 0)
                assert await anyio.to_thread.run_sync(sock.recv, 1) == b""  # closed by the server
            await _answers(target)
        _bounded(target, log)


# -- TLS: handshakes that never finish, and the wrong protocol on a port --------------------

TLS = ("serve tls", "gateway tls")
PLAIN = tuple(name for name in MODBUS_STREAMS if name not in TLS)


@pytest.mark.parametrize("name", TLS)
async def test_a_handshake_that_never_finishes_is_closed_and_takes_a_place(
    name: str, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """Half a ClientHello, then silence: the connection holds one place of the limit until
    the handshake timeout (10 s; 0.5 s here), then is closed in one log line."""
    monkeypatch.setattr("aiortu.slave._tls_server.HANDSHAKE_TIMEOUT", 0.5)
    monkeypatch.setattr("aiortu.gateway._open._HANDSHAKE_TIMEOUT", 0.5)
    hello = bytes.fromhex("16 0301 0200 01 0001FC 0303") + bytes(32)
    async with listener(tmp_path, name) as target:
        with records() as log:
            held = await anyio.to_thread.run_sync(_connect_many, target, MAX_CONNECTIONS + 2)
            try:
                for sock in held:
                    sock.send(hello)
                await _until(lambda: _open(target) == MAX_CONNECTIONS)
                await _until(
                    lambda: _closed_by_server(held) == len(held)
                )  # refused, then timed out
            finally:
                _close_all(held)
            await _answers(target)
        failures = [each for each in log.taken if "did not finish in time" in each.getMessage()]
        assert len(failures) == MAX_CONNECTIONS
        _bounded(target, log)


@pytest.mark.parametrize("name", TLS)
async def test_a_plaintext_client_on_a_tls_port_is_closed_in_one_line(
    name: str, tmp_path: Path
) -> None:
    async with listener(tmp_path, name) as target:
        with records() as log:
            for _ in range(20):
                await _drain(target, target.request(), raw=True)
            await _answers(target)
        assert target.server.counters.requests == 1
        loud = [each.getMessage() for each in log.at_least(logging.WARNING)]
        assert len(loud) == 1, loud
        assert "does not speak TLS" in loud[0]
        _bounded(target, log)


def _tls_hello(target: Target) -> str:
    """Try a TLS handshake on a plain port; how it ended."""
    sock = socket.socket(socket.AF_UNIX if target.kind == "unix" else socket.AF_INET)
    sock.settimeout(0.5)
    sock.connect(target.address)
    context = ssl.create_default_context()
    try:
        with context.wrap_socket(sock, server_hostname="localhost"):
            return "handshake done"
    except TimeoutError:
        return "timed out"
    except (ssl.SSLError, ConnectionError) as error:
        return f"refused: {error}"
    finally:
        sock.close()


@pytest.mark.parametrize("name", PLAIN)
async def test_a_tls_client_on_a_plain_port_gets_no_handshake(name: str, tmp_path: Path) -> None:
    """A ClientHello is no Modbus request: an MBAP listener closes the connection (the
    header's protocol id is not 0), an RTU or ASCII one drops it as noise; the client's
    handshake fails or times out, and a good client is answered."""
    async with listener(tmp_path, name) as target:
        with records() as log:
            ended = [await anyio.to_thread.run_sync(_tls_hello, target) for _ in range(2)]
            # An RTU or ASCII listener keeps the ClientHello as noise: the client times out.
            await _answers(target)
        assert all(each != "handshake done" for each in ended), ended
        if target.framing == "mbap":
            assert all(each.startswith("refused") for each in ended), ended
        _bounded(target, log)


# -- the same attacks under trio, where the listeners' paths differ ------------------------

UNDER_TRIO = {
    "serve tcp": (
        test_a_flood_of_good_requests_is_answered_in_full,
        test_a_flood_of_garbage_costs_a_few_log_lines,
        test_thousands_of_connections_beyond_the_limit_are_refused,
        test_slowloris_is_one_connection_of_the_limit,
        test_a_half_sent_request_is_closed_as_idle,
        test_a_client_that_never_sends_is_closed_as_idle,
    ),
    "serve tls": (
        test_a_flood_of_good_requests_is_answered_in_full,
        test_malformed_frames_of_every_kind_cost_no_traceback,
        test_thousands_of_connections_beyond_the_limit_are_refused,
        test_a_plaintext_client_on_a_tls_port_is_closed_in_one_line,
    ),
    "serve rtu+tcp": (
        test_slowloris_is_one_connection_of_the_limit,
        test_a_half_sent_request_is_closed_as_idle,
        test_a_client_that_never_sends_is_closed_as_idle,
    ),
    "serve ascii+tcp": (
        test_slowloris_is_one_connection_of_the_limit,
        test_a_half_sent_request_is_closed_as_idle,
        test_a_client_that_never_sends_is_closed_as_idle,
    ),
    "serve udp": (
        test_a_flood_of_datagrams_costs_datagrams_not_memory,
        test_a_flood_of_garbage_costs_a_few_log_lines,
    ),
    "gateway tcp": (
        test_a_flood_of_good_requests_is_answered_in_full,
        test_a_pipelining_client_that_never_reads_is_held_back,
    ),
    "gateway tls": (
        test_thousands_of_connections_beyond_the_limit_are_refused,
        test_a_flood_of_garbage_costs_a_few_log_lines,
    ),
}
"""The attacks run again under trio: on asyncio these listeners are pushed (answered from the
event loop's callbacks); under trio they are anyio streams, or a task reading the socket."""


@pytest.mark.parametrize(
    ("name", "attack"),
    [(name, attack) for name, attacks in UNDER_TRIO.items() for attack in attacks],
    ids=lambda each: each if isinstance(each, str) else each.__name__.removeprefix("test_"),
)
def test_under_trio(name: str, attack: Callable[[str, Path], Any], tmp_path: Path) -> None:
    anyio.run(attack, name, tmp_path, backend="trio")

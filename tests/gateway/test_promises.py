"""Promises of the line server that a rewrite of its request path could quietly lose.

Each test goes through public behaviour only: real sockets on 127.0.0.1 (or, for the tests of
time, in-memory streams that the gateway serves as it serves a socket, on a virtual clock), a
virtual line whose slave holds a request until the test lets it go (so a read is in flight for
as long as the test needs, whatever the machine's load), and the gateway's public counters.
Assertions are on the content and order of what the clients receive, and on virtual time.
"""

from __future__ import annotations

import gc
import inspect
import logging
import re
import tracemalloc
import warnings
from collections import deque
from collections.abc import Callable
from types import SimpleNamespace

import anyio
import anyio.abc
import pytest

from aiortu.core.mbap import encode_adu
from aiortu.core.rtu import encode_frame
from aiortu.errors import InvalidValue
from aiortu.gateway import Gateway, GatewayLine, gateway
from aiortu.gateway._metrics import parse_metrics_url
from aiortu.gateway._server import _drop_unstarted
from aiortu.slave import MemoryStore, RequestContext
from tests.gateway.helpers import (
    UNIT,
    Line,
    TcpClient,
    client,
    device,
    line,
    memory_client,
    memory_stream,
)
from tests.virtual_clock import on_virtual_clock

pytestmark = pytest.mark.timeout(30)

OTHER = 18
"""A second unit on the line, whose registers differ from `UNIT`'s."""

HELD = {"timeout": 10.0}
"""Master options: the hold, not the master's timeout, decides when a request is answered."""

BOTH = ("tcp://127.0.0.1:0", "rtu+tcp://127.0.0.1:0")


class Hold:
    """A slave hook that holds every request on the line until `release`."""

    def __init__(self) -> None:
        self.released = anyio.Event()
        self.held = 0

    async def __call__(self, request: object, context: RequestContext) -> None:
        self.held += 1
        await self.released.wait()

    def release(self) -> None:
        self.released.set()


async def _until(condition: Callable[[], bool]) -> None:
    """Wait (at most 10 s) for `condition`: counters of several objects, none of which signals."""
    with anyio.fail_after(10):
        while not condition():  # noqa: ASYNC110
            await anyio.sleep(0.001)


def _on_the_line_or_shared(bench: Line, reads: int) -> Callable[[], bool]:
    """Whether the gateway has handed on `reads` reads: each either sent or sharing another's."""
    counters = bench.gateway.counters
    return lambda: counters.transactions + counters.coalesced >= reads


async def _two_reads_in_flight(bench: Line, first: tuple[int, str], second: tuple[int, str]) -> str:
    """Send read `first` (unit, PDU) from one client, hold it on the line, send `second` from
    another client, let both go; the second client's reply PDU, after checking its ids."""
    hold = Hold()
    bench.slave.before_request(hold)
    async with client(bench.gateway) as a, client(bench.gateway) as b:
        await a.send(first[1], first[0], 1)
        await _until(lambda: hold.held == 1)
        await b.send(second[1], second[0], 2)
        await _until(_on_the_line_or_shared(bench, 2))
        hold.release()
        first_reply, second_reply = await a.receive(), await b.receive()
    assert first_reply is not None
    assert second_reply is not None
    assert (second_reply.transaction_id, second_reply.unit) == (2, second[0])
    return second_reply.pdu.hex(" ").upper()


async def test_identical_reads_to_two_units_in_flight_at_once_get_each_units_data() -> None:
    other = MemoryStore(holding_registers={0: [0x0BAD, 0xF00D]})
    async with line({UNIT: device(), OTHER: other}, master_options=HELD) as bench:
        reply = await _two_reads_in_flight(bench, (UNIT, "03 0000 0002"), (OTHER, "03 0000 0002"))
        assert reply == "03 04 0B AD F0 0D"  # never unit 17's 12 34 AB CD
        assert bench.messages == 2


async def test_reads_of_different_counts_in_flight_at_once_get_their_own_reply() -> None:
    async with line(master_options=HELD) as bench:
        reply = await _two_reads_in_flight(bench, (UNIT, "03 0000 0001"), (UNIT, "03 0000 0002"))
        assert reply == "03 04 12 34 AB CD"  # never the one-register read's 03 02 12 34
        assert bench.messages == 2


async def test_without_coalescing_identical_reads_in_flight_each_go_on_the_line() -> None:
    async with line(master_options=HELD, coalesce=False) as bench:
        reply = await _two_reads_in_flight(bench, (UNIT, "03 0000 0001"), (UNIT, "03 0000 0001"))
        assert reply == "03 02 12 34"
        assert bench.messages == 2
        assert bench.gateway.counters.coalesced == 0


async def test_a_broadcast_between_two_cached_reads_drops_the_cache() -> None:
    async with line(cache_ms=60_000) as bench, client(bench.gateway) as tcp:
        assert await tcp.request("03 0000 0001") == "03 02 12 34"
        on_the_line = bench.messages
        assert await tcp.request("03 0000 0001") == "03 02 12 34"
        assert bench.messages == on_the_line  # the cache answered
        await tcp.send("06 0000 0042", unit=0, transaction_id=2)  # never answered
        await _until(lambda: bench.gateway.counters.broadcasts == 1)
        assert bench.messages == on_the_line + 1
        assert await tcp.request("03 0000 0001", transaction_id=3) == "03 02 00 42"


@on_virtual_clock
async def test_rtu_over_tcp_replies_keep_the_order_of_the_requests() -> None:
    # A served unit's read, held on the line, then a unit the gateway refuses at once, in one
    # chunk: the refusal must not overtake the read's reply (RTU frames carry no ids).
    async with line(listen=(), master_options=HELD) as bench:
        hold = Hold()
        bench.slave.before_request(hold)
        async with memory_stream(bench.gateway, rtu_framing=True) as stream:
            read = encode_frame(UNIT, bytes.fromhex("03 0000 0001"))
            refused = encode_frame(250, bytes.fromhex("03 0000 0001"))
            await stream.send(read + refused)
            await _until(lambda: hold.held == 1)
            received = b""
            with anyio.move_on_after(5):  # what the gateway sends while the read is held
                received += await stream.receive()
            hold.release()
            expected = encode_frame(UNIT, bytes.fromhex("03 02 1234")) + encode_frame(
                250, bytes.fromhex("83 0B")
            )
            while len(received) < len(expected):
                received += await stream.receive()
            assert received == expected


@on_virtual_clock
async def test_a_connection_waiting_for_a_slow_line_is_not_closed_as_idle() -> None:
    idle = 0.25
    async with line(idle_timeout=idle, master_options=HELD, listen=()) as bench:
        hold = Hold()
        bench.slave.before_request(hold)
        async with memory_client(bench.gateway) as tcp:
            await tcp.send("03 0000 0001", UNIT, 7)
            await _until(lambda: hold.held == 1)
            # Eight idle timeouts with the read on the line: the connection stays open.
            assert not await tcp.closed_by_server(wait=8 * idle)
            hold.release()
            reply = await tcp.receive()
            answered = anyio.current_time()
            assert reply is not None
            assert (reply.transaction_id, reply.pdu.hex(" ")) == (7, "03 02 12 34")
            assert bench.gateway.counters.connections_idle == 0
            # Answered, it is idle again, and closed as such, idle_timeout after its reply.
            assert await tcp.closed_by_server()
            assert anyio.current_time() - answered == pytest.approx(idle, abs=1e-9)
            assert bench.gateway.counters.connections_idle == 1


def _label_value(sample: str, metric: str) -> str:
    """The value of the one label of `metric` in Prometheus text, unescaped as the format says."""
    start = sample.index(metric + '{line="') + len(metric) + len('{line="')
    value, index = [], start
    while sample[index] != '"':
        if sample[index] == "\\":
            index += 1
            value.append({"n": "\n", "\\": "\\", '"': '"'}[sample[index]])
        else:
            value.append(sample[index])
        index += 1
    assert sample[index : index + 2] == '"}', "the label value runs on past its closing quote"
    return "".join(value)


async def _get_metrics(address: tuple[str, int], target: str = "/metrics") -> str:
    async with await anyio.connect_tcp(*address) as stream:
        await stream.send(f"GET {target} HTTP/1.1\r\nHost: x\r\n\r\n".encode())
        data = b""
        with anyio.fail_after(5):
            try:
                while True:
                    data += await stream.receive()
            except anyio.EndOfStream:
                pass
    head, _, body = data.decode().partition("\r\n\r\n")
    assert head.startswith("HTTP/1.1 200 OK")
    return body


async def test_a_line_name_with_a_quote_a_backslash_and_a_newline_is_escaped_in_metrics() -> None:
    name = 'bench "A"\\left\nside'
    metrics = "http://127.0.0.1:0/metrics"
    async with line() as bench:
        lines = [GatewayLine(bench.master, name=name)]
        async with gateway(lines, ["tcp://127.0.0.1:0"], metrics=metrics) as named:
            async with client(named) as tcp:
                assert await tcp.request("03 0000 0001") == "03 02 12 34"
            assert named.metrics_address is not None
            body = await _get_metrics(named.metrics_address)
            # A query string is allowed, and changes nothing.
            assert await _get_metrics(named.metrics_address, "/metrics?name[]=x") == body
    metric = "aiortu_gateway_line_transactions_total"
    expected = f'{metric}{{line="bench \\"A\\"\\\\left\\nside"}} 1'
    assert expected in body.splitlines()
    assert _label_value(body, metric) == name
    for text in body.splitlines():  # every line a comment or a whole sample
        assert text.startswith(("# ", "aiortu_gateway_")), text


async def test_an_endless_rtu_frame_of_unknown_length_is_not_buffered_whole() -> None:
    # A user-defined function code has no length: only a silence ends its frame. A client that
    # never pauses must not make the gateway buffer everything it sends.
    chunk = b"\x41" * 4096
    flood = 1024  # chunks: 4 MiB, each sent as soon as the last is taken
    async with line(listen=BOTH) as bench:
        port = bench.gateway.local_addresses[1][1]
        async with await anyio.connect_tcp("127.0.0.1", port) as stream:
            tracemalloc.start()
            try:
                before, _ = tracemalloc.get_traced_memory()
                await stream.send(encode_frame(UNIT, b"\x41"))
                for _ in range(flood):
                    await stream.send(chunk)
                await anyio.sleep(0.2)  # a silence: whatever is buffered ends as a frame
                _, peak = tracemalloc.get_traced_memory()
            finally:
                tracemalloc.stop()
            assert peak - before < 1024 * 1024, f"{(peak - before) // 1024} KiB held"
            assert bench.messages == 0  # noise, never sent on the line
            # The connection goes on.
            await stream.send(encode_frame(UNIT, bytes.fromhex("03 0000 0001")))
            with anyio.fail_after(5):
                assert await stream.receive() == encode_frame(UNIT, bytes.fromhex("03 02 1234"))


async def test_a_write_drops_only_the_cached_blocks_it_touches() -> None:
    async with line(cache_ms=60_000) as bench, client(bench.gateway) as tcp:
        assert await tcp.request("03 0001 0002") == "03 04 AB CD 00 07"
        on_the_line = bench.messages
        # Registers 0 and 3 lie just before and just after the block: it stays cached.
        assert await tcp.request("06 0000 0042") == "06 00 00 00 42"
        assert await tcp.request("06 0003 0042") == "06 00 03 00 42"
        assert await tcp.request("03 0001 0002") == "03 04 AB CD 00 07"
        assert bench.messages == on_the_line + 2  # the writes alone
        # Register 2 lies in it: read again.
        assert await tcp.request("06 0002 0009") == "06 00 02 00 09"
        assert await tcp.request("03 0001 0002") == "03 04 AB CD 00 09"
        assert bench.messages == on_the_line + 4


async def test_a_truncated_write_drops_every_cached_block_of_its_unit() -> None:
    # 06 with one address byte: the cache cannot tell what it writes, so nothing it kept for
    # the unit may be trusted after it (the device decides what it makes of the request).
    async with line(cache_ms=60_000) as bench, client(bench.gateway) as tcp:
        assert await tcp.request("03 0005 0001") == "03 02 00 00"
        assert await tcp.request("03 0005 0001") == "03 02 00 00"
        on_the_line = bench.messages
        await tcp.request("06 00")
        assert await tcp.request("03 0005 0001") == "03 02 00 00"
        assert bench.messages == on_the_line + 2  # the write, and the read again


async def test_replies_are_counted_by_kind_per_unit() -> None:
    dead = OTHER  # no device answers it
    async with line() as bench, client(bench.gateway) as tcp:
        assert await tcp.request("03 0000 0001") == "03 02 12 34"
        assert await tcp.request("03 FFF0 0001") == "83 02"  # the device's own exception
        assert await tcp.request("03 0000 0001", dead) == "83 0B"
        assert await tcp.request("03 0000 0001", 250) == "83 0B"  # refused at once
        units = bench.gateway.statistics.units
        assert (units[("line", UNIT)].replies, units[("line", UNIT)].exceptions) == (1, 1)
        assert (units[("line", dead)].no_response, units[("line", dead)].exceptions) == (1, 0)
        assert bench.gateway.counters.refused_units == 1


@pytest.mark.parametrize(
    ("url", "reason"),
    [
        ("ftp://127.0.0.1:9102/metrics", "expected an http:// URL"),
        ("http://127.0.0.1:9102", None),  # the default path
        ("http://127.0.0.1:70000/metrics", "the port '70000' is not in 0..65535"),
        ("http://:9102/metrics", "expected an http:// URL"),
    ],
)
async def test_a_metrics_url_is_checked_before_anything_is_opened(
    url: str, reason: str | None
) -> None:
    async with line() as bench:
        if reason is None:
            async with gateway(bench.master, [], metrics=url.replace("9102", "0")) as served:
                assert served.metrics_address is not None
                assert (await _get_metrics(served.metrics_address)).startswith("# HELP")
            return
        with pytest.raises(InvalidValue, match=re.escape(reason)):
            async with gateway(bench.master, [], metrics=url):
                pass


@on_virtual_clock
async def test_a_connection_has_four_requests_waiting_at_most_by_default() -> None:
    async with line(master_options=HELD, listen=()) as bench:
        hold = Hold()
        bench.slave.before_request(hold)
        async with memory_client(bench.gateway) as tcp:
            for transaction_id in range(6):
                await tcp.send("03 0000 0001", UNIT, transaction_id)
            await _until(lambda: bench.gateway.counters.requests >= 4)
            await anyio.sleep(5)  # time for a fifth to be read, were it allowed
            assert bench.gateway.counters.requests == 4
            hold.release()
            replies = [await tcp.receive() for _ in range(6)]
            # Each answered once. Modbus TCP replies carry their ids and keep no order: the
            # reads share one transaction, whose waiters trio wakes in an order of its own.
            assert sorted(reply.transaction_id for reply in replies if reply) == list(range(6))


async def test_a_connection_over_the_limit_is_logged_once_until_one_closes(
    caplog: pytest.LogCaptureFixture,
) -> None:
    caplog.set_level(logging.WARNING, logger="aiortu")
    async with line(max_connections=1) as bench, client(bench.gateway) as first:
        assert await first.request("03 0000 0001") == "03 02 12 34"
        for _ in range(2):
            async with client(bench.gateway) as refused:
                assert await refused.closed_by_server()
        assert bench.gateway.counters.connections_refused == 2
    warnings = [r.getMessage() for r in caplog.records if r.levelno == logging.WARNING]
    assert len(warnings) == 1
    assert warnings[0].startswith("gateway: 1 connections open, the most allowed; closing")


@pytest.mark.parametrize(
    ("option", "value", "message"),
    [
        ("max_in_flight", 0, "max_in_flight must be an int of at least 1, not 0"),
        ("max_connections", 0, "max_connections must be an int of at least 1, not 0"),
        ("idle_timeout", 0, "idle_timeout must be a positive number of seconds, not 0"),
    ],
)
async def test_a_limit_below_its_least_value_is_refused_in_one_sentence(
    option: str, value: int, message: str
) -> None:
    async with line() as bench:
        with pytest.raises(InvalidValue) as raised:
            Gateway(bench.master, **{option: value})
    assert str(raised.value) == message


class Clock:
    """A clock the test moves: the cache's age is asserted without waiting."""

    def __init__(self) -> None:
        self.now = 100.0

    def __call__(self) -> float:
        return self.now


async def test_a_cached_read_is_answered_until_exactly_cache_ms_old() -> None:
    clock = Clock()
    async with line(cache_ms=500, clock=clock) as bench, client(bench.gateway) as tcp:
        assert await tcp.request("03 0000 0001") == "03 02 12 34"
        on_the_line = bench.messages
        clock.now += 0.5
        assert await tcp.request("03 0000 0001") == "03 02 12 34"
        assert bench.messages == on_the_line  # 500 ms old: still answered
        clock.now += 0.001
        assert await tcp.request("03 0000 0001") == "03 02 12 34"
        assert bench.messages == on_the_line + 1


async def test_a_gateway_made_directly_coalesces_and_has_no_port_before_it_listens() -> None:
    async with line() as bench:
        made = Gateway(bench.master)
        assert made.coalesce is True
        assert (made.max_in_flight, made.max_connections) == (4, 32)
        with pytest.raises(RuntimeError, match="the gateway is not listening yet"):
            _ = made.port


async def test_a_connection_served_directly_speaks_modbus_tcp_by_default() -> None:
    async with (
        line() as bench,
        await anyio.create_tcp_listener(local_host="127.0.0.1") as listener,
        anyio.create_task_group() as tasks,
    ):
        made = Gateway(bench.master)
        tasks.start_soon(listener.serve, made.serve_connection)
        port = listener.extra(anyio.abc.SocketAttribute.local_port)
        async with await anyio.connect_tcp("127.0.0.1", port) as stream:
            with anyio.fail_after(5):
                assert await TcpClient(stream).request("03 0000 0001") == "03 02 12 34"
        tasks.cancel_scope.cancel()


def test_a_metrics_url_takes_every_port_up_to_65535() -> None:
    assert parse_metrics_url("http://127.0.0.1:65535/metrics").port == 65535
    assert parse_metrics_url("http://[::1]:0").port == 0
    with pytest.raises(InvalidValue, match=re.escape("the port '65536' is not in 0..65535")):
        parse_metrics_url("http://127.0.0.1:65536/metrics")


@on_virtual_clock
async def test_a_read_that_asks_again_keeps_its_place_in_its_connections_window() -> None:
    async with line(master_options=HELD, listen=()) as bench:
        hold = Hold()
        bench.slave.before_request(hold)
        async with memory_client(bench.gateway) as follower:
            async with memory_client(bench.gateway) as leader:
                await leader.send("03 0000 0001", UNIT, 0)
                await _until(lambda: bench.gateway.counters.requests == 1)
                await follower.send("03 0000 0001", UNIT, 0)  # joins the leader's read
                await _until(lambda: bench.gateway.counters.requests == 2)
            # The leader left: the follower's read asks again, still one of its four places.
            for transaction_id in range(1, 6):
                await follower.send(f"03 {transaction_id:04X} 0001", UNIT, transaction_id)
            await _until(lambda: bench.gateway.counters.requests >= 5)
            await anyio.sleep(5)  # time for a fifth of its own to be read, were it allowed
            assert bench.gateway.counters.requests == 5
            hold.release()
            replies = [await follower.receive() for _ in range(6)]
            assert sorted(reply.transaction_id for reply in replies if reply) == list(range(6))


async def _stop_with_requests_queued_for_a_worker() -> None:
    """A write and a read in one segment: the read queues behind the write for the same
    worker. The write is held on the line when the gateway stops, so no worker ever takes
    the read, nor the write after it."""
    async with line(master_options=HELD, listen=()) as bench:
        hold = Hold()
        bench.slave.before_request(hold)
        async with memory_stream(bench.gateway) as stream:
            await stream.send(
                encode_adu(1, UNIT, bytes.fromhex("06 0005 0042"))
                + encode_adu(2, UNIT, bytes.fromhex("03 0000 0001"))
                + encode_adu(3, OTHER, bytes.fromhex("06 0006 0043"))
            )
            await _until(lambda: bench.gateway.counters.requests == 3 and hold.held == 1)


@on_virtual_clock
async def test_requests_left_queued_for_a_worker_leave_no_coroutine_unawaited() -> None:
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        await _stop_with_requests_queued_for_a_worker()
        gc.collect()
    unawaited = [str(w.message) for w in caught if "never awaited" in str(w.message)]
    assert unawaited == []


def test_a_reads_line_awaitable_no_worker_took_is_closed_with_its_connection() -> None:
    # Where the line gives a read a coroutine (trio; an idle line where the fast path does
    # not take it), a worker awaits it: when the connection ends before a worker took the
    # read, the coroutine, not started and so nothing sent, is closed.
    async def on_the_line() -> None:
        raise AssertionError("never run")

    submitted = on_the_line()
    request = SimpleNamespace(submitted=submitted)
    connection = SimpleNamespace(pending=deque([request, SimpleNamespace(submitted=None)]))
    _drop_unstarted(connection)  # type: ignore[arg-type]
    assert inspect.getcoroutinestate(submitted) == inspect.CORO_CLOSED
    assert not connection.pending

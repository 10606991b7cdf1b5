"""Modbus TCP for the slave: the same route as on a serial line, many connections, limits."""

from __future__ import annotations

import logging
import os
import random
from collections.abc import Awaitable, Callable

import anyio
import anyio.lowlevel
import pytest

from aiortu.core.pdu import RawPDU
from aiortu.errors import InvalidValue
from aiortu.slave import (
    MemoryStore,
    ModbusTcpServer,
    Reply,
    RequestContext,
    RtuOverTcpServer,
    Table,
    serve,
)
from tests.slave.helpers import raising_trace, slave_line
from tests.slave.tcp_helpers import UNIT, connect, device, tcp_server

pytestmark = pytest.mark.timeout(30)

# One request for each public function code a TCP server serves, and refusals.
REQUESTS = [
    "01 00 00 00 04",
    "02 00 00 00 03",
    "03 00 00 00 03",
    "04 00 01 00 02",
    "05 00 01 FF 00",
    "06 00 03 00 63",
    "0F 00 04 00 03 01 05",
    "10 00 04 00 03 06 00 01 00 02 00 03",
    "14 07 06 00 04 00 01 00 02",
    "15 0D 06 00 04 00 03 00 03 00 07 00 08 00 09",
    "14 07 06 00 04 00 03 00 03",
    "16 00 00 00 FF 00 00",
    "17 00 00 00 02 00 01 00 01 02 00 05",
    "18 04 DE",
    "2B 0E 01 00",
    "03 00 00 00 00",  # quantity 0: 03
    "03 FF 00 00 02",  # unmapped: 02
    "05 00 01 12 34",  # a coil value that is neither ON nor OFF: 03
    "41 01 02",  # a user-defined code with no handler: 01
    "01 00 00 00 10",
]

SERIAL_LINE_ONLY = ["07", "08 00 00 A5 37", "0B", "0C", "11"]


async def test_every_function_code_answers_as_on_a_serial_line() -> None:
    tcp_store, serial_store = device(), device()
    async with tcp_server({UNIT: tcp_store}) as server, connect(server) as client:
        tcp = [await client.request(pdu, transaction_id=n) for n, pdu in enumerate(REQUESTS)]
    async with slave_line({UNIT: serial_store}) as (master, _):
        serial = [await master.request(UNIT, pdu) for pdu in REQUESTS]
    assert tcp == serial
    assert tcp[2] == "03 06 12 34 AB CD 00 07"
    assert tcp[-5:-1] == ["83 03", "83 02", "85 03", "C1 01"]
    assert tcp_store.get(Table.HOLDING_REGISTERS, 0, 7) == serial_store.get(
        Table.HOLDING_REGISTERS, 0, 7
    )


async def test_serial_line_only_codes_get_01_unless_asked_for() -> None:
    async with tcp_server() as server, connect(server) as client:
        refused = [await client.request(pdu) for pdu in SERIAL_LINE_ONLY]
    assert refused == ["87 01", "88 01", "8B 01", "8C 01", "91 01"]
    async with tcp_server(serial_line_codes=True) as server, connect(server) as client:
        assert await client.request("07") == "07 6D"
        assert await client.request("08 00 00 A5 37") == "08 00 00 A5 37"
        assert (await client.request("11")).startswith("11")


async def test_a_handler_set_for_a_serial_line_code_is_served() -> None:
    def status(request: RawPDU, context: RequestContext) -> RawPDU:
        return RawPDU(0x07, b"\x2a")

    async with tcp_server(handlers={0x07: status}) as server, connect(server) as client:
        assert await client.request("07") == "07 2A"


async def test_replies_carry_the_transaction_and_unit_id() -> None:
    async with tcp_server() as server, connect(server) as client:
        await client.send("03 00 00 00 01", transaction_id=0xBEEF)
        reply = await client.receive()
        assert reply is not None
        assert (reply.transaction_id, reply.unit, reply.pdu.hex()) == (0xBEEF, UNIT, "03021234")


async def test_one_unit_answers_to_0_and_255_as_itself() -> None:
    async with tcp_server() as server, connect(server) as client:
        assert await client.request("03 00 01 00 01", unit=0) == "03 02 AB CD"
        assert await client.request("03 00 01 00 01", unit=255) == "03 02 AB CD"
        assert await client.request("03 00 01 00 01", unit=5) == "83 0B"
    assert server.counters.unknown_unit == 1


async def test_several_units_broadcast_on_0_and_refuse_unknown_units() -> None:
    first, second = device(), device()
    async with tcp_server({1: first, 2: second}) as server, connect(server) as client:
        await client.send("06 00 05 00 2A", unit=0, transaction_id=1)
        # No reply to the broadcast: the next reply is the next request's.
        assert await client.request("03 00 05 00 01", unit=2, transaction_id=2) == "03 02 00 2A"
        assert await client.request("03 00 05 00 01", unit=255) == "83 0B"
    assert first.get(Table.HOLDING_REGISTERS, 5) == [42]


async def test_unit_aliases_and_silence_for_unknown_units() -> None:
    units = {1: device(), 2: device()}
    options = {"unit_aliases": {255: 2}, "answer_unknown_units": False}
    async with tcp_server(units, **options) as server, connect(server) as client:
        await client.send("06 00 05 00 07", unit=255)
        assert (await client.receive()) is not None
        await client.send("03 00 05 00 01", unit=9, transaction_id=2)
        await client.send("03 00 05 00 01", unit=2, transaction_id=3)
        reply = await client.receive()
        assert reply is not None
        assert reply.transaction_id == 3  # nothing came back for unit 9
    assert units[2].get(Table.HOLDING_REGISTERS, 5) == [7]
    with pytest.raises(ValueError, match="unit_aliases"):
        ModbusTcpServer({1: device()}, unit_aliases={0: 3})


def _seed() -> int:
    """A fresh seed, or ``AIORTU_TCP_SEED`` to run a failure's seed again."""
    return int(os.environ.get("AIORTU_TCP_SEED") or random.randrange(2**32))


async def test_requests_split_anywhere_and_pipelined() -> None:
    seed = _seed()
    rng = random.Random(seed)
    from aiortu.core.mbap import encode_adu

    adus = b"".join(
        encode_adu(n, UNIT, bytes.fromhex(f"03 00 {n % 3:02X} 00 01")) for n in range(40)
    )
    async with tcp_server() as server, connect(server) as client:
        cut = 0
        while cut < len(adus):
            step = rng.randint(1, 30)
            await client.stream.send(adus[cut : cut + step])
            cut += step
            await anyio.lowlevel.checkpoint()
        replies = [await client.receive() for _ in range(40)]
    values = [0x1234, 0xABCD, 7]
    assert [(r.transaction_id, r.pdu) for r in replies if r is not None] == [
        (n, bytes((3, 2)) + values[n % 3].to_bytes(2, "big")) for n in range(40)
    ], f"seed {seed} (AIORTU_TCP_SEED={seed})"


async def test_many_connections_at_once() -> None:
    store = MemoryStore(holding_registers={0: [0] * 20})

    async def client_writes(index: int) -> None:
        async with connect(server) as client:
            for count in range(1, 21):
                pdu = f"06 00 {index:02X} 00 {count:02X}"
                assert await client.request(pdu, transaction_id=count) == pdu

    async with tcp_server({UNIT: store}) as server, anyio.create_task_group() as group:
        for index in range(12):
            group.start_soon(client_writes, index)
    assert store.get(Table.HOLDING_REGISTERS, 0, 12) == [20] * 12
    assert server.counters.connections_accepted == 12


async def test_a_malformed_header_closes_only_its_connection(
    caplog: pytest.LogCaptureFixture,
) -> None:
    async with tcp_server() as server, connect(server) as good, connect(server) as bad:
        assert await good.request("03 00 00 00 01") == "03 02 12 34"
        with caplog.at_level(logging.WARNING):
            # Protocol id 1, then more bytes that must not be read as a request.
            await bad.stream.send(bytes.fromhex("00 01 00 01 00 06 11 03 00 00 00 01") * 3)
            assert await bad.closed_by_server()
        assert await good.request("03 00 00 00 01", transaction_id=2) == "03 02 12 34"
    assert server.counters.connections_malformed == 1
    assert len([r for r in caplog.records if "protocol id is 1" in r.getMessage()]) == 1


async def test_an_over_long_length_field_closes_the_connection() -> None:
    async with tcp_server() as server, connect(server) as client:
        await client.stream.send(bytes.fromhex("00 01 00 00 01 00 11 03"))
        assert await client.closed_by_server()


async def test_connections_over_the_limit_are_closed() -> None:
    async with tcp_server(max_connections=2) as server:
        async with connect(server) as first, connect(server) as second:
            assert await first.request("03 00 00 00 01") == "03 02 12 34"
            assert await second.request("03 00 00 00 01") == "03 02 12 34"
            async with connect(server) as third:
                assert await third.closed_by_server()
        for _ in range(500):  # the server notices both closes
            if not server.connections:
                break
            await anyio.sleep(0.01)
        async with connect(server) as later:
            assert await later.request("03 00 00 00 01") == "03 02 12 34"
    assert server.counters.connections_refused == 1


async def test_an_idle_connection_is_closed() -> None:
    # Long enough that the request is answered before it, however loaded the machine.
    async with tcp_server(idle_timeout=1.0) as server, connect(server) as client:
        assert await client.request("03 00 00 00 01") == "03 02 12 34"
        await client.stream.send(bytes.fromhex("00 01 00"))  # half a header, then silence
        assert await client.closed_by_server()
    assert server.counters.connections_idle == 1


async def test_requests_of_all_connections_run_one_at_a_time() -> None:
    running, most = 0, 0

    async def slow(request: RawPDU, context: RequestContext) -> RawPDU:
        nonlocal running, most
        running += 1
        most = max(most, running)
        await anyio.sleep(0.01)
        running -= 1
        return RawPDU(0x41, b"")

    async def ask(server: ModbusTcpServer) -> None:
        async with connect(server) as client:
            for n in range(5):
                assert await client.request("41", transaction_id=n) == "41"

    async with tcp_server(handlers={0x41: slow}) as server, anyio.create_task_group() as group:
        for _ in range(4):
            group.start_soon(ask, server)
    assert most == 1


async def test_hooks_routes_and_replies_over_tcp() -> None:
    seen: list[int] = []
    async with tcp_server() as server, connect(server) as client:
        server.before_request(lambda request, context: seen.append(context.unit))
        server.route(Table.INPUT_REGISTERS, range(100, 102), lambda access: [7, 8])

        def odd(request: RawPDU, context: RequestContext) -> Reply:
            return Reply(RawPDU(0x42, b"\x01"), delay=0.01, unit=99)

        server.set_handler(0x42, odd)
        assert await client.request("04 00 64 00 02") == "04 04 00 07 00 08"
        await client.send("42", transaction_id=9)
        reply = await client.receive()
        assert reply is not None
        assert (reply.transaction_id, reply.unit, reply.pdu) == (9, 99, b"\x42\x01")
    assert seen == [UNIT, UNIT]


async def test_rtu_over_tcp_listens_and_serves_each_connection_as_a_line() -> None:
    from aiortu.core.rtu import decode_frame, encode_frame

    store = device()
    async with serve("rtu+tcp://127.0.0.1:0", {UNIT: store}) as server:
        assert isinstance(server, RtuOverTcpServer)
        for value in (5, 6):
            async with await anyio.connect_tcp("127.0.0.1", server.port) as stream:
                await stream.send(encode_frame(UNIT, bytes.fromhex(f"06 00 09 00 {value:02X}")))
                reply = await stream.receive()
                assert decode_frame(reply).pdu == bytes.fromhex(f"06 00 09 00 {value:02X}")
    assert store.get(Table.HOLDING_REGISTERS, 9) == [6]


async def test_rtu_over_tcp_to_a_named_host_and_port_connects_to_a_device_server() -> None:
    # The address of a serial device server that listens: the slave connects to it, and
    # answers the requests that come through it as a device on its line.
    from aiortu.core.rtu import decode_frame, encode_frame
    from aiortu.slave import Slave

    async with await anyio.create_tcp_listener(local_host="127.0.0.1") as listeners:
        listener = listeners.listeners[0]
        port = listener.extra(anyio.abc.SocketAttribute.local_port)
        with anyio.fail_after(5):
            async with serve(f"rtu+tcp://127.0.0.1:{port}", {UNIT: device()}) as slave:
                assert isinstance(slave, Slave)
                async with await listener.accept() as line:
                    await anyio.sleep(0.05)  # the slave's receiver first waits for silence
                    await line.send(encode_frame(UNIT, bytes.fromhex("03 00 01 00 01")))
                    reply = await line.receive()
                    assert decode_frame(reply).pdu == bytes.fromhex("03 02 AB CD")


async def test_listen_is_for_urls_only() -> None:
    with pytest.raises(InvalidValue, match="only a URL listens"):
        async with serve("/dev/ttyUSB0", {UNIT: device()}, listen=True):
            pass


@pytest.mark.parametrize(
    "scenario",
    [test_replies_carry_the_transaction_and_unit_id, test_many_connections_at_once],
)
def test_under_trio(scenario: Callable[[], Awaitable[None]]) -> None:
    anyio.run(scenario, backend="trio")


async def test_rtu_over_tcp_hooks_reach_lines_connected_before_and_after() -> None:
    from aiortu.core.rtu import encode_frame

    seen: list[str] = []
    async with serve("rtu+tcp://127.0.0.1:0", {UNIT: device()}) as server:
        assert isinstance(server, RtuOverTcpServer)
        async with await anyio.connect_tcp("127.0.0.1", server.port) as early:
            await early.send(encode_frame(UNIT, bytes.fromhex("03 00 00 00 01")))
            await early.receive()
            remove = server.before_request(lambda request, context: seen.append("early"))
            await early.send(encode_frame(UNIT, bytes.fromhex("03 00 00 00 01")))
            await early.receive()
        async with await anyio.connect_tcp("127.0.0.1", server.port) as late:
            await late.send(encode_frame(UNIT, bytes.fromhex("03 00 00 00 01")))
            await late.receive()
            remove()
            await late.send(encode_frame(UNIT, bytes.fromhex("03 00 00 00 01")))
            await late.receive()
    assert seen == ["early", "early"]


async def test_trace_sees_each_request_and_reply_adu() -> None:
    seen: list[tuple[str, str]] = []
    trace = lambda kind, data: seen.append((kind, data.hex(" ")))  # noqa: E731
    async with tcp_server(trace=trace) as server, connect(server) as client:
        await client.request("03 00 01 00 01", transaction_id=7)
    assert seen == [
        ("received", "00 07 00 00 00 06 11 03 00 01 00 01"),
        ("sent", "00 07 00 00 00 05 11 03 02 ab cd"),
    ]


async def test_a_raising_trace_is_logged_and_detached_and_the_reply_still_goes(
    caplog: pytest.LogCaptureFixture,
) -> None:
    calls: list[str] = []
    with caplog.at_level(logging.ERROR, logger="aiortu"):
        async with tcp_server(trace=raising_trace(calls)) as server, connect(server) as client:
            assert await client.request("03 00 01 00 01") == "03 02 AB CD"
            assert server.trace is None
            assert await client.request("03 00 01 00 01") == "03 02 AB CD"
    assert calls == ["received"]
    assert "the trace callback failed; it is detached" in caplog.text


async def test_a_port_in_use_is_one_port_error() -> None:
    from aiortu.errors import PortBusy

    async with tcp_server() as server:
        with pytest.raises(PortBusy, match="in use"):
            async with serve(f"tcp://127.0.0.1:{server.port}", {UNIT: device()}):
                pass


def _random_request(rng: random.Random) -> str:
    """A request of a code served over TCP, well framed, its fields often out of range."""
    code = rng.choice([1, 2, 3, 4, 5, 6, 0x0F, 0x10, 0x16, 0x17, 0x18])
    address = rng.choice([0, 1, 5, 14, 15, 16, 0xFFF0])
    if code in (1, 2, 3, 4):
        count = rng.choice([0, 1, 3, 16, 17, 125, 126, 2000, 2001])
        fields = bytes((code,)) + address.to_bytes(2, "big") + count.to_bytes(2, "big")
    elif code in (5, 6):
        value = rng.choice([0xFF00, 0x0000, 0x1234])
        fields = bytes((code,)) + address.to_bytes(2, "big") + value.to_bytes(2, "big")
    elif code in (0x0F, 0x10):
        count = rng.randint(1, 10)
        size = (count + 7) // 8 if code == 0x0F else 2 * count
        data = bytes(rng.randrange(256) for _ in range(size))
        head = bytes((code,)) + address.to_bytes(2, "big") + count.to_bytes(2, "big")
        fields = head + bytes((size,)) + data
    elif code == 0x16:
        masks = bytes(rng.randrange(256) for _ in range(4))
        fields = bytes((code,)) + address.to_bytes(2, "big") + masks
    elif code == 0x17:
        count = rng.randint(1, 4)
        read = address.to_bytes(2, "big") + rng.choice([0, 2, 126]).to_bytes(2, "big")
        write = rng.choice([0, 3]).to_bytes(2, "big") + count.to_bytes(2, "big")
        data = bytes(rng.randrange(256) for _ in range(2 * count))
        fields = bytes((code,)) + read + write + bytes((2 * count,)) + data
    else:
        fields = bytes((code,)) + rng.choice([0x04DE, 0x0001]).to_bytes(2, "big")
    return fields.hex(" ")


async def test_random_requests_answered_as_on_a_serial_line() -> None:
    seed = _seed()
    rng = random.Random(seed)
    requests = [_random_request(rng) for _ in range(120)]
    tcp_store, serial_store = device(), device()
    async with tcp_server({UNIT: tcp_store}) as server, connect(server) as client:
        tcp = [await client.request(pdu, transaction_id=n) for n, pdu in enumerate(requests)]
    async with slave_line({UNIT: serial_store}) as (master, _):
        serial = [await master.request(UNIT, pdu) for pdu in requests]
    for request, over_tcp, over_serial in zip(requests, tcp, serial, strict=True):
        assert over_tcp == over_serial, f"seed {seed} (AIORTU_TCP_SEED={seed}): {request}"
    for table in (Table.COILS, Table.HOLDING_REGISTERS):
        same = tcp_store.get(table, 0, 16) == serial_store.get(table, 0, 16)
        assert same, f"seed {seed} (AIORTU_TCP_SEED={seed})"


async def test_rtu_over_tcp_logs_a_burst_of_refused_lines_once(
    caplog: pytest.LogCaptureFixture,
) -> None:
    with caplog.at_level(logging.WARNING, logger="aiortu"):
        async with serve("rtu+tcp://127.0.0.1:0", {UNIT: device()}, max_connections=1) as server:
            assert isinstance(server, RtuOverTcpServer)
            async with await anyio.connect_tcp("127.0.0.1", server.port):
                for _ in range(20):
                    async with await anyio.connect_tcp("127.0.0.1", server.port) as refused:
                        with pytest.raises((anyio.EndOfStream, anyio.BrokenResourceError)):
                            with anyio.fail_after(5):
                                await refused.receive()
            assert server.counters.connections_refused == 20
    assert sum("the most allowed" in record.getMessage() for record in caplog.records) == 1


async def test_rtu_over_tcp_connections_share_one_device() -> None:
    # Listen-only mode and the counters are the device's: set from one connection, seen
    # from another, as masters sharing a serial device server's line see one device.
    from aiortu.core.rtu import decode_frame, encode_frame

    async def ask(stream: anyio.abc.ByteStream, pdu: str) -> bytes | None:
        await stream.send(encode_frame(UNIT, bytes.fromhex(pdu)))
        with anyio.move_on_after(0.3):
            return decode_frame(await stream.receive()).pdu
        return None

    async with (
        serve("rtu+tcp://127.0.0.1:0", {UNIT: device()}) as server,
        await anyio.connect_tcp("127.0.0.1", server.port) as first,
        await anyio.connect_tcp("127.0.0.1", server.port) as second,
    ):
        assert await ask(first, "03 0000 0001") is not None
        assert await ask(second, "08 000B 0000") == bytes.fromhex("08 000B 0002")
        assert await ask(first, "08 0004 0000") is None  # listen-only: no reply
        assert await ask(second, "03 0000 0001") is None  # the device is silent for all
        assert await ask(second, "08 0001 0000") is None  # restarted, from listen-only
        assert await ask(first, "03 0000 0001") is not None


def test_units_1_to_247_are_served_and_others_refused_in_one_sentence() -> None:
    ModbusTcpServer({1: device(), 247: device()})
    for unit in (0, 248):
        with pytest.raises(InvalidValue) as raised:
            ModbusTcpServer({unit: device()})
        assert str(raised.value) == f"unit = {unit} is outside the allowed range 1..247"

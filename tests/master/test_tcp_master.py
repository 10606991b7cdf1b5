"""The master over Modbus TCP: the same API, transaction ids matched, reconnects, timeouts."""

from __future__ import annotations

import itertools
from collections.abc import AsyncIterator, Awaitable, Callable
from contextlib import asynccontextmanager

import anyio
import anyio.abc
import anyio.streams.stapled
import pytest

import aiortu
from aiortu.core.codes import MBAP_UNIT_IDS, SERIAL_UNIT_IDS, DeviceIdReadCode, UnitIds
from aiortu.core.mbap import Adu, AduDecoder, encode_adu
from aiortu.core.pdu import ExceptionPDU, RawPDU
from aiortu.errors import ExceptionResponse, PortNotFound, ResponseTimeout
from aiortu.line import Link
from aiortu.slave import RequestContext, Table
from aiortu.testing import MockLine
from aiortu.transport import AsciiStream, ModbusTcpCounters, ModbusTcpStream, PushConnectionStream
from tests.slave.tcp_helpers import UNIT, device, tcp_server

pytestmark = pytest.mark.timeout(30)

FAST = {"timeout": 2.0, "retries": 0, "reconnect_delay": (0.01, 0.05)}


def url(port: int) -> str:
    return f"tcp://127.0.0.1:{port}"


async def until(condition: Callable[[], bool]) -> None:
    """Wait, looking every 5 ms, until `condition()` holds (at most 5 s)."""
    with anyio.fail_after(5):
        for _ in itertools.count():
            if condition():
                return
            await anyio.sleep(0.005)


def counters(master: aiortu.Master) -> ModbusTcpCounters:
    stream = master.link.stream
    assert isinstance(stream, ModbusTcpStream | PushConnectionStream)
    return stream.counters


async def test_every_master_method_against_the_modbus_tcp_server() -> None:
    store = device()
    async with (
        tcp_server({UNIT: store}) as server,
        aiortu.open_master(url(server.port), **FAST) as master,
    ):
        assert await master.read_coils(UNIT, 0, 4) == [True, False, True, True]
        assert await master.read_discrete_inputs(UNIT, 0, 3) == [False, True, True]
        assert await master.read_holding_registers(UNIT, 0, 3) == [0x1234, 0xABCD, 7]
        assert await master.read_input_registers(UNIT, 1, 2) == [22, 33]
        await master.write_coil(UNIT, 1, True)
        await master.write_register(UNIT, 3, 0x63)
        await master.write_coils(UNIT, 4, [True, False, True])
        await master.write_registers(UNIT, 4, [1, 2, 3])
        await master.mask_write_register(UNIT, 0, 0xF2, 0x25)
        assert store.get(Table.COILS, 0, 7) == [1, 1, 1, 1, 1, 0, 1]
        assert store.get(Table.HOLDING_REGISTERS, 3, 4) == [0x63, 1, 2, 3]
        assert store.get(Table.HOLDING_REGISTERS, 0, 1) == [(0x1234 & 0xF2) | (0x25 & ~0xF2)]
        assert await master.read_write_registers(UNIT, 4, 2, 8, [5, 6]) == [1, 2]
        assert await master.read_fifo_queue(UNIT, 0x04DE) == [440, 25]
        assert await master.read_file_record(UNIT, [(4, 1, 2)]) == [[0x04BE, 0x100D]]
        await master.write_file_record(UNIT, [(4, 3, [9, 8])])
        assert await master.read_file_record(UNIT, [(4, 3, 2)]) == [[9, 8]]
        objects = await master.read_device_identification(UNIT)
        assert objects == {0: b"aiortu", 1: b"SIM", 2: b"1.0"}
        one = await master.read_device_identification(UNIT, DeviceIdReadCode.INDIVIDUAL, 1)
        assert one == {1: b"SIM"}
        # Serial-line codes are sent as asked; this server refuses them by default.
        with pytest.raises(ExceptionResponse) as refused:
            await master.read_exception_status(UNIT)
        assert refused.value.code == 1
        handle = master.slave(UNIT)
        assert await handle.read_coils(0, 2) == [True, True]
        assert counters(master).dropped == 0
        assert counters(master).requests == counters(master).replies


async def test_serial_line_codes_when_the_server_answers_them() -> None:
    async with (
        tcp_server(serial_line_codes=True) as server,
        aiortu.open_master(url(server.port), **FAST) as master,
    ):
        assert await master.read_exception_status(UNIT) == 0x6D
        diagnostics = await master.diagnostics(UNIT, 0, b"\xa5\x37")
        assert diagnostics is not None
        assert diagnostics.data == b"\xa5\x37"
        assert (await master.report_server_id(UNIT)).server_id == b"\x11"
        await master.get_comm_event_counter(UNIT)
        await master.get_comm_event_log(UNIT)
        with pytest.raises(ExceptionResponse) as refused:
            await master.read_holding_registers(UNIT, 0xFF00, 2)
        assert refused.value.code == 2


async def test_a_code_of_unknown_length_is_a_whole_frame_at_once() -> None:
    def echo(request: RawPDU, context: RequestContext) -> RawPDU:
        return RawPDU(0x41, request.data[::-1])

    async with (
        tcp_server(handlers={0x41: echo}) as server,
        aiortu.open_master(url(server.port), **FAST) as master,
    ):
        reply = await master.execute(UNIT, RawPDU(0x41, b"\x01\x02\x03"))
        assert reply == RawPDU(0x41, b"\x03\x02\x01")
        refused = await master.execute(UNIT, RawPDU(0x42, b""))
        assert isinstance(refused, ExceptionPDU)
        assert refused.exception_code == 1
        # No wire: no t3.5 before a request, no wire time, and each chunk ends its frame.
        link = master.link
        assert (link.frame_gap, link.char_time, link.receiver.frame_silence) == (0, 0, 0)


async def test_a_link_on_a_byte_stream_keeps_the_serial_timing() -> None:
    left, right = anyio.create_memory_object_stream[bytes](1)
    from anyio.streams.stapled import StapledObjectStream

    stream = StapledObjectStream(left, right)
    link = Link(stream)  # type: ignore[arg-type]
    assert link.frame_gap == link.settings.t3_5
    assert link.char_time > 0
    await left.aclose()
    await right.aclose()


Answer = Callable[[anyio.abc.SocketStream, Adu], Awaitable[None]]


@asynccontextmanager
async def fake_server(answer: Answer, close_after: int = 0) -> AsyncIterator[int]:
    """A raw Modbus TCP server calling `answer` for each request ADU; it closes each
    connection after `close_after` requests (0: never). Yields its port."""

    async def serve(stream: anyio.abc.SocketStream) -> None:
        decoder = AduDecoder()
        served = 0
        async with stream:
            while True:
                try:
                    data = await stream.receive()
                except (anyio.EndOfStream, anyio.BrokenResourceError):
                    return
                for adu in decoder.feed(data):
                    await answer(stream, adu)
                    served += 1
                    if served == close_after:
                        return

    listener = await anyio.create_tcp_listener(local_host="127.0.0.1", local_port=0)
    async with listener, anyio.create_task_group() as group:
        group.start_soon(listener.serve, serve)
        yield listener.extra(anyio.abc.SocketAttribute.local_port)
        group.cancel_scope.cancel()


def registers(adu: Adu, *values: int) -> bytes:
    """A reply to a register read with the ADU's ids and `values`."""
    data = b"".join(value.to_bytes(2, "big") for value in values)
    return encode_adu(adu.transaction_id, adu.unit, bytes((3, len(data))) + data)


async def test_a_reply_with_another_transaction_id_is_dropped_and_counted() -> None:
    async def answer(stream: anyio.abc.SocketStream, adu: Adu) -> None:
        # The same shape, other values: a stale id and an unknown one, then the reply.
        stale = Adu((adu.transaction_id - 1) & 0xFFFF, adu.unit, adu.pdu)
        unknown = Adu(0xBEEF, adu.unit, adu.pdu)
        await stream.send(registers(stale, 666) + registers(unknown, 777))
        await stream.send(registers(adu, 42))

    async with fake_server(answer) as port, aiortu.open_master(url(port), **FAST) as master:
        for _ in range(3):
            assert await master.read_holding_registers(1, 0, 1) == [42]
        assert counters(master).dropped == 6
        assert counters(master).replies == 3
        assert master.unit_stats(1).successes == 3


async def test_a_late_reply_after_a_timeout_never_answers_the_next_request() -> None:
    first: list[Adu] = []

    async def answer(stream: anyio.abc.SocketStream, adu: Adu) -> None:
        if not first:
            first.append(adu)  # no reply in time
            return
        await stream.send(registers(first[0], 666))  # the late reply comes now
        await stream.send(registers(adu, 42))

    async with fake_server(answer) as port, aiortu.open_master(url(port), **FAST) as master:
        with pytest.raises(ResponseTimeout):
            await master.read_holding_registers(1, 0, 1, timeout=0.1)
        assert await master.read_holding_registers(1, 0, 1) == [42]
        assert counters(master).dropped == 1
        assert master.unit_stats(1).timeouts == 1


async def test_the_master_reconnects_when_the_server_closes_the_connection() -> None:
    async def answer(stream: anyio.abc.SocketStream, adu: Adu) -> None:
        await stream.send(registers(adu, adu.transaction_id))

    async with (
        fake_server(answer, close_after=1) as port,
        aiortu.open_master(url(port), **FAST) as master,
    ):
        ids = []
        for served in range(1, 4):
            await master.connection.wait_connected()
            ids += await master.read_holding_registers(1, 0, 1)
            await until(lambda n=served: master.connection.disconnects == n)  # server closed
        assert master.connection.reconnects >= 2
        # Transaction ids go on across connections: no reply can match an older request.
        assert ids == [0, 1, 2]
        assert counters(master).requests == 3


async def test_a_malformed_header_closes_the_connection_and_the_master_reconnects() -> None:
    async def answer(stream: anyio.abc.SocketStream, adu: Adu) -> None:
        if adu.transaction_id == 0:
            await stream.send(b"\x00\x00\x00\x07\x00\x03\x01\x03\x00")  # protocol id 7
        else:
            await stream.send(registers(adu, 5))

    async with fake_server(answer) as port, aiortu.open_master(url(port), **FAST) as master:
        with pytest.raises(aiortu.ConnectionLost):
            await master.read_holding_registers(1, 0, 1)
        await until(lambda: master.connection.reconnects == 1)
        assert await master.read_holding_registers(1, 0, 1) == [5]
        assert master.connection.reconnects == 1


async def test_a_server_that_never_answers_times_out() -> None:
    async def answer(stream: anyio.abc.SocketStream, adu: Adu) -> None:
        return

    async with (
        fake_server(answer) as port,
        aiortu.open_master(url(port), timeout=0.05, retries=1) as master,
    ):
        with pytest.raises(ResponseTimeout):
            await master.read_holding_registers(1, 0, 1)
        assert master.unit_stats(1).timeouts == 2
        assert counters(master).requests == 2


async def test_nothing_listening_is_a_port_error() -> None:
    listener = await anyio.create_tcp_listener(local_host="127.0.0.1", local_port=0)
    port = listener.extra(anyio.abc.SocketAttribute.local_port)
    await listener.aclose()
    with pytest.raises(PortNotFound, match=r"\btcp://127\.0\.0\.1:\d+: connection refused"):
        async with aiortu.open_master(url(port)):
            pass


async def test_many_callers_share_one_connection() -> None:
    store = aiortu.MemoryStore(holding_registers={0: list(range(100, 164))})
    results: dict[int, list[int]] = {}

    async def read(master: aiortu.Master, address: int) -> None:
        results[address] = await master.read_holding_registers(UNIT, address, 2)

    async with (
        tcp_server({UNIT: store}) as server,
        aiortu.open_master(url(server.port), **FAST) as master,
    ):
        async with anyio.create_task_group() as group:
            for address in range(0, 60, 3):
                group.start_soon(read, master, address)
        assert counters(master).requests == 20
    assert results == {address: [100 + address, 101 + address] for address in range(0, 60, 3)}


async def test_unit_ids_255_and_0_are_unicasts_over_modbus_tcp() -> None:
    # The MBAP header carries the unit id as given: 255 for a device reached by its IP
    # address, 0 an ordinary id whose reply is awaited; the server maps both to its unit.
    async with (
        tcp_server() as server,
        aiortu.open_master(url(server.port), **FAST) as master,
    ):
        assert master.unit_range == range(256)
        assert await master.read_holding_registers(255, 0, 2) == [0x1234, 0xABCD]
        assert await master.read_holding_registers(0, 0, 2) == [0x1234, 0xABCD]
        assert await master.slave(255).read_input_registers(1, 1) == [22]
        assert master.unit_stats(255).successes == 2
        with pytest.raises(aiortu.InvalidRequest):
            await master.read_holding_registers(256, 0, 1)
        # A broadcast asked for is still one: sent, and no reply awaited.
        await master.broadcast.write_register(3, 9)


@asynccontextmanager
async def silent_server(scheme: str) -> AsyncIterator[tuple[str, list[bytes]]]:
    """A Modbus TCP or UDP server on loopback that reads every request and answers none:
    its URL, and the chunks (TCP) or datagrams (UDP) it received."""
    received: list[bytes] = []
    async with anyio.create_task_group() as tasks:
        if scheme == "tcp":
            listener = await anyio.create_tcp_listener(local_host="127.0.0.1", local_port=0)
            port = listener.extra(anyio.abc.SocketAttribute.local_port)

            async def read(stream: anyio.abc.SocketStream) -> None:
                async for chunk in stream:
                    received.append(chunk)

            tasks.start_soon(listener.serve, read)
        else:
            socket = await anyio.create_udp_socket(local_host="127.0.0.1")
            port = socket.extra(anyio.abc.SocketAttribute.local_port)

            async def read_datagrams() -> None:
                async for datagram, _ in socket:
                    received.append(datagram)

            tasks.start_soon(read_datagrams)
        yield f"{scheme}://127.0.0.1:{port}", received
        tasks.cancel_scope.cancel()


@pytest.mark.parametrize("scheme", ["tcp", "udp"])
async def test_unit_0_over_mbap_goes_offline_and_fails_fast_like_any_unit(scheme: str) -> None:
    # Over Modbus TCP and UDP unit 0 is an ordinary id (its reply awaited), so the unit
    # health counts it, marks it offline and refuses it, as any other; a broadcast asked
    # for awaits no reply and still goes.
    options = {"timeout": 0.05, "retries": 0, "offline_after": 2, "late_reply_guard": 0.001}
    async with (
        silent_server(scheme) as (address, received),
        aiortu.open_master(address, fail_fast_offline=True, **options) as master,
    ):
        for _ in range(2):
            with pytest.raises(ResponseTimeout):
                await master.read_holding_registers(0, 0, 1)
        await until(lambda: len(b"".join(received)) == 2 * 12)
        assert not master.is_online(0)
        with pytest.raises(aiortu.UnitOffline):
            await master.read_holding_registers(0, 0, 1)
        assert master.unit_stats(0).requests == 2
        assert master.is_online(1)
        await master.broadcast.write_register(3, 9)
        await until(lambda: len(b"".join(received)) == 3 * 12)
        assert master.unit_stats(0).failures == 2


async def test_a_serial_line_master_keeps_units_1_to_247() -> None:
    from aiortu.testing import PtyBus

    async with (
        PtyBus() as bus,
        aiortu.open_master(bus.paths[0], parity="N", stopbits=2, timeout=0.1) as master,
    ):
        assert master.unit_range == range(1, 248)
        for unit in (0, 248, 255):
            with pytest.raises(aiortu.InvalidRequest):
                await master.read_holding_registers(unit, 0, 1)


class DeclaredStream(anyio.abc.ByteStream):
    """A stream of frames that says which unit ids its framing carries, and carries nothing."""

    def __init__(self, unit_ids: UnitIds) -> None:
        self._unit_ids = unit_ids

    @property
    def whole_frames(self) -> bool:
        return True

    @property
    def unit_ids(self) -> UnitIds:
        return self._unit_ids

    async def send(self, item: bytes) -> None:
        pass

    async def receive(self, max_bytes: int = 65536) -> bytes:
        await anyio.sleep_forever()
        raise AssertionError  # never reached

    async def send_eof(self) -> None:
        pass

    async def aclose(self) -> None:
        pass


@pytest.mark.parametrize(
    ("stream", "unit_ids"),
    [
        (DeclaredStream(MBAP_UNIT_IDS), MBAP_UNIT_IDS),
        (DeclaredStream(SERIAL_UNIT_IDS), SERIAL_UNIT_IDS),
        (ModbusTcpStream(DeclaredStream(SERIAL_UNIT_IDS)), MBAP_UNIT_IDS),
        (AsciiStream(DeclaredStream(MBAP_UNIT_IDS)), SERIAL_UNIT_IDS),
    ],
)
def test_the_unit_ids_are_what_the_stream_declares(stream: object, unit_ids: UnitIds) -> None:
    # The master takes them from the stream, whatever its class: an MBAP framing's 0..255,
    # each awaited; a serial line's 0..247, 0 the broadcast.
    master = aiortu.Master(stream)  # type: ignore[arg-type]
    assert master.unit_ids == unit_ids
    assert master.unit_range == unit_ids.unicast
    assert master.unit_stats(unit_ids.ids[-1]).requests == 0
    with pytest.raises(aiortu.InvalidRequest):
        master.unit_stats(unit_ids.ids.stop)


def test_a_stream_that_declares_nothing_carries_a_serial_line() -> None:
    # RTU frames on any byte stream, or a seam in its place.
    send, receive = anyio.create_memory_object_stream[bytes]()
    for master in (
        aiortu.Master(anyio.streams.stapled.StapledObjectStream(send, receive)),  # type: ignore[arg-type]
        aiortu.Master(MockLine(lambda unit, request: None)),  # type: ignore[arg-type, return-value]
    ):
        assert master.unit_ids == SERIAL_UNIT_IDS
        assert master.unit_range == range(1, 248)
        assert master.unit_stats(0).requests == 0  # unit 0 counts the broadcasts
    send.close()
    receive.close()


async def test_modbus_ascii_keeps_units_1_to_247_though_its_frames_come_whole() -> None:
    from aiortu.testing import PtyBus

    async with (
        PtyBus() as bus,
        aiortu.open_master(
            bus.paths[0], parity="N", stopbits=2, timeout=0.1, framing="ascii"
        ) as master,
    ):
        assert master.link.whole_frames
        assert master.unit_range == range(1, 248)

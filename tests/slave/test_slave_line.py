"""The slave on a line: what it answers, what it drops, when it replies, and its handlers."""

from __future__ import annotations

import logging

import anyio
import pytest

from aiortu.core.pdu import RawPDU, ReadHoldingRegistersRequest
from aiortu.core.rtu import encode_frame
from aiortu.errors import ConnectionLost, ExceptionResponse, InvalidValue
from aiortu.slave import Change, MemoryStore, RequestContext, Slave, Table
from aiortu.testing import virtual_pair

from .helpers import UNIT, example_store, slave_line


def corrupt(frame: bytes) -> bytes:
    return frame[:-1] + bytes((frame[-1] ^ 0x01,))


async def test_bad_crc_gets_no_reply_and_is_counted() -> None:
    async with slave_line() as (master, slave):
        await master.send(corrupt(encode_frame(UNIT, bytes.fromhex("03 00 6B 00 03"))))
        await master.assert_silent_then_alive()
    assert slave.counters.bus_communication_error_count == 1
    assert slave.counters.bus_message_count == 1


async def test_other_units_get_no_reply_and_are_counted() -> None:
    async with slave_line() as (master, slave):
        await master.send_request(18, "03 00 6B 00 03")
        await anyio.sleep(0.03)
        # Another slave's reply, as it would cross the bus.
        await master.send(encode_frame(18, bytes.fromhex("03 06 AE 41 56 52 43 40")))
        await master.assert_silent_then_alive()
    assert slave.counters.other_unit_count == 2
    assert slave.counters.bus_message_count == 3
    assert slave.counters.server_message_count == 1


async def test_each_unit_answers_from_its_own_store() -> None:
    first = MemoryStore(holding_registers={0: [1]})
    second = MemoryStore(holding_registers={0: [2]})
    async with slave_line({1: first, 2: second}) as (master, _):
        assert await master.request(1, "03 00 00 00 01") == "03 02 00 01"
        assert await master.request(2, "03 00 00 00 01") == "03 02 00 02"


async def test_broadcast_write_is_executed_by_every_unit_and_not_answered() -> None:
    first = example_store()
    second = MemoryStore(holding_registers={0: 4})
    async with slave_line({UNIT: first, 5: second}) as (master, slave):
        await master.send_request(0, "06 00 01 12 34")
        await master.assert_silent_then_alive()
        assert first.get(Table.HOLDING_REGISTERS, 1) == [0x1234]
        assert second.get(Table.HOLDING_REGISTERS, 1) == [0x1234]
    assert slave.counters.server_no_response_count == 1


@pytest.mark.parametrize(
    "pdu",
    ["06 00 30 12 34", "05 00 AC 12 34", "10 00 01 00 02 02 00 01", "41 00", "03 00 00 00 00"],
)
async def test_invalid_broadcast_gets_no_exception(pdu: str) -> None:
    async with slave_line() as (master, slave):
        await master.send_request(0, pdu)
        await master.assert_silent_then_alive()
    assert slave.counters.bus_exception_error_count == 0
    assert slave.counters.server_no_response_count == 1


async def test_listen_only_monitors_and_neither_executes_nor_answers() -> None:
    # The spec: in listen-only mode messages are monitored, no action is taken and no
    # response sent.
    store = example_store()
    async with slave_line({UNIT: store}) as (master, slave):
        slave.listen_only = True
        await master.send_request(UNIT, "06 00 01 00 07")
        assert await master.receive_frame(0.05) is None
        slave.listen_only = False
        await master.assert_silent_then_alive()
    assert store.get(Table.HOLDING_REGISTERS, 1) == [0]
    assert slave.counters.server_no_response_count == 1


async def test_reply_waits_for_frame_gap_of_silence() -> None:
    gap = 0.08
    async with slave_line(frame_gap=gap) as (master, _):
        sent = anyio.current_time()
        await master.send_request(UNIT, "03 00 6B 00 03")
        frame = await master.receive_frame()
        elapsed = anyio.current_time() - sent
    assert frame is not None
    assert gap <= elapsed < gap + 0.5


async def test_reply_with_no_frame_gap_is_prompt() -> None:
    async with slave_line(frame_gap=0.0, frame_silence=0.05) as (master, _):
        sent = anyio.current_time()
        await master.send_request(UNIT, "03 00 6B 00 03")
        frame = await master.receive_frame()
        elapsed = anyio.current_time() - sent
    assert frame is not None
    # The frame's length is known, so it is answered without waiting for silence.
    assert elapsed < 0.05


async def test_failing_handler_gives_04_and_the_slave_goes_on(
    caplog: pytest.LogCaptureFixture,
) -> None:
    def explode(request: RawPDU, context: RequestContext) -> RawPDU:
        raise RuntimeError("boom")

    async with slave_line(handlers={0x41: explode}) as (master, slave):
        with caplog.at_level(logging.ERROR, logger="aiortu.slave._slave"):
            assert await master.request(UNIT, "41 01") == "C1 04"
        assert await master.request(UNIT, "03 00 6B 00 01") == "03 02 AE 41"
    assert "boom" in caplog.text
    assert slave.counters.bus_exception_error_count == 1


async def test_store_failure_gives_04() -> None:
    class Broken:
        def read(self, table: Table, address: int, count: int) -> list[int]:
            raise OSError("disk on fire")

        def write(self, table: Table, address: int, values: object) -> None:
            raise OSError("disk on fire")

    async with slave_line({UNIT: Broken()}) as (master, _):
        assert await master.request(UNIT, "03 00 00 00 01") == "83 04"
        assert await master.request(UNIT, "06 00 00 00 01") == "86 04"


async def test_custom_sync_and_async_handlers() -> None:
    def echo_reversed(request: RawPDU, context: RequestContext) -> RawPDU:
        return RawPDU(request.function_code, request.data[::-1])

    async def slow_unit(request: RawPDU, context: RequestContext) -> RawPDU:
        await anyio.sleep(0.01)
        return RawPDU(request.function_code, bytes((context.unit,)))

    async def refuse(request: RawPDU, context: RequestContext) -> RawPDU:
        raise ExceptionResponse(0x06)

    async with slave_line() as (master, slave):
        slave.set_handler(0x41, echo_reversed)
        slave.handler(0x64)(slow_unit)
        slave.set_handler(0x6E, refuse)
        assert await master.request(UNIT, "41 01 02 03") == "41 03 02 01"
        assert await master.request(UNIT, "64") == "64 11"
        assert await master.request(UNIT, "6E") == "EE 06"
        slave.set_handler(0x41, None)
        assert await master.request(UNIT, "41 01") == "C1 01"
    assert slave.counters.server_busy_count == 1


async def test_replacing_a_builtin_handler() -> None:
    def constant(request: ReadHoldingRegistersRequest, context: RequestContext) -> RawPDU:
        return RawPDU(3, bytes((2 * request.count,)) + b"\x00\x2a" * request.count)

    async with slave_line(handlers={3: constant}) as (master, _):
        assert await master.request(UNIT, "03 00 00 00 02") == "03 04 00 2A 00 2A"


async def test_handler_returning_none_sends_nothing() -> None:
    async with slave_line(handlers={0x42: lambda request, context: None}) as (master, slave):
        await master.send_request(UNIT, "42")
        await master.assert_silent_then_alive()
    assert slave.counters.server_no_response_count == 1


async def test_observers_see_master_writes() -> None:
    store = example_store()
    seen: list[Change] = []
    remove = store.observe(seen.append)
    async with slave_line({UNIT: store}) as (master, _):
        with store.changes() as feed:
            await master.request(UNIT, "10 00 01 00 02 04 00 0A 01 02")
            await master.request(UNIT, "05 00 AC FF 00")
            first = await anext(feed)
            second = await anext(feed)
    remove()
    assert seen == [first, second]
    assert first == Change(Table.HOLDING_REGISTERS, 1, (0x000A, 0x0102), (0, 0))
    assert second == Change(Table.COILS, 0xAC, (True,), (False,))


async def test_serve_ends_with_connection_lost_when_the_line_closes() -> None:
    master_end, slave_end = virtual_pair()
    slave = Slave(slave_end, {UNIT: example_store()}, frame_gap=0)
    async with slave:
        await master_end.aclose()
        with anyio.fail_after(2):
            await slave.wait_stopped()
    assert isinstance(slave.connection_error, ConnectionLost)


async def test_serve_in_the_current_task_raises_connection_lost() -> None:
    master_end, slave_end = virtual_pair()
    slave = Slave(slave_end, {UNIT: example_store()})
    await master_end.aclose()
    with pytest.raises(ConnectionLost), anyio.fail_after(2):
        await slave.serve()


@pytest.mark.parametrize("unit", [0, 248, -1])
async def test_bad_unit_addresses_are_refused(unit: int) -> None:
    _, slave_end = virtual_pair()
    with pytest.raises(InvalidValue):
        Slave(slave_end, {unit: example_store()})


async def test_bad_function_code_for_a_handler_is_refused() -> None:
    async with slave_line() as (_, slave):
        with pytest.raises(InvalidValue):
            slave.set_handler(0x80, lambda request, context: None)

"""The master's methods against a fake slave: the right request on the wire, the reply decoded."""

from __future__ import annotations

import math

import anyio
import pytest

import aiortu
from aiortu.core.codes import DeviceIdReadCode
from aiortu.core.model import Layout, encode_value
from aiortu.core.pdu import ExceptionPDU, RawPDU, ReadHoldingRegistersRequest
from aiortu.errors import InvalidRequest
from tests.virtual_clock import on_virtual_clock

from .fakes import FakeSlave, coil_value, line, register_value, standard_reply


@on_virtual_clock
async def test_reads_return_the_values_trimmed_to_the_count() -> None:
    async with line() as (master, slave, _):
        assert await master.read_holding_registers(17, 0x6B, 3) == [
            register_value(17, 0x6B + i) for i in range(3)
        ]
        assert await master.read_input_registers(2, 10, 2) == [
            register_value(2, 10) ^ 0xFFFF,
            register_value(2, 11) ^ 0xFFFF,
        ]
        coils = await master.read_coils(3, 0x13, 19)
        assert coils == [coil_value(3, 0x13 + i) for i in range(19)]
        inputs = await master.read_discrete_inputs(4, 7, 5)
        assert inputs == [coil_value(4, 7 + i) for i in range(5)]
        assert [seen.unit for seen in slave.seen] == [17, 2, 3, 4]


@on_virtual_clock
async def test_writes_send_the_request_and_verify_the_echo() -> None:
    async with line() as (master, slave, _):
        await master.write_coil(1, 5, True)
        await master.write_register(1, 6, 0xBEEF)
        await master.write_coils(1, 7, [True, False, True])
        await master.write_registers(1, 0x10, [1, 2, 3])
        await master.mask_write_register(1, 4, 0xF2, 0x25)
        sent = [seen.request for seen in slave.seen]
        assert [request.function_code for request in sent] == [0x05, 0x06, 0x0F, 0x10, 0x16]
        assert sent[3].values == (1, 2, 3)  # type: ignore[attr-defined]


@on_virtual_clock
async def test_a_write_whose_echo_differs_is_not_accepted() -> None:
    async def wrong_echo(slave: FakeSlave, unit: int, request: object) -> None:
        await slave.reply(unit, bytes.fromhex("06 00 06 00 01"))

    async with line(default=wrong_echo, retries=0, timeout=0.05) as (master, _, _):
        with pytest.raises(aiortu.MalformedPDU):
            await master.write_register(1, 6, 0xBEEF)


@on_virtual_clock
async def test_the_other_function_codes() -> None:
    async with line() as (master, _, _):
        assert await master.read_write_registers(9, 100, 2, 200, [7, 8]) == [
            register_value(9, 100),
            register_value(9, 101),
        ]
        assert await master.read_fifo_queue(9, 0x4D2) == [0x4D2, 2, 3]
        assert await master.read_file_record(9, [(4, 1, 2), (3, 9, 1)]) == [[5, 6], [12]]
        await master.write_file_record(9, [(4, 7, [0x6AF, 0x1234])])
        assert await master.read_exception_status(9) == 0x55
        diagnostics = await master.diagnostics(9, 0, b"\xa5\x37")
        assert diagnostics is not None
        assert diagnostics.data == b"\xa5\x37"
        counter = await master.get_comm_event_counter(9)
        assert counter.event_count == 7
        log = await master.get_comm_event_log(9)
        assert log.message_count == 9
        assert log.events == b"\x20\x00"
        server = await master.report_server_id(9)
        assert server.server_id == b"\x09"
        assert server.run_indicator


@on_virtual_clock
async def test_device_identification_follows_more_follows() -> None:
    async with line() as (master, slave, _):
        objects = await master.read_device_identification(5)
        assert objects == {0: b"aiortu", 1: b"FAKE-1", 2: b"1.0"}
        assert len(slave.seen) == 2
        one = await master.read_device_identification(5, DeviceIdReadCode.INDIVIDUAL, 1)
        assert one == {1: b"FAKE-1"}


@on_virtual_clock
async def test_execute_takes_custom_codes_and_returns_exceptions_as_values() -> None:
    async def refuse(slave: FakeSlave, unit: int, request: object) -> None:
        await slave.reply(unit, bytes((0x41 | 0x80, 0x01)))

    async with line() as (master, _, _):
        reply = await master.execute(3, RawPDU(0x41, b"\x01\x02\x03"))
        assert reply == RawPDU(0x41, b"\x03\x02\x01")
    async with line(default=refuse) as (master, _, _):
        reply = await master.execute(3, RawPDU(0x41, b"\x01"))
        assert isinstance(reply, ExceptionPDU)
        assert reply.exception_code == 1


@on_virtual_clock
async def test_diagnostics_force_listen_only_awaits_no_reply() -> None:
    async with line(turnaround_delay=0.01) as (master, slave, _):
        assert await master.diagnostics(4, 4) is None
        await anyio.sleep(0.01)
        assert slave.seen[0].request.function_code == 0x08


@on_virtual_clock
async def test_the_unit_handle_and_typed_values() -> None:
    float_registers = encode_value(123.456, "float32", Layout.CDAB)

    async def floats(slave: FakeSlave, unit: int, request: object) -> None:
        assert isinstance(request, ReadHoldingRegistersRequest)
        await slave.reply(
            unit, bytes((3, 4)) + b"".join(r.to_bytes(2, "big") for r in float_registers)
        )

    async with line(script={4: floats}) as (master, slave, _):
        device = master.slave(17)
        assert await device.read_holding_registers(0, 2) == [17000, 17001]
        assert await device.read_reference("40108", 2) == [
            register_value(17, 107),
            register_value(17, 108),
        ]
        assert await device.read_reference("000020", 3) == [
            coil_value(17, 19 + i) for i in range(3)
        ]
        await device.write_float32(10, 1.5, Layout.CDAB)
        assert slave.seen[3].request.values == encode_value(1.5, "float32", Layout.CDAB)  # type: ignore[attr-defined]
        value = await device.read_float32(10, Layout.CDAB)
        assert math.isclose(value, 123.456, rel_tol=1e-6)
        assert await device.read_string(0, 1) == bytes((0x42, 0x68)).decode()
        with pytest.raises(InvalidRequest):
            master.slave(0)


@pytest.mark.parametrize(
    ("call", "args"),
    [
        ("read_holding_registers", (0, 0, 1)),
        ("read_holding_registers", (248, 0, 1)),
        ("read_holding_registers", (True, 0, 1)),
        ("read_input_registers", ("1", 0, 1)),
        ("read_input_registers", (1.0, 0, 1)),
        ("read_input_registers", (1, 0, 126)),
        ("read_holding_registers", (1, 0, 0)),
        ("read_holding_registers", (1, 0, 126)),
        ("read_holding_registers", (1, 65535, 2)),
        ("read_coils", (1, 0, 2001)),
        ("write_register", (1, 0, 70000)),
        ("write_register", (1, 65536, 1)),
        ("write_registers", (1, 0, [])),
        ("write_registers", (1, 0, [0] * 124)),
        ("write_coils", (1, 0, [True] * 1969)),
        ("mask_write_register", (1, 0, -1, 0)),
        ("read_write_registers", (1, 0, 126, 0, [1])),
        ("read_file_record", (1, [(0, 0, 1)])),
        ("diagnostics", (1, 1, b"\x12\x34")),
        ("execute", (0, RawPDU(0x41))),
    ],
)
async def test_invalid_requests_raise_before_anything_is_sent(call: str, args: tuple) -> None:
    async with line() as (master, slave, bus):
        with pytest.raises(InvalidRequest):
            await getattr(master, call)(*args)
        await anyio.sleep(0.01)
        assert not bus.trace
        assert not slave.seen
        assert master.engine.transactions == 0


@pytest.mark.parametrize("bad", [0, -1.0, float("nan"), float("inf"), True, "1"])
async def test_a_call_timeout_must_be_positive(bad: float) -> None:
    async with line() as (master, _, bus):
        for read in (master.read_holding_registers, master.read_coils):
            with pytest.raises(InvalidRequest, match=r"^timeout must be .* seconds > 0, not "):
                await read(1, 0, 1, timeout=bad)
        await anyio.sleep(0.01)
        assert not bus.trace
        assert await master.read_holding_registers(1, 0, 1, timeout=0.5) is not None


@on_virtual_clock
async def test_a_read_cannot_be_broadcast() -> None:
    async with line() as (master, _, bus):
        with pytest.raises(InvalidRequest):
            await master.send_without_reply(0, ReadHoldingRegistersRequest(0, 1))
        assert not bus.trace


@on_virtual_clock
async def test_broadcast_waits_the_turnaround_and_no_reply() -> None:
    async with line(turnaround_delay=0.05) as (master, slave, _):
        start = anyio.current_time()
        await master.broadcast.write_register(0x10, 7)
        await master.broadcast.write_coils(0, [True, False])
        await master.broadcast.write_registers(1, [1, 2])
        await master.broadcast.write_coil(1, True)
        await master.broadcast.mask_write_register(1, 0xFF, 0)
        await master.broadcast.write_file_record([(1, 0, [5])])
        elapsed = anyio.current_time() - start
        assert 6 * 0.05 <= elapsed < 6 * 0.05 + 0.2
        await anyio.sleep(0.01)
        assert [seen.unit for seen in slave.seen] == [0] * 6
        gaps = [b.time - a.time for a, b in zip(slave.seen, slave.seen[1:], strict=False)]
        assert min(gaps) >= 0.05 - 0.005
        # The reply the fake could give is nobody's: nothing was awaited or matched.
        assert master.unit_stats(0).requests == 6
        assert standard_reply(1, slave.seen[0].request)  # a normal unicast would be answered

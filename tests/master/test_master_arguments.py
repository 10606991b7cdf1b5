"""The master's arguments are checked in the caller's task, before anything is queued or
sent; a bad one never reaches another caller, the line or the unit's health."""

from __future__ import annotations

import contextlib
import math

import anyio
import pytest

import aiortu
from aiortu.core.codes import FunctionCode
from aiortu.core.machines import SAFE_TO_REPEAT, Failure
from aiortu.core.pdu import RawPDU, Request, Response, WriteSingleRegisterResponse
from aiortu.core.rtu import encode_frame
from aiortu.errors import InvalidRequest, InvalidValue, ModbusError
from aiortu.master import Master
from aiortu.testing import VirtualBus
from tests.virtual_clock import on_virtual_clock

from .fakes import FakeSlave, line, register_value, standard_reply


@on_virtual_clock
async def test_bad_priorities_fail_at_once_and_leave_the_queue_to_the_others() -> None:
    results: dict[object, object] = {}

    async def call(master: Master, priority: object) -> None:
        try:
            results[priority] = await master.read_holding_registers(
                9,
                0,
                2,
                priority=priority,  # type: ignore[arg-type]
            )
        except ModbusError as error:
            results[priority] = error

    priorities: list[object] = [0, "x", 1, None, 2, 1.5]
    async with line() as (master, slave, _):
        async with anyio.create_task_group() as callers:
            for priority in priorities:
                callers.start_soon(call, master, priority)
        for bad in ("x", None, 1.5):
            error = results[bad]
            assert isinstance(error, InvalidRequest)
            assert str(error).startswith("priority ")
        for good in (0, 1, 2):
            assert results[good] == [register_value(9, 0), register_value(9, 1)]
        assert len(slave.seen) == 3
        # At once: in the call's first step, before it ever waits for the line.
        for bad in ("x", None, 1.5):
            call_step = master.read_holding_registers(9, 0, 2, priority=bad)  # type: ignore[arg-type]
            with pytest.raises(InvalidRequest):
                call_step.send(None)
        # The queue is sound for later callers too.
        assert await master.read_holding_registers(9, 1, 1, priority=5) == [register_value(9, 1)]


@pytest.mark.parametrize(
    ("call", "args", "field"),
    [
        ("read_holding_registers", (17, 2.0, 1), "address"),
        ("read_holding_registers", (17, 0, 3.0), "count"),
        ("read_holding_registers", (17, 0, True), "count"),
        ("read_coils", (17.0, 0, 1), "unit"),
        ("write_register", (17, 0, True), "value"),
        ("write_register", (17, 0, 1.0), "value"),
        ("write_registers", (17, 0, b"\x01\x02"), "values"),
        ("write_registers", (17, 0, [1, True]), "values[1]"),
        ("write_registers", (17, 0, [1, 2.0]), "values[1]"),
        ("write_registers", (17, 0, "12"), "values"),
        ("write_coil", (17, 1, "off"), "value"),
        ("write_coil", (17, 1, "no"), "value"),
        ("write_coil", (17, 1, "0"), "value"),
        ("write_coil", (17, 1, 2), "value"),
        ("write_coil", (17, 1, None), "value"),
        ("write_coils", (17, 0, ["no"]), "values[0]"),
        ("write_coils", (17, 0, [True, 2]), "values[1]"),
        ("write_coils", (17, 0, "10"), "values"),
        ("read_write_registers", (17, 0, 1, 0, [70000]), "values[0]"),
        ("read_file_record", (17, [(1.0, 0, 1)]), "file_number"),
        ("read_file_record", (17, None), "sub_requests"),
        ("write_file_record", (17, [(1, 0, [1.5])]), "values[0]"),
        ("diagnostics", (17, 0.0), "sub_function"),
    ],
)
async def test_a_bad_argument_raises_before_anything_is_sent(
    call: str, args: tuple[object, ...], field: str
) -> None:
    async with line() as (master, slave, bus):
        with pytest.raises(InvalidRequest) as raised:
            await getattr(master, call)(*args)
        assert raised.value.field == field
        assert str(raised.value).startswith(f"{field} ")
        assert "\n" not in str(raised.value)
        await anyio.sleep(0.01)
        assert not bus.trace
        assert not slave.seen


@on_virtual_clock
async def test_coil_values_the_spec_and_python_agree_on() -> None:
    async with line() as (master, slave, _):
        for value in (True, 1, 0xFF00):
            await master.write_coil(17, 1, value)
        for value in (False, 0, 0x0000):
            await master.write_coil(17, 1, value)
        await master.write_coils(17, 0, [1, 0, True, False])
        sent = [seen.request for seen in slave.seen]
        assert [request.value for request in sent[:6]] == [True] * 3 + [False] * 3  # type: ignore[attr-defined]
        assert sent[6].values == (True, False, True, False)  # type: ignore[attr-defined]


@pytest.mark.parametrize(
    ("setting", "value"),
    [
        ("timeout", 0),
        ("timeout", math.nan),
        ("timeout", "1"),
        ("retries", -1),
        ("retries", 1.0),
        ("retry_on", ["timeout"]),
        ("retry_on", [999]),
        ("retry_on", "timeout"),
        ("repeatable", [0x41, 200]),
        ("late_reply_guard", -1),
        ("late_reply_guard", math.nan),
        ("offline_after", 0),
        ("offline_after", 2.5),
        ("probe_interval", -1),
        ("turnaround_delay", math.inf),
        ("frame_gap", -0.1),
        ("fail_fast_offline", "yes"),
        ("reconnect", 1),
        ("reconnect_delay", (0, 1)),
        ("reconnect_delay", (2, 1)),
        ("reconnect_delay", 5),
        ("timing", "loose"),
        ("settings", 19200),
        ("clock", 5.0),
        ("opener", "/dev/ttyUSB0"),
    ],
)
def test_a_bad_setting_is_refused_when_the_master_is_made(setting: str, value: object) -> None:
    bus = VirtualBus(2)
    with pytest.raises(InvalidValue) as raised:
        Master(bus.endpoints[0], **{setting: value})  # type: ignore[arg-type]
    assert str(raised.value).startswith(f"{setting} ")


def test_good_settings_are_taken() -> None:
    bus = VirtualBus(2)
    master = Master(
        bus.endpoints[0],
        timeout=2,
        retry_on=[Failure.TIMEOUT, 6],
        repeatable=[0x41],
        late_reply_guard=0,
        probe_interval=0,
        timing="strict",
    )
    assert master.policy.retry_on == {Failure.TIMEOUT, 6}
    assert master.policy.repeatable == {0x41}


@on_virtual_clock
async def test_a_raw_pdu_of_a_known_code_gets_its_reply() -> None:
    # Write single register as raw bytes: the reply, decoded as 06's, answers it.
    async with line(offline_after=1) as (master, slave, _):
        reply = await master.execute(17, RawPDU(0x06, bytes.fromhex("0001 0003")))
        assert reply == WriteSingleRegisterResponse(1, 3)
        assert len(slave.seen) == 1
        assert master.is_online(17)
        with pytest.raises(InvalidRequest):
            await master.execute(17, RawPDU(0x06, b"\x00"))
        assert len(slave.seen) == 1


def late_by(delay: float):  # type: ignore[no-untyped-def]
    async def step(slave: FakeSlave, unit: int, request: Request) -> None:
        await anyio.sleep(delay)
        await slave.reply(unit, standard_reply(unit, request))

    return step


@on_virtual_clock
async def test_a_custom_code_is_sent_once_unless_the_caller_says_so() -> None:
    # A 0x41 handler that answers after 150 ms, a call with timeout=0.1.
    async with line(default=late_by(0.15), retries=2) as (master, slave, _):
        with pytest.raises(aiortu.ResponseTimeout):
            await master.execute(17, RawPDU(0x41, b"\x01"), timeout=0.1)
        await anyio.sleep(0.1)
        assert len(slave.seen) == 1
    # Said so: the request goes again (and may take the late reply to the first).
    async with line(default=late_by(0.15), retries=2, repeatable=[0x41]) as (master, slave, _):
        with contextlib.suppress(aiortu.ResponseTimeout):
            await master.execute(17, RawPDU(0x41, b"\x01"), timeout=0.1)
        assert len(slave.seen) > 1


@pytest.mark.parametrize("code", [0x17, 0x08])
async def test_codes_that_are_not_safe_to_repeat_are_sent_once(code: int) -> None:
    async def silent_then_nothing(slave: FakeSlave, unit: int, request: Request) -> None:
        pass

    async with line(default=silent_then_nothing, retries=2, timeout=0.05) as (master, slave, _):
        call = (
            master.read_write_registers(17, 0, 1, 0, [1])
            if code == 0x17
            else master.diagnostics(17, 0x01)
        )
        with pytest.raises(aiortu.ResponseTimeout):
            await call
        assert len(slave.seen) == 1
        # A write that is safe to repeat is repeated.
        with pytest.raises(aiortu.ResponseTimeout):
            await master.write_register(17, 0, 1)
        assert len(slave.seen) == 4


def test_the_default_repeats_reads_and_idempotent_writes_only() -> None:
    reads = {0x01, 0x02, 0x03, 0x04, 0x07, 0x0B, 0x0C, 0x11, 0x14, 0x18, 0x2B}
    writes = {0x05, 0x06, 0x0F, 0x10, 0x15, 0x16}
    assert reads | writes == SAFE_TO_REPEAT
    assert FunctionCode.READ_WRITE_MULTIPLE_REGISTERS not in SAFE_TO_REPEAT


@on_virtual_clock
async def test_the_first_crc_failure_after_opening_is_a_crc_error() -> None:
    async def bad_crc(slave: FakeSlave, unit: int, request: Request) -> None:
        frame = bytearray(encode_frame(unit, standard_reply(unit, request)))
        frame[-1] ^= 0xFF
        await slave.send_raw(bytes(frame))

    bus = VirtualBus(2)
    slave = FakeSlave(bus.endpoints[1], default=bad_crc)
    async with anyio.create_task_group() as tasks:
        tasks.start_soon(slave.run)
        # No wait for the receivers to leave INIT: the first reply comes while the
        # master's receiver still waits for the line's first silence.
        async with Master(
            bus.endpoints[0], aiortu.LineSettings(1_000_000), frame_gap=0, timeout=0.1
        ) as master:
            with pytest.raises(aiortu.CRCError):
                await master.read_holding_registers(3, 0, 2)
            stats = master.unit_stats(3)
            assert (stats.crc_errors, stats.frame_errors) == (3, 0)
        tasks.cancel_scope.cancel()


@on_virtual_clock
async def test_broadcast_values_are_checked_too() -> None:
    async with line() as (master, _, bus):
        with pytest.raises(InvalidRequest):
            await master.broadcast.write_coil(1, "off")  # type: ignore[arg-type]
        with pytest.raises(InvalidRequest):
            await master.broadcast.write_coils(1, ["no"])  # type: ignore[list-item]
        with pytest.raises(InvalidRequest):
            await master.broadcast.write_registers(1, b"\x01\x02")  # type: ignore[arg-type]
        with pytest.raises(InvalidRequest):
            await master.broadcast.write_register(1, 1, priority="x")  # type: ignore[arg-type]
        await anyio.sleep(0.01)
        assert not bus.trace


@on_virtual_clock
async def test_open_master_checks_its_settings_before_opening_the_port() -> None:
    # The port does not exist: the setting is refused before it is looked for.
    with pytest.raises(InvalidValue, match=r"^late_reply_guard "):
        async with aiortu.open_master("/dev/aiortu-no-such-port", late_reply_guard=-1):
            pass


@on_virtual_clock
async def test_reads_follow_the_repeatable_codes_too() -> None:
    async def silent(slave: FakeSlave, unit: int, request: Request) -> None:
        pass

    async with line(default=silent, retries=2, timeout=0.05, repeatable=[]) as (master, slave, _):
        with pytest.raises(aiortu.ResponseTimeout):
            await master.read_holding_registers(17, 0, 1)
        assert len(slave.seen) == 1
        with pytest.raises(InvalidRequest, match=r"^retries "):
            await master.request(17, slave.seen[0].request, Response, retries=-1)


@on_virtual_clock
async def test_a_typed_value_is_refused_before_the_read_goes_out() -> None:
    async with line() as (master, slave, bus):
        handle = master.slave(17)
        with pytest.raises(InvalidValue, match=r"^layout must be .*, not 'XYZW'"):
            await handle.read_float32(0, layout="XYZW")
        with pytest.raises(InvalidValue, match=r"^kind must be .*, not 'float16'"):
            await handle.read_value(0, "float16")
        with pytest.raises(InvalidValue, match=r"^encoding "):
            await handle.read_string(0, 2, encoding="no-such-codec")
        with pytest.raises(InvalidRequest, match=r"^table "):
            await handle.read_float32(0, table="coils")
        await anyio.sleep(0.01)
        assert not bus.trace
        assert not slave.seen

"""The late reply: a reply that answers the request of a unit's last timed-out attempt is
that request's reply come too late. It is skipped and counted while the wait goes on; a
misshapen reply that answers no abandoned request still fails the attempt at once.

The sequence that found it: libmodbus's unit-test server at 115200, `retries=0`, a read of
three registers at its slow address times out (`timeout=0.2`), then a read of one register
got the three-register reply and failed with `MalformedPDU: ... byte_count = 6`.
"""

from __future__ import annotations

import functools

import anyio
import pytest

import aiortu
from aiortu.core.machines import MasterMachine, OutcomeKind, RetryPolicy, SkipReason, Transaction
from aiortu.core.pdu import ReadHoldingRegistersRequest, ReadHoldingRegistersResponse, Request
from aiortu.core.serial import LineSettings
from aiortu.errors import MalformedPDU, ResponseTimeout
from aiortu.testing import VirtualBus
from tests.master.fakes import FakeSlave, Step, answer, silent, standard_reply
from tests.virtual_clock import on_virtual_clock

THREE = ReadHoldingRegistersResponse((1, 2, 3)).encode()  # byte count 6
ONE = ReadHoldingRegistersResponse((9,)).encode()
TWO = ReadHoldingRegistersResponse((4, 5)).encode()  # byte count 4: answers neither


def _timed_out_then_waiting(late: int = 3) -> MasterMachine:
    """A machine whose read of `late` registers from unit 1 timed out, now waiting for the
    reply to a read of one register from unit 1 (sent 1.0 to 1.001)."""
    machine = MasterMachine()
    machine.begin(Transaction(1, ReadHoldingRegistersRequest(0x16B, late), 0.2, RetryPolicy(0)))
    machine.sent(0.0, 0.001)
    timed_out = machine.expired(0.201)
    assert timed_out.kind is OutcomeKind.FAILED
    assert isinstance(timed_out.error, ResponseTimeout)
    machine.begin(Transaction(1, ReadHoldingRegistersRequest(0, 1), 0.2, RetryPolicy(0)))
    machine.sent(1.0, 1.001)
    return machine


def test_the_late_reply_to_the_timed_out_request_is_skipped_and_the_wait_goes_on() -> None:
    machine = _timed_out_then_waiting()
    late = machine.frame_received(1, THREE, 1.002, 1.003)
    assert (late.kind, late.skipped) == (OutcomeKind.WAIT, SkipReason.LATE)
    genuine = machine.frame_received(1, ONE, 1.004, 1.005)
    assert genuine.kind is OutcomeKind.DONE
    assert genuine.response == ReadHoldingRegistersResponse((9,))


def test_a_misshapen_reply_that_answers_no_abandoned_request_fails_at_once() -> None:
    machine = _timed_out_then_waiting()
    wrong = machine.frame_received(1, TWO, 1.002, 1.003)
    assert wrong.kind is OutcomeKind.FAILED
    assert isinstance(wrong.error, MalformedPDU)


def test_a_late_reply_is_recognised_once() -> None:
    # The unit sends one reply per request: a second frame of that shape is misshapen.
    machine = _timed_out_then_waiting()
    assert machine.frame_received(1, THREE, 1.002, 1.003).skipped is SkipReason.LATE
    again = machine.frame_received(1, THREE, 1.004, 1.005)
    assert again.kind is OutcomeKind.FAILED
    assert isinstance(again.error, MalformedPDU)


def test_a_unit_that_answered_awaits_no_late_reply() -> None:
    # The unit answered a later request: it is in step, and a reply of the timed-out
    # request's shape is misshapen again.
    machine = _timed_out_then_waiting()
    assert machine.frame_received(1, ONE, 1.004, 1.005).kind is OutcomeKind.DONE
    machine.begin(Transaction(1, ReadHoldingRegistersRequest(0, 1), 0.2, RetryPolicy(0)))
    machine.sent(2.0, 2.001)
    assert machine.frame_received(1, THREE, 2.002, 2.003).kind is OutcomeKind.FAILED


def test_the_late_reply_of_another_unit_is_not_taken_for_this_ones() -> None:
    machine = _timed_out_then_waiting()
    machine.transaction.unit = 2  # type: ignore[union-attr]  # the same request, to unit 2
    other = machine.frame_received(2, THREE, 1.002, 1.003)
    assert other.kind is OutcomeKind.FAILED  # unit 2 timed out nothing: misshapen


SLOW_ADDRESS = 0x16B
"""libmodbus's UT_REGISTERS_ADDRESS_SLEEP_500_MS."""


async def _libmodbus_like(slave: FakeSlave, unit: int, request: Request) -> None:
    """libmodbus's unit-test server: one request at a time; at the slow address the reply
    comes 0.5 s late."""
    if isinstance(request, ReadHoldingRegistersRequest) and request.address == SLOW_ADDRESS:
        await anyio.sleep(0.5)
    await answer(slave, unit, request)


@pytest.mark.parametrize("fast_path", [True, False])
async def test_the_libmodbus_sequence_on_a_virtual_line(fast_path: bool) -> None:
    settings = LineSettings(115200, parity="N")
    bus = VirtualBus(2, settings=settings)
    slave = FakeSlave(bus.endpoints[1], frozenset({1}), {}, _libmodbus_like)
    master = aiortu.Master(bus.endpoints[0], settings, timeout=0.2, retries=0, fast_path=fast_path)
    async with anyio.create_task_group() as tasks:
        tasks.start_soon(slave.run)
        async with master:
            with pytest.raises(ResponseTimeout):
                await master.read_holding_registers(1, SLOW_ADDRESS, 3)
            with anyio.fail_after(2):
                # Its own timeout leaves room for the reply after the late one (0.5 s
                # after the first request; this one goes out after 0.3 s).
                values = await master.read_holding_registers(1, 0, 1, timeout=1.0)
            assert values == list(
                ReadHoldingRegistersResponse.decode(
                    standard_reply(1, ReadHoldingRegistersRequest(0, 1))
                ).values
            )
            stats = master.unit_stats(1)
            assert stats.late_replies == 1
            assert (stats.successes, stats.failures, stats.timeouts) == (1, 1, 1)
        tasks.cancel_scope.cancel()


async def _late_by(seconds: float, slave: FakeSlave, unit: int, request: Request) -> None:
    await anyio.sleep(seconds)
    await answer(slave, unit, request)


@on_virtual_clock
async def test_a_unit_that_answers_only_late_goes_offline_though_its_replies_are_taken() -> None:
    # Each reply comes 0.15 s after its request, the timeout is 0.1 s and no guard is kept:
    # every read times out once, and its retry takes the first attempt's reply. The caller
    # gets its values; the unit's health counts each as a failure.
    bus = VirtualBus(2)
    slave = FakeSlave(bus.endpoints[1], frozenset({1}), {}, functools.partial(_late_by, 0.15))
    master = aiortu.Master(
        bus.endpoints[0], LineSettings(1_000_000), timeout=0.1, late_reply_guard=0, frame_gap=0
    )
    async with anyio.create_task_group() as tasks:
        tasks.start_soon(slave.run)
        async with master:
            for _ in range(3):
                assert await master.read_holding_registers(1, 0, 1) == [1000]
            stats = master.unit_stats(1)
            assert (stats.successes, stats.late_successes, stats.timeouts) == (3, 3, 3)
            assert not master.is_online(1)
        tasks.cancel_scope.cancel()


@on_virtual_clock
async def test_a_reply_in_time_after_a_lost_request_keeps_the_unit_online() -> None:
    # One timed-out attempt then a reply in time: one failure in a row, not three.
    def script() -> dict[int, Step]:
        return {0: silent}

    bus = VirtualBus(2)
    slave = FakeSlave(bus.endpoints[1], frozenset({1}), script(), answer)
    master = aiortu.Master(bus.endpoints[0], LineSettings(1_000_000), timeout=0.1, frame_gap=0)
    async with anyio.create_task_group() as tasks:
        tasks.start_soon(slave.run)
        async with master:
            assert await master.read_holding_registers(1, 0, 1) == [1000]
            assert await master.read_holding_registers(1, 0, 1) == [1000]
            stats = master.unit_stats(1)
            assert (stats.late_successes, stats.consecutive_failures, stats.online) == (1, 0, True)
        tasks.cancel_scope.cancel()

"""The master's state machine: the table, the deadlines, matching and the retry policy."""

from __future__ import annotations

import pytest
from hypothesis import given
from hypothesis import strategies as st

from aiortu.core.errors import CRCError, FrameError, MalformedPDU, ResponseTimeout
from aiortu.core.machines import (
    Failure,
    MasterEvent,
    MasterMachine,
    MasterMachineError,
    MasterState,
    OutcomeKind,
    RetryPolicy,
    SkipReason,
    Transaction,
)
from aiortu.core.machines._master_machine import TRANSITIONS, next_state
from aiortu.core.pdu import (
    RawRegisterRead,
    ReadHoldingRegistersRequest,
    ReadHoldingRegistersResponse,
    ReadInputRegistersRequest,
    WriteSingleRegisterRequest,
)

REPLY = ReadHoldingRegistersResponse((1, 2)).encode()


@given(st.sampled_from(MasterState), st.sampled_from(MasterEvent))
def test_every_pair_goes_where_the_table_says_or_raises(
    state: MasterState, event: MasterEvent
) -> None:
    if (state, event) in TRANSITIONS:
        assert next_state(state, event) is TRANSITIONS[state, event][0]
    else:
        with pytest.raises(MasterMachineError):
            next_state(state, event)


operations = st.lists(
    st.sampled_from(["begin", "sent", "reply", "other", "bad", "expire", "lost"]), max_size=30
)


@given(operations, st.integers(0, 2))
def test_the_machine_only_takes_transitions_from_the_table(ops: list[str], retries: int) -> None:
    seen: list[tuple[MasterState, MasterEvent, MasterState]] = []
    machine = MasterMachine(on_transition=lambda *step: seen.append(step))
    now = 0.0
    for op in ops:
        now += 0.3
        try:
            if op == "begin":
                request = ReadHoldingRegistersRequest(0, 2)
                machine.begin(Transaction(1, request, 0.5, RetryPolicy(retries)))
            elif op == "sent":
                machine.sent(now - 0.001, now)
            elif op == "reply":
                machine.frame_received(1, REPLY, now, now)
            elif op == "other":
                machine.frame_received(2, REPLY, now, now)
            elif op == "bad":
                machine.frame_error(FrameError("noise"), now)
            elif op == "expire":
                machine.expired(now)
            else:
                machine.connection_lost(ConnectionError("gone"))
        except MasterMachineError:
            pass
    for state, event, target in seen:
        assert TRANSITIONS[state, event][0] is target
    # Transient states never outlive a call.
    assert machine.state not in (MasterState.PROCESSING_REPLY, MasterState.PROCESSING_ERROR)


def started(timeout: float = 1.0, retries: int = 0, **options: object) -> MasterMachine:
    machine = MasterMachine()
    request = ReadHoldingRegistersRequest(0, 2)
    machine.begin(Transaction(1, request, timeout, RetryPolicy(retries), **options))  # type: ignore[arg-type]
    return machine


def test_the_deadline_counts_from_the_end_of_transmission() -> None:
    machine = started(timeout=0.5)
    assert machine.sent(10.0, 10.004) == pytest.approx(10.504)
    assert machine.state is MasterState.WAITING_REPLY
    assert machine.expired(10.5).kind is OutcomeKind.WAIT
    outcome = machine.expired(10.504)
    assert outcome.kind is OutcomeKind.FAILED
    assert isinstance(outcome.error, ResponseTimeout)
    assert machine.state is MasterState.IDLE


def test_stale_other_unit_and_other_function_frames_are_skipped() -> None:
    machine = started()
    machine.sent(10.0, 10.004)
    assert machine.frame_received(1, REPLY, 9.0, 9.9).skipped is SkipReason.STALE
    assert machine.frame_received(2, REPLY, 10.0, 10.01).skipped is SkipReason.OTHER_UNIT
    other = WriteSingleRegisterRequest(0, 1).encode()
    assert machine.frame_received(1, other, 10.0, 10.01).skipped is SkipReason.OTHER_FUNCTION
    outcome = machine.frame_received(1, REPLY, 10.0, 10.02)
    assert outcome.kind is OutcomeKind.DONE
    assert outcome.response == ReadHoldingRegistersResponse((1, 2))


MISSHAPEN = {
    "one register for two": ReadHoldingRegistersResponse((1,)).encode(),
    "three registers for two": ReadHoldingRegistersResponse((1, 2, 3)).encode(),
    "byte count off": bytes((0x03, 0x05, 0, 1, 0, 2)),
    "truncated": bytes((0x03, 0x04, 0, 1)),
    "exception without its code": bytes((0x83,)),
}


@pytest.mark.parametrize("pdu", MISSHAPEN.values(), ids=MISSHAPEN.keys())
@pytest.mark.parametrize("observed", [False, True])
def test_a_misshapen_reply_from_the_unit_asked_fails_the_attempt_at_once(
    pdu: bytes, observed: bool
) -> None:
    seen: list[tuple[MasterState, MasterEvent, MasterState]] = []
    machine = MasterMachine(on_transition=(lambda *step: seen.append(step)) if observed else None)
    machine.begin(Transaction(1, ReadHoldingRegistersRequest(0, 2), 3.0, RetryPolicy(0)))
    machine.sent(10.0, 10.004)
    outcome = machine.frame_received(1, pdu, 10.01, 10.02)
    assert outcome.kind is OutcomeKind.FAILED  # at once, not after the 3 s timeout
    assert isinstance(outcome.error, MalformedPDU)
    assert machine.state is MasterState.IDLE
    assert machine.transaction is not None
    assert machine.transaction.failures == [Failure.FRAME_ERROR]
    if observed:
        assert (MasterState.PROCESSING_REPLY, MasterEvent.REPLY_MALFORMED) in {
            (state, event) for state, event, _ in seen
        }


def test_a_misshapen_reply_is_retried_as_a_frame_error() -> None:
    machine = started(retries=1)
    machine.sent(10.0, 10.004)
    one = ReadHoldingRegistersResponse((1,)).encode()
    assert machine.frame_received(1, one, 10.01, 10.02).kind is OutcomeKind.RETRY
    machine.sent(11.0, 11.004)
    assert machine.frame_received(1, REPLY, 11.01, 11.02).kind is OutcomeKind.DONE


def test_a_misshapen_frame_from_another_unit_or_stale_is_skipped() -> None:
    machine = started()
    machine.sent(10.0, 10.004)
    one = ReadHoldingRegistersResponse((1,)).encode()
    assert machine.frame_received(2, one, 10.01, 10.02).skipped is SkipReason.OTHER_UNIT
    assert machine.frame_received(1, one, 9.0, 9.9).skipped is SkipReason.STALE
    assert machine.state is MasterState.WAITING_REPLY


def test_retries_follow_the_policy() -> None:
    machine = started(retries=1)
    machine.sent(0.0, 0.001)
    assert machine.expired(2.0).kind is OutcomeKind.RETRY
    machine.sent(2.0, 2.001)
    assert machine.expired(4.0).kind is OutcomeKind.FAILED
    assert machine.transaction is not None
    assert machine.transaction.failures == [Failure.TIMEOUT, Failure.TIMEOUT]


def test_exception_replies_are_not_retried_by_default() -> None:
    machine = started(retries=3)
    machine.sent(0.0, 0.001)
    outcome = machine.frame_received(1, bytes((0x83, 0x02)), 0.01, 0.02)
    assert outcome.kind is OutcomeKind.DONE
    assert outcome.response is not None


def test_a_frame_error_shortens_the_wait_and_is_the_failure() -> None:
    machine = started(timeout=1.0)
    machine.sent(0.0, 0.001)
    error = CRCError(1, 2)
    assert machine.frame_error(error, 0.1).kind is OutcomeKind.WAIT
    assert machine.deadline == pytest.approx(0.1 + machine.frame_error_grace)
    outcome = machine.expired(0.2)
    assert outcome.error is error


def test_abandoned_transactions_are_not_retried() -> None:
    machine = started(retries=3)
    machine.sent(0.0, 0.001)
    assert machine.transaction is not None
    machine.transaction.abandoned = True
    assert machine.expired(2.0).kind is OutcomeKind.FAILED


def test_a_broadcast_waits_the_turnaround() -> None:
    machine = started(expects_reply=False, turnaround=0.1)
    assert machine.sent(0.0, 0.004) == pytest.approx(0.104)
    assert machine.state is MasterState.WAITING_TURNAROUND
    assert machine.frame_received(1, REPLY, 0.05, 0.05).kind is OutcomeKind.WAIT
    assert machine.expired(0.1).kind is OutcomeKind.WAIT
    assert machine.expired(0.105).kind is OutcomeKind.DONE
    assert machine.state is MasterState.IDLE


def test_a_second_transaction_cannot_begin_mid_way() -> None:
    machine = started()
    machine.sent(0.0, 0.001)
    with pytest.raises(MasterMachineError):
        machine.begin(Transaction(1, ReadHoldingRegistersRequest(0, 1), 1.0))


register_replies = st.one_of(
    st.binary(max_size=12),
    st.builds(
        lambda function, values: (
            bytes([function, 2 * len(values)]) + b"".join(v.to_bytes(2, "big") for v in values)
        ),
        st.sampled_from([3, 4, 0x83, 6]),
        st.lists(st.integers(0, 0xFFFF), max_size=4),
    ),
)


usual_reply_cases = given(
    st.sampled_from([ReadHoldingRegistersRequest, ReadInputRegistersRequest]),
    st.integers(1, 4),
    st.integers(0, 3),
    register_replies,
    st.sampled_from([9.5, 10.0, 10.01]),
)
"""A register read of 1..4 registers to unit 1 (unit 3 stands for a read sent to unit 2),
any frame from unit 0..3 ending before, at or after the request began."""


@usual_reply_cases
def test_the_usual_reply_in_one_step_equals_the_table_step_by_step(
    kind: type[ReadHoldingRegistersRequest],
    count: int,
    unit: int,
    pdu: bytes,
    end: float,
) -> None:
    """Without an observer the machine takes a register read's usual reply in one step;
    with one it fires every transition: the outcome and the state must be the same."""
    seen: list[tuple[MasterState, MasterEvent, MasterState]] = []
    results = []
    for machine in (MasterMachine(), MasterMachine(on_transition=lambda *s: seen.append(s))):
        machine.begin(Transaction(2 if unit == 3 else 1, kind(0, count), 1.0))
        machine.sent(10.0, 10.004)
        outcome = machine.frame_received(unit, pdu, end - 0.001, end)
        results.append((outcome, machine.state, machine.deadline, machine.transaction))
    assert results[0][:3] == results[1][:3]
    assert results[0][3] is not None
    assert results[1][3] is not None
    assert repr(results[0][3].frame_error) == repr(results[1][3].frame_error)
    for state, event, target in seen:
        assert TRANSITIONS[state, event][0] is target


@usual_reply_cases
def test_the_usual_response_equals_receiving_the_reply(
    kind: type[ReadHoldingRegistersRequest],
    count: int,
    unit: int,
    pdu: bytes,
    end: float,
) -> None:
    """A frame of the usual reply's shape, taken without the machine, gives the response
    frame_received gives; a frame of any other shape is left to the machine."""
    frame = bytes([unit]) + pdu + b"\x00\x00"  # the CRC is the link's to check
    request = kind(0, count)
    known = MasterMachine().usual_exchange(1, request)
    assert known is not None
    shape = known.reply_shape
    assert shape == (bytes([1, kind.function_code, 2 * count]), 5 + 2 * count)
    machine = MasterMachine()
    machine.begin(Transaction(1, request, 1.0))
    machine.sent(10.0, 10.004)
    expected = machine.frame_received(unit, pdu, end - 0.001, end)
    if len(frame) == shape[1] and frame.startswith(shape[0]) and end >= 10.0:
        assert expected.kind is OutcomeKind.DONE
        assert MasterMachine.usual_response(known, frame) == expected.response
        assert machine.state is MasterState.IDLE


def test_only_register_reads_on_an_idle_unobserved_machine_have_a_usual_exchange() -> None:
    machine = MasterMachine()
    assert machine.usual_exchange(1, WriteSingleRegisterRequest(0, 1)) is None
    assert machine.usual_exchange(0, ReadHoldingRegistersRequest(0, 1)) is None  # broadcast
    assert machine.usual_exchange(1, ReadInputRegistersRequest(0, 1)) is not None
    machine.begin(Transaction(1, ReadHoldingRegistersRequest(0, 1), 1.0))
    machine.sent(10.0, 10.004)
    assert machine.usual_exchange(1, ReadHoldingRegistersRequest(0, 1)) is None  # busy
    # With an observer every transition must be seen: no shortcut.
    observed = MasterMachine(on_transition=lambda *step: None)
    assert observed.usual_exchange(1, ReadHoldingRegistersRequest(0, 1)) is None


@given(
    kind=st.sampled_from([ReadHoldingRegistersRequest, ReadInputRegistersRequest]),
    # A few small values make repeated replies common; the others cover the range.
    replies=st.lists(
        st.lists(st.integers(0, 2) | st.integers(0, 0xFFFF), min_size=2, max_size=2),
        max_size=6,
    ),
)
def test_the_usual_response_is_the_reply_decoded_even_when_remembered(
    kind: type[ReadHoldingRegistersRequest], replies: list[list[int]]
) -> None:
    """A reply equal to the last one gives the same (immutable) response without being
    decoded again; any other is decoded and remembered."""
    machine = MasterMachine()
    request = kind(0, 2)
    known = machine.usual_exchange(1, request)
    assert known is not None
    assert known.reply_shape == (bytes([1, kind.function_code, 4]), 9)
    last = None
    for values in replies:
        frame = bytes([1, kind.function_code, 4]) + b"".join(v.to_bytes(2, "big") for v in values)
        frame += b"\x00\x00"  # the CRC is the link's to check
        response = machine.usual_response(known, bytes(bytearray(frame)))
        assert type(response) is request.response_class
        assert list(response.values) == values  # type: ignore[attr-defined]
        if last is not None and last[0] == frame:
            assert response is last[1]
        assert known.last_reply == frame
        last = (frame, response)
    assert machine.state is MasterState.IDLE
    assert machine.usual_exchange(1, request) is known  # remembered per unit and request


@given(
    code=st.sampled_from([0x03, 0x04]),
    address=st.integers(0, 100),
    count=st.integers(1, 4),
    replies=st.lists(st.binary(min_size=2, max_size=8), max_size=4),
)
def test_a_read_kept_as_bytes_has_the_usual_exchange_of_the_decoded_read(
    code: int, address: int, count: int, replies: list[bytes]
) -> None:
    """A RawRegisterRead has the frame and the usual reply's shape of the decoded read of the
    same bytes, and its usual reply is handed over as those bytes, not decoded."""
    raw = RawRegisterRead(code, bytes.fromhex(f"{address:04X}{count:04X}"))
    decoded = (ReadHoldingRegistersRequest if code == 0x03 else ReadInputRegistersRequest)(
        address, count
    )
    known = MasterMachine().usual_exchange(7, raw)
    expected = MasterMachine().usual_exchange(7, decoded)
    assert known is not None
    assert expected is not None
    assert (known.frame, known.reply_shape) == (expected.frame, expected.reply_shape)
    for words in replies:
        data = (words * count)[: 2 * count].ljust(2 * count, b"\x00")
        frame = bytes((7, code, 2 * count)) + data + b"\x00\x00"  # the link checks the CRC
        response = MasterMachine.usual_response(known, frame)
        assert response.encode() == frame[1:-2]
        assert response.encode() == MasterMachine.usual_response(expected, frame).encode()

"""The slave state machine: the table, the decisions, and the counters."""

from __future__ import annotations

import contextlib

import pytest
from hypothesis import given
from hypothesis import strategies as st

from aiortu.core.machines import (
    SerialLineCounters,
    SlaveEvent,
    SlaveMachine,
    SlaveMachineError,
    SlaveState,
)
from aiortu.core.machines._slave_machine import TRANSITIONS


@given(st.sampled_from(SlaveState), st.sampled_from(SlaveEvent))
def test_every_state_event_pair_follows_the_table_or_raises(
    state: SlaveState, event: SlaveEvent
) -> None:
    machine = SlaveMachine({17})
    machine.state = state
    target = TRANSITIONS.get((state, event))
    if target is None:
        with pytest.raises(SlaveMachineError):
            machine.fire(event)
        assert machine.state is state
    else:
        assert machine.fire(event) is target


def test_every_state_is_reachable_and_returns_to_idle() -> None:
    targets = set(TRANSITIONS.values())
    assert targets == set(SlaveState)
    for state in SlaveState:
        # From every state some path leads back to IDLE.
        seen = {state}
        frontier = [state]
        while frontier:
            current = frontier.pop()
            for (source, _), target in TRANSITIONS.items():
                if source is current and target not in seen:
                    seen.add(target)
                    frontier.append(target)
        assert SlaveState.IDLE in seen


# Steps the slave may take, as (name, argument).
_STEPS = st.lists(
    st.one_of(
        st.tuples(st.just("frame"), st.sampled_from([0, 17, 18, 200])),
        st.tuples(st.just("check"), st.sampled_from([None, 1, 2, 3])),
        st.tuples(st.just("unsupported"), st.none()),
        st.tuples(st.just("processed"), st.none()),
        st.tuples(st.just("failed"), st.sampled_from([2, 4, 6, 7])),
        st.tuples(st.just("sent"), st.none()),
        st.tuples(st.just("silent"), st.none()),
        st.tuples(st.just("corrupt"), st.none()),
        st.tuples(st.just("overrun"), st.none()),
    ),
    max_size=30,
)


def _step(machine: SlaveMachine, name: str, argument: int | None) -> None:
    """Take one of the _STEPS."""
    if name == "frame":
        assert argument is not None
        machine.frame_received(argument, 3)
    elif name == "check":
        machine.check_request(supported=True, violation=argument)
    elif name == "unsupported":
        machine.check_request(supported=False, violation=3)
    elif name == "processed":
        machine.processed()
    elif name == "failed":
        assert argument is not None
        machine.processing_failed(argument)
    elif name == "sent":
        machine.reply_sent()
    elif name == "silent":
        machine.no_reply()
    elif name == "corrupt":
        machine.frame_corrupt()
    else:
        machine.character_overrun()


@given(_STEPS, st.booleans())
def test_random_driving_either_follows_the_table_or_raises(
    steps: list[tuple[str, int | None]], listen_only: bool
) -> None:
    machine = SlaveMachine({17})
    machine.listen_only = listen_only
    for name, argument in steps:
        before = machine.state
        try:
            _step(machine, name, argument)
        except SlaveMachineError:
            # A refused step changes nothing, except reply_sent where no reply may go.
            assert machine.state is before
    counters = machine.counters
    assert counters.server_message_count <= counters.bus_message_count
    assert counters.bus_exception_error_count <= counters.server_message_count
    assert counters.server_no_response_count <= counters.server_message_count
    if listen_only:
        assert counters.bus_exception_error_count == 0


def run_request(
    machine: SlaveMachine,
    unit: int,
    *,
    supported: bool = True,
    violation: int | None = None,
    failure: int | None = None,
) -> tuple[bool, int | None]:
    """Drive one request as the slave does; return (replied, exception code)."""
    if not machine.frame_received(unit):
        return False, None
    if machine.check_request(supported=supported, violation=violation):
        if failure is None:
            machine.processed()
        else:
            machine.processing_failed(failure)
    code = machine.exception_code
    if machine.should_reply:
        machine.reply_sent()
        return True, code
    machine.no_reply()
    return False, code


def test_exception_order_unsupported_before_value_before_address() -> None:
    machine = SlaveMachine({17})
    assert run_request(machine, 17, supported=False, violation=3) == (True, 1)
    assert run_request(machine, 17, violation=3) == (True, 3)
    assert run_request(machine, 17, failure=2) == (True, 2)
    assert run_request(machine, 17, failure=4) == (True, 4)
    assert run_request(machine, 17) == (True, None)
    assert machine.state is SlaveState.IDLE


def test_broadcast_never_answered_and_other_units_dropped() -> None:
    machine = SlaveMachine({17})
    assert run_request(machine, 0) == (False, None)
    assert run_request(machine, 0, violation=3) == (False, 3)
    assert run_request(machine, 0, supported=False) == (False, 1)
    assert run_request(machine, 18) == (False, None)
    machine.frame_received(0)
    machine.check_request(supported=True)
    machine.processed()
    with pytest.raises(SlaveMachineError):
        machine.reply_sent()


def test_counters_follow_the_spec_definitions() -> None:
    machine = SlaveMachine({17, 18})
    run_request(machine, 17)
    run_request(machine, 18, failure=6)
    run_request(machine, 17, failure=7)
    run_request(machine, 17, violation=3)
    run_request(machine, 0)
    run_request(machine, 99)
    machine.frame_corrupt()
    machine.character_overrun()
    machine.listen_only = True
    run_request(machine, 17)
    assert machine.counters == SerialLineCounters(
        bus_message_count=7,
        bus_communication_error_count=1,
        bus_exception_error_count=3,
        server_message_count=6,
        server_no_response_count=2,
        server_nak_count=1,
        server_busy_count=1,
        bus_character_overrun_count=1,
        other_unit_count=1,
    )
    assert machine.counters.word("bus_message_count") == 7
    machine.counters.bus_message_count = 0x10005
    assert machine.counters.word("bus_message_count") == 5
    machine.counters.clear()
    assert machine.counters == SerialLineCounters()


def _machine_after(steps: list[tuple[str, int | None]]) -> SlaveMachine:
    """A machine serving units 17 and 18, driven through *steps*, refusals skipped."""
    machine = SlaveMachine({17, 18})
    for name, argument in steps:
        with contextlib.suppress(SlaveMachineError):
            _step(machine, name, argument)
    return machine


def _snapshot(machine: SlaveMachine) -> tuple[object, ...]:
    return (
        machine.state,
        machine.counters,
        machine.event_log.events(),
        machine.event_log.event_count,
        machine.unit,
        machine.function_code,
        machine.broadcast,
        machine.exception_code,
        machine.should_reply,
    )


@given(_STEPS, st.sampled_from([17, 18]), st.sampled_from([1, 2, 3, 4, 5, 6, 0x0B, 0x0C]))
def test_answered_at_once_equals_the_four_steps(
    steps: list[tuple[str, int | None]], unit: int, function_code: int
) -> None:
    one_step = _machine_after(steps)
    step_by_step = _machine_after(steps)
    if one_step.state is not SlaveState.IDLE:
        with pytest.raises(SlaveMachineError):
            one_step.answered_at_once(unit, function_code)
        return
    one_step.answered_at_once(unit, function_code)
    assert step_by_step.frame_received(unit, function_code)
    assert step_by_step.check_request(supported=True)
    step_by_step.processed()
    step_by_step.reply_sent()
    assert _snapshot(one_step) == _snapshot(step_by_step)


def test_answered_at_once_refuses_what_it_does_not_stand_for() -> None:
    machine = SlaveMachine({17})
    for unit in (0, 5):  # a broadcast, another unit
        with pytest.raises(SlaveMachineError):
            machine.answered_at_once(unit, 3)
    machine.listen_only = True
    with pytest.raises(SlaveMachineError):
        machine.answered_at_once(17, 3)
    assert machine.counters == SerialLineCounters()

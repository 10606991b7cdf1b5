"""The comm event log's bytes, bit by bit as the spec gives them (function code 0C)."""

from __future__ import annotations

import pytest

from aiortu.core.machines import SlaveMachine, receive_event, send_event


@pytest.mark.parametrize(
    ("exception_code", "event"),
    [
        (None, 0x40),
        (1, 0x41),  # bit 0: read exception sent (01 to 03)
        (2, 0x41),
        (3, 0x41),
        (4, 0x42),  # bit 1: server abort exception sent (04)
        (5, 0x44),  # bit 2: server busy exception sent (05, 06)
        (6, 0x44),
        (7, 0x48),  # bit 3: server program NAK exception sent (07)
        (8, 0x40),
        (0x0B, 0x40),
    ],
)
def test_a_send_event_names_the_exception_sent(exception_code: int | None, event: int) -> None:
    assert send_event(exception_code) == event
    assert send_event(exception_code, listen_only=True) == event | 0x20


def test_a_receive_event_sets_a_bit_per_condition() -> None:
    assert receive_event() == 0x80
    assert receive_event(communication_error=True) == 0x82
    assert receive_event(overrun=True) == 0x90
    assert receive_event(listen_only=True) == 0xA0
    assert receive_event(broadcast=True) == 0xC0


def test_a_corrupt_frame_is_logged_as_a_communication_error() -> None:
    machine = SlaveMachine([17])
    machine.frame_corrupt()
    assert machine.event_log.events() == bytes([0x82])
    assert machine.counters.bus_communication_error_count == 1

"""The state diagrams in the docs are the ones the code's transition tables draw."""

from __future__ import annotations

import enum
from collections.abc import Mapping
from pathlib import Path

import pytest

from aiortu.core import ascii
from aiortu.core.machines import _master_machine as master_machine
from aiortu.core.machines import _slave_machine as slave_machine
from aiortu.core.machines import state_diagram
from aiortu.core.rtu import _receiver as receiver

DOCS = Path(__file__).resolve().parents[2] / "docs"

MACHINES: dict[str, tuple[Mapping[tuple[enum.Enum, enum.Enum], object], enum.Enum]] = {
    "receiver": (receiver.TRANSITIONS, receiver.ReceiverState.INIT),
    "ascii receiver": (ascii.ASCII_TRANSITIONS, ascii.AsciiState.IDLE),
    "master": (master_machine.TRANSITIONS, master_machine.MasterState.IDLE),
    "slave": (slave_machine.TRANSITIONS, slave_machine.SlaveState.IDLE),
}


@pytest.mark.parametrize("machine", sorted(MACHINES))
def test_the_protocol_page_draws_each_machine_from_its_table(machine: str) -> None:
    table, initial = MACHINES[machine]
    page = (DOCS / "protocol.md").read_text(encoding="utf-8")
    assert state_diagram(table, initial) in page  # type: ignore[arg-type]


@pytest.mark.parametrize("machine", sorted(MACHINES))
def test_every_entry_of_a_table_is_drawn(machine: str) -> None:
    table, initial = MACHINES[machine]
    drawn = state_diagram(table, initial)  # type: ignore[arg-type]
    for (state, event), entry in table.items():
        target = entry[0] if isinstance(entry, tuple) else entry
        arrows = [line for line in drawn.splitlines() if f"{state.name} --> {target.name}:" in line]
        assert any(event.name in arrow for arrow in arrows), (state, event)

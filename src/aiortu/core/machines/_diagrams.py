"""Draw a state machine's transition table as a Mermaid state diagram.

The documentation's diagrams are generated from the same tables the machines run on
(`python -m aiortu.core.machines._diagrams`), and a test checks that the pages still match, so a
diagram can never drift from the code.
"""

from __future__ import annotations

import enum
from collections.abc import Mapping
from typing import TypeVar

__all__ = ("state_diagram",)

StateT = TypeVar("StateT", bound=enum.Enum)
EventT = TypeVar("EventT", bound=enum.Enum)


def state_diagram(
    transitions: Mapping[tuple[StateT, EventT], tuple[StateT, str] | StateT],
    initial: StateT,
) -> str:
    """A Mermaid `stateDiagram-v2` block with one arrow per (state, event) entry.

    A table maps `(state, event)` to `(next state, action)` or to the next state
    alone. Arrows are labelled `EVENT / action` (or `EVENT`); `initial` gets the start
    marker. Entries that share their source, target and action are merged into one arrow
    whose label lists the events.
    """
    merged: dict[tuple[str, str, str], list[str]] = {}
    for (source, event), entry in transitions.items():
        target, action = entry if isinstance(entry, tuple) else (entry, "")
        merged.setdefault((source.name, target.name, action), []).append(event.name)
    lines = ["```mermaid", "stateDiagram-v2", f"    [*] --> {initial.name}"]
    for (source_name, target_name, action), events in merged.items():
        label = " | ".join(events) + (f" / {action}" if action else "")
        lines.append(f"    {source_name} --> {target_name}: {label}")
    lines.append("```")
    return "\n".join(lines) + "\n"


def _main() -> None:
    from aiortu.core.ascii import ASCII_TRANSITIONS, AsciiState
    from aiortu.core.machines import _master_machine as master_machine
    from aiortu.core.machines import _slave_machine as slave_machine
    from aiortu.core.rtu import RECEIVER_TRANSITIONS, ReceiverState

    print("Receiver:")
    print(state_diagram(RECEIVER_TRANSITIONS, ReceiverState.INIT))
    print("ASCII receiver:")
    print(state_diagram(ASCII_TRANSITIONS, AsciiState.IDLE))
    print("Master:")
    print(state_diagram(master_machine.TRANSITIONS, master_machine.MasterState.IDLE))
    print("Slave:")
    print(state_diagram(slave_machine.TRANSITIONS, slave_machine.SlaveState.IDLE))


if __name__ == "__main__":
    _main()

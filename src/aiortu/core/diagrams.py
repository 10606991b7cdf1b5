"""Draw a state machine's transition table as a Mermaid state diagram.

The documentation's diagrams are generated from the same tables the machines run on
(``python -m aiortu.core.diagrams``), and a test checks that the pages still match, so a
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
    transitions: Mapping[tuple[StateT, EventT], tuple[StateT, str]],
    initial: StateT,
) -> str:
    """A Mermaid ``stateDiagram-v2`` block with one arrow per (state, event) entry.

    Arrows are labelled ``EVENT / action``; *initial* gets the start marker. Entries
    that share their source, target and action are merged into one arrow whose label
    lists the events.
    """
    merged: dict[tuple[str, str, str], list[str]] = {}
    for (source, event), (target, action) in transitions.items():
        merged.setdefault((source.name, target.name, action), []).append(event.name)
    lines = ["```mermaid", "stateDiagram-v2", f"    [*] --> {initial.name}"]
    for (source_name, target_name, action), events in merged.items():
        lines.append(f"    {source_name} --> {target_name}: {' | '.join(events)} / {action}")
    lines.append("```")
    return "\n".join(lines) + "\n"


def _main() -> None:
    from aiortu.core.receiver import TRANSITIONS, ReceiverState

    print("Receiver:")
    print(state_diagram(TRANSITIONS, ReceiverState.INIT))


if __name__ == "__main__":
    _main()

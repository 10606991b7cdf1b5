"""The state diagrams in the docs are the ones the code's transition tables draw."""

from __future__ import annotations

from pathlib import Path

from aiortu.core.diagrams import state_diagram
from aiortu.core.receiver import TRANSITIONS, ReceiverState

DOCS = Path(__file__).resolve().parent.parent / "docs"


def test_the_receiver_diagram_matches_its_table() -> None:
    page = (DOCS / "protocol.md").read_text(encoding="utf-8")
    assert state_diagram(TRANSITIONS, ReceiverState.INIT) in page


def test_the_diagram_has_one_arrow_per_merged_entry() -> None:
    drawn = state_diagram(TRANSITIONS, ReceiverState.INIT)
    arrows = [line for line in drawn.splitlines() if "-->" in line and "[*]" not in line]
    sources = {
        (state.name, target.name, action) for (state, _), (target, action) in TRANSITIONS.items()
    }
    assert len(arrows) == len(sources)

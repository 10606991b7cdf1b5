"""What the built site shows a reader: the state diagrams drawn offline, as SVG (no script
from a CDN), each drawn in full and legible; API summaries that are whole sentences; and a
docs extra that builds without a warning about formatting signatures."""

from __future__ import annotations

import html
import re
import sys
import tomllib
from pathlib import Path

import griffe
import pytest
import yaml

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT / "docs_hooks"))

from griffe_summaries import FirstParagraphSummaries, first_paragraph_on_one_line  # noqa: E402
from state_diagrams import FENCE, _clutter, _place, parse, render  # noqa: E402

PROTOCOL = (ROOT / "docs" / "protocol.md").read_text(encoding="utf-8")
BLOCKS = [found.group(1) for found in FENCE.finditer(PROTOCOL)]
DOCUMENTED = [
    "master",
    "slave",
    "testing",
    "gateway",
    "transport",
    "line",
    "errors",
    "core",
    "blocking",
]


IDS = [f"diagram {index + 1} ({parse(block).states[1]})" for index, block in enumerate(BLOCKS)]


def test_the_protocol_page_has_its_machines() -> None:
    # The receiver, the master's and the slave's machines at least.
    assert len(BLOCKS) >= 3


@pytest.mark.parametrize("block", BLOCKS, ids=IDS)
def test_each_diagram_is_an_svg_with_every_state_and_transition(block: str) -> None:
    diagram = parse(block)
    svg = render(diagram)
    assert svg.startswith('<svg class="state-diagram"')
    assert "mermaid" not in svg
    assert "<script" not in svg
    shown = set(re.findall(r"<text[^>]*>([^<]*)</text>", svg))
    assert set(diagram.states) <= shown
    for line in block.splitlines()[1:]:
        label = line.split(": ", 1)[1]
        assert html.escape(label) in shown, label


def _extents(svg: str, kind: str) -> list[tuple[float, float, float, float]]:
    """The boxes of one class (label-box, state) an SVG draws, as (left, top, right, bottom)."""
    number = r"([-\d.]+)"
    found = re.findall(
        rf'<rect x="{number}" y="{number}" width="{number}" height="{number}" rx="\d+" '
        rf'class="{kind}"',
        svg,
    )
    return [(x, y, x + w, y + h) for x, y, w, h in ((float(v) for v in f) for f in found)]


def _overlaps(a: tuple[float, ...], b: tuple[float, ...]) -> bool:
    return min(a[2], b[2]) > max(a[0], b[0]) and min(a[3], b[3]) > max(a[1], b[1])


@pytest.mark.parametrize("block", BLOCKS, ids=IDS)
def test_no_label_covers_another_or_a_state(block: str) -> None:
    svg = render(parse(block))
    labels, states = _extents(svg, "label-box"), _extents(svg, "state")
    assert len(labels) == len(parse(block).arrows)
    assert len(states) == len(parse(block).states)
    for index, label in enumerate(labels):
        assert not any(_overlaps(label, other) for other in labels[index + 1 :])
        assert not any(_overlaps(label, state) for state in states)


def test_the_check_sees_a_label_over_another() -> None:
    # The master's states in the order they appear, on the smallest ellipse, do clash.
    diagram = next(parse(b) for b in BLOCKS if "WAITING_TURNAROUND" in b)
    assert _clutter(diagram, _place(tuple(diagram.states))) > 0


def test_the_hook_replaces_the_blocks_and_nothing_else() -> None:
    from state_diagrams import on_page_markdown

    out = on_page_markdown(PROTOCOL)
    assert "stateDiagram-v2" not in out
    assert out.count('<svg class="state-diagram"') == len(BLOCKS)
    without_svg = re.sub(r"\n<svg class=\"state-diagram\".*?</svg>\n\n", "", out, flags=re.S)
    assert without_svg == FENCE.sub("", PROTOCOL)


def test_a_first_paragraph_becomes_one_line() -> None:
    text = "Open `port` (a device or\na URL) and yield\na master.\n\nMore here,\nand there."
    assert first_paragraph_on_one_line(text) == (
        "Open `port` (a device or a URL) and yield a master.\n\nMore here,\nand there."
    )
    assert first_paragraph_on_one_line("One line.\n\nRest.") == "One line.\n\nRest."
    code = "Run it:\n    x = 1\n    y = 2"
    assert first_paragraph_on_one_line(code) == code


def _summaries(*extensions: griffe.Extension) -> dict[str, str]:
    """The first line of the docstring of every public name of the documented packages."""
    package = griffe.load(
        "aiortu",
        search_paths=[str(ROOT / "src")],
        extensions=griffe.load_extensions(*extensions),
        resolve_aliases=True,
    )
    found: dict[str, str] = {}

    def note(obj: griffe.Object) -> None:
        if obj.path in found or obj.docstring is None:
            return
        found[obj.path] = obj.docstring.value.split("\n", 1)[0].rstrip()
        if obj.is_class:
            for name, member in obj.members.items():
                if not name.startswith("_"):
                    note(member.final_target if member.is_alias else member)

    for name in DOCUMENTED:
        module = package[name]
        note(module)
        for export in module.exports or ():
            member = module[export]
            note(member.final_target if member.is_alias else member)
    return found


def test_every_api_summary_is_a_whole_sentence() -> None:
    summaries = _summaries(FirstParagraphSummaries())
    assert len(summaries) > 300
    cut = {path: line for path, line in summaries.items() if not re.search(r"[.!?:]$", line)}
    assert cut == {}
    # Without the extension, open_master's summary stopped mid-sentence.
    plain = _summaries()
    assert plain["aiortu.master._client.open_master"].endswith("`tcp://host:port` for")


def test_the_docs_extra_has_what_formats_the_signatures() -> None:
    config = yaml.load((ROOT / "mkdocs.yml").read_text(), Loader=yaml.BaseLoader)
    handler = next(p for p in config["plugins"] if isinstance(p, dict) and "mkdocstrings" in p)
    options = handler["mkdocstrings"]["handlers"]["python"]["options"]
    assert options["separate_signature"] == "true"
    extra = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]
    docs = extra["optional-dependencies"]["docs"]
    assert any(re.match(r"(ruff|black)\b", requirement) for requirement in docs)

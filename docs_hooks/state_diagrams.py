"""Draw the pages' state diagrams as SVG when the site is built, so that they show offline.

The pages keep each machine's ```mermaid `stateDiagram-v2` block as the code's transition
table draws it (`python -m aiortu.core.machines._diagrams`, checked by
tests/project/test_docs_diagrams.py): readable as text, and diffable. Drawn in the browser,
those blocks need the Mermaid script
from a CDN, and a reader offline sees the raw text. This hook replaces each block with an
inline SVG drawn here, with no script and no download: the states on an ellipse, the initial
one at the top, one arrow per pair of states (its events and actions one line each), a loop
for a state's transitions to itself. The block's text stays in the page source.

The subset read is what `state_diagram` writes: `[*] --> STATE` and
`SOURCE --> TARGET: LABEL` lines.
"""

from __future__ import annotations

import html
import itertools
import math
import re
from dataclasses import dataclass, field
from typing import Any

FENCE = re.compile(r"^```mermaid\nstateDiagram-v2\n(.*?)^```\n", re.MULTILINE | re.DOTALL)
"""A state diagram block of a page."""

_CHAR = 7.2
"""Width of a character of the 12 px sans-serif labels, about."""
_LINE = 15
_BOX_HEIGHT = 30
_SCALES = (1.0, 1.15, 1.3, 1.5)
"""The sizes of ellipse tried, smallest first."""


@dataclass
class Diagram:
    """The states (initial first, then in order of appearance) and the labels of the arrows
    between each pair of states, in the block's order."""

    initial: str
    states: list[str] = field(default_factory=list)
    arrows: dict[tuple[str, str], list[str]] = field(default_factory=dict)


def parse(body: str) -> Diagram:
    """The diagram a `stateDiagram-v2` block's lines describe."""
    diagram: Diagram | None = None
    for raw in body.splitlines():
        line = raw.strip()
        found = re.fullmatch(r"\[\*\] --> (\w+)", line)
        if found:
            diagram = Diagram(found.group(1), [found.group(1)])
            continue
        found = re.fullmatch(r"(\w+) --> (\w+): (.+)", line)
        if not found or diagram is None:
            raise ValueError(f"not a line of a state diagram: {line!r}")
        source, target, label = found.groups()
        for state in (source, target):
            if state not in diagram.states:
                diagram.states.append(state)
        diagram.arrows.setdefault((source, target), []).append(label)
    if diagram is None:
        raise ValueError("a state diagram needs its initial state ([*] --> STATE)")
    return diagram


@dataclass(frozen=True)
class _Box:
    x: float
    y: float
    width: float

    def edge(self, dx: float, dy: float) -> tuple[float, float]:
        """Where a line from the centre in direction (dx, dy) leaves the box."""
        scale = min(
            self.width / 2 / abs(dx) if dx else math.inf,
            _BOX_HEIGHT / 2 / abs(dy) if dy else math.inf,
        )
        return self.x + dx * scale, self.y + dy * scale


def _label(x: float, y: float, lines: list[str]) -> tuple[str, tuple[float, float, float, float]]:
    """SVG text of `lines` centred on (x, y) over a white box, and the box's extent."""
    width = max(len(line) for line in lines) * _CHAR + 8
    height = len(lines) * _LINE + 4
    left, top = x - width / 2, y - height / 2
    parts = [
        f'<rect x="{left:.1f}" y="{top:.1f}" width="{width:.1f}" height="{height:.1f}" '
        'rx="3" class="label-box"/>'
    ]
    for index, line in enumerate(lines):
        baseline = top + 2 + _LINE * (index + 1) - 4
        parts.append(
            f'<text x="{x:.1f}" y="{baseline:.1f}" text-anchor="middle">{html.escape(line)}</text>'
        )
    return "".join(parts), (left, top, left + width, top + height)


Extent = tuple[float, float, float, float]


def _place(order: tuple[str, ...], scale: float = 1.0) -> dict[str, _Box]:
    """The states' boxes on an ellipse, in `order` clockwise from the top, its size
    `scale` times the usual for that many states."""
    count = len(order)
    radius_x, radius_y = scale * (140 + 45 * count), scale * (70 + 35 * count)
    boxes: dict[str, _Box] = {}
    for index, state in enumerate(order):
        angle = -math.pi / 2 + 2 * math.pi * index / count
        width = len(state) * _CHAR + 24
        boxes[state] = _Box(radius_x * math.cos(angle), radius_y * math.sin(angle), width)
    return boxes


def _overlap(a: Extent, b: Extent) -> float:
    width = min(a[2], b[2]) - max(a[0], b[0])
    height = min(a[3], b[3]) - max(a[1], b[1])
    return width * height if width > 0 and height > 0 else 0.0


def _clutter(diagram: Diagram, boxes: dict[str, _Box]) -> float:
    """How much the labels of a placement cover each other and the states."""
    extents = [_label(*_arrow(diagram, boxes, pair)[1], texts)[1] for pair, texts in
               diagram.arrows.items()]  # fmt: skip
    states = [(b.x - b.width / 2, b.y - _BOX_HEIGHT / 2, b.x + b.width / 2, b.y + _BOX_HEIGHT / 2)
              for b in boxes.values()]  # fmt: skip
    cost = sum(_overlap(a, b) for i, a in enumerate(extents) for b in extents[i + 1 :])
    return cost + sum(_overlap(a, b) for a in extents for b in states)


def _arrow(
    diagram: Diagram, boxes: dict[str, _Box], pair: tuple[str, str]
) -> tuple[str, tuple[float, float]]:
    """The path of the arrow between `pair`, and where its label goes."""
    source, target = pair
    a, b = boxes[source], boxes[target]
    if source != target:
        return _arc(a, b, bend=(target, source) in diagram.arrows)
    path, (x, y) = _loop(a)
    # Beside the loop, on its outer side.
    half = max(len(text) for text in diagram.arrows[pair]) * _CHAR / 2 + 4
    return path, (x + half if a.x >= 0 else x - half, y)


def render(diagram: Diagram) -> str:
    """The diagram as an inline SVG element: of the orders of the states around the
    ellipse (the initial state at the top), the one whose labels cover nothing, on the
    smallest ellipse that has one."""
    first, *others = diagram.states
    orders = [(first, *rest) for rest in itertools.permutations(others)]
    boxes = _place(tuple(diagram.states))
    for scale in _SCALES:
        # The smallest ellipse on which some order leaves every label clear, else the
        # least cluttered order on the largest.
        boxes = min((_place(order, scale) for order in orders), key=lambda b: _clutter(diagram, b))
        if _clutter(diagram, boxes) == 0:
            break
    shapes: list[str] = []
    labels: list[str] = []
    extents: list[Extent] = []
    for pair, texts in diagram.arrows.items():
        path, (lx, ly) = _arrow(diagram, boxes, pair)
        shapes.append(f'<path d="{path}" class="arrow" marker-end="url(#head)"/>')
        text, extent = _label(lx, ly, texts)
        labels.append(text)
        extents.append(extent)
    for state, box in boxes.items():
        left = box.x - box.width / 2
        extents.append((left, box.y - _BOX_HEIGHT / 2, left + box.width, box.y + _BOX_HEIGHT))
        shapes.append(
            f'<rect x="{left:.1f}" y="{box.y - _BOX_HEIGHT / 2:.1f}" width="{box.width:.1f}" '
            f'height="{_BOX_HEIGHT}" rx="8" class="state"/>'
            f'<text x="{box.x:.1f}" y="{box.y + 4:.1f}" text-anchor="middle" '
            f'class="state-name">{state}</text>'
        )
    start = boxes[diagram.initial]
    top = start.y - _BOX_HEIGHT / 2
    shapes.append(
        f'<circle cx="{start.x:.1f}" cy="{top - 34:.1f}" r="6" class="start"/>'
        f'<path d="M {start.x:.1f} {top - 28:.1f} L {start.x:.1f} {top:.1f}" class="arrow" '
        'marker-end="url(#head)"/>'
    )
    extents.append((start.x - 6, top - 40, start.x + 6, top))
    x0 = min(e[0] for e in extents) - 10
    y0 = min(e[1] for e in extents) - 10
    width = max(e[2] for e in extents) + 10 - x0
    height = max(e[3] for e in extents) + 10 - y0
    title = f"state diagram, initial state {diagram.initial}"
    return (
        f'<svg class="state-diagram" role="img" aria-label="{title}" '
        f'viewBox="{x0:.0f} {y0:.0f} {width:.0f} {height:.0f}" '
        f'width="{width:.0f}" xmlns="http://www.w3.org/2000/svg">'
        f"<title>{title}</title>{_STYLE}" + "".join(shapes) + "".join(labels) + "</svg>"
    )


def _arc(a: _Box, b: _Box, *, bend: bool) -> tuple[str, tuple[float, float]]:
    """A path from box `a` to box `b`, bent to its right when the opposite arrow exists;
    and where its label goes."""
    dx, dy = b.x - a.x, b.y - a.y
    length = math.hypot(dx, dy) or 1.0
    offset = 0.18 * length if bend else 0.0
    cx = (a.x + b.x) / 2 - dy / length * offset
    cy = (a.y + b.y) / 2 + dx / length * offset
    x1, y1 = a.edge(cx - a.x, cy - a.y)
    x2, y2 = b.edge(cx - b.x, cy - b.y)
    label = (0.25 * x1 + 0.5 * cx + 0.25 * x2, 0.25 * y1 + 0.5 * cy + 0.25 * y2)
    return f"M {x1:.1f} {y1:.1f} Q {cx:.1f} {cy:.1f} {x2:.1f} {y2:.1f}", label


def _loop(box: _Box) -> tuple[str, tuple[float, float]]:
    """A loop from a box back to itself, on the side away from the diagram's centre."""
    side = 1.0 if box.x >= 0 else -1.0
    edge = box.x + side * box.width / 2
    out = edge + side * 42
    path = (
        f"M {edge:.1f} {box.y - 8:.1f} C {out:.1f} {box.y - 34:.1f} {out:.1f} {box.y + 34:.1f} "
        f"{edge + side * 2:.1f} {box.y + 8:.1f}"
    )
    return path, (out + side * 4, box.y)


_STYLE = (
    "<defs><marker id='head' viewBox='0 0 10 10' refX='9' refY='5' markerWidth='7' "
    "markerHeight='7' orient='auto-start-reverse'><path d='M 0 0 L 10 5 L 0 10 z' "
    "class='head'/></marker></defs>"
    "<style>text{font:12px sans-serif;fill:currentColor}"
    ".state{fill:#e8eaf6;stroke:#3f51b5;stroke-width:1.5}.state-name{font-weight:bold}"
    ".arrow{fill:none;stroke:#5c6bc0;stroke-width:1.3}.head{fill:#5c6bc0}"
    ".start{fill:#3f51b5}.label-box{fill:#fff;fill-opacity:.9;stroke:none}</style>"
)


def on_page_markdown(markdown: str, **_: Any) -> str:
    """Replace each state diagram block of a page with its SVG."""
    return FENCE.sub(lambda found: f"\n{render(parse(found.group(1)))}\n\n", markdown)

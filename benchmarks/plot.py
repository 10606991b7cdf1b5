"""Draw the benchmark summary as an SVG bar chart for the docs.

The figures come from ``benchmarks/summary.toml``, each a ratio copied from a table of
``benchmarks/README.md`` (the test suite checks that every one of them still stands there,
and that the SVG is the one this script draws), so the chart cannot drift from the
recorded runs. No plotting library is needed: the chart is a few SVG rectangles.

    python benchmarks/plot.py            # writes docs/img/benchmarks.svg
"""

from __future__ import annotations

import html
import sys
import tomllib
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
SUMMARY = ROOT / "benchmarks" / "summary.toml"
OUTPUT = ROOT / "docs" / "img" / "benchmarks.svg"

BAR_HEIGHT = 22
GAP = 10
LABEL_WIDTH = 360
CHART_WIDTH = 380
TOP = 56


def load_rows(path: Path = SUMMARY) -> list[dict[str, object]]:
    """The rows of the summary, each with its ratio made "higher is better".

    A row names the README *section* and the *figure* as printed there (``"5.52x"``,
    ``"73,712"``), divided by *reference* when given (an absolute figure against its
    target); ``invert = true`` marks a figure where lower is better (CPU per request),
    drawn as its inverse. *target* is the issue's target, already higher-is-better.
    """
    rows: list[dict[str, object]] = tomllib.loads(path.read_text(encoding="utf-8"))["row"]
    for row in rows:
        text = str(row["figure"]).replace(",", "")
        value = float(text[:-1]) / 100 if text.endswith("%") else float(text.rstrip("x"))
        value /= float(str(row.get("reference", 1)))
        row["ratio"] = 1 / value if row.get("invert") else value
    return rows


def draw(rows: list[dict[str, object]]) -> str:
    """The SVG text of the chart: one bar per row, the ratio to the reference (1x)."""
    largest = max(max(float(str(row["ratio"])), float(str(row["target"]))) for row in rows)
    scale = CHART_WIDTH / max(largest * 1.1, 1.2)
    height = TOP + len(rows) * (BAR_HEIGHT + GAP) + 30
    width = LABEL_WIDTH + CHART_WIDTH + 80
    parts = [
        f'<svg xmlns="http://www.w3.org/2000/svg" width="{width}" height="{height}" '
        f'viewBox="0 0 {width} {height}" font-family="sans-serif" font-size="13">',
        f'<rect width="{width}" height="{height}" fill="white"/>',
        '<text x="10" y="22" font-size="16" font-weight="bold">'
        "aiortu relative to the reference (higher is better)</text>",
        '<text x="10" y="42" fill="#555">bars: measured; ticks: the target; '
        "the line at 1x: the reference (pymodbus, or socat for the relay)</text>",
    ]
    one = LABEL_WIDTH + scale
    for index, row in enumerate(rows):
        y = TOP + index * (BAR_HEIGHT + GAP)
        ratio = float(str(row["ratio"]))
        target = float(str(row["target"]))
        met = ratio >= target
        colour = "#2e7d32" if met else "#c62828"
        label = html.escape(str(row["label"]))
        tick = LABEL_WIDTH + target * scale
        parts += [
            f'<text x="10" y="{y + 16}">{label}</text>',
            f'<rect x="{LABEL_WIDTH}" y="{y}" width="{ratio * scale:.1f}" '
            f'height="{BAR_HEIGHT}" fill="{colour}"/>',
            f'<text x="{LABEL_WIDTH + ratio * scale + 6:.1f}" y="{y + 16}">{ratio:.2f}x</text>',
            f'<line x1="{tick:.1f}" x2="{tick:.1f}" y1="{y - 3}" y2="{y + BAR_HEIGHT + 3}" '
            'stroke="black" stroke-width="2"/>',
        ]
    bottom = TOP + len(rows) * (BAR_HEIGHT + GAP)
    parts += [
        f'<line x1="{one:.1f}" x2="{one:.1f}" y1="{TOP - 6}" y2="{bottom}" '
        'stroke="#555" stroke-dasharray="4 3"/>',
        f'<text x="{one - 8:.1f}" y="{bottom + 16}" fill="#555">1x</text>',
        "</svg>",
    ]
    return "\n".join(parts) + "\n"


def main() -> int:
    OUTPUT.parent.mkdir(parents=True, exist_ok=True)
    OUTPUT.write_text(draw(load_rows()), encoding="utf-8")
    print(f"wrote {OUTPUT.relative_to(ROOT)}")
    return 0


if __name__ == "__main__":
    sys.exit(main())

"""The benchmark chart in the docs matches the recorded runs in benchmarks/README.md."""

from __future__ import annotations

import importlib.util
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
_spec = importlib.util.spec_from_file_location("plot", ROOT / "benchmarks" / "plot.py")
assert _spec is not None
assert _spec.loader is not None
plot = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(plot)


def _sections() -> dict[str, str]:
    text = (ROOT / "benchmarks" / "README.md").read_text(encoding="utf-8")
    sections: dict[str, str] = {}
    for chunk in text.split("\n## ")[1:]:
        title, _, body = chunk.partition("\n")
        sections[title.strip()] = body
    return sections


def test_every_charted_figure_stands_in_its_readme_section() -> None:
    sections = _sections()
    rows = plot.load_rows()
    assert rows
    for row in rows:
        section = sections[str(row["section"])]
        assert f" {row['figure']} " in section, (row["section"], row["figure"])


def test_the_chart_in_the_docs_is_the_one_the_summary_draws() -> None:
    drawn = plot.draw(plot.load_rows())
    assert (ROOT / "docs" / "img" / "benchmarks.svg").read_text(encoding="utf-8") == drawn

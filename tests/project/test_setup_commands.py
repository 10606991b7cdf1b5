"""The README's test command is the one `.ci/run` runs, verbatim: CI checks what users run."""

from __future__ import annotations

from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]


def _readme_commands() -> list[str]:
    """The one-line commands of the README's set-up section, in its order."""
    text = (ROOT / "README.md").read_text(encoding="utf-8")
    section = text.split("## Set up", 1)[1].split("\n## ", 1)[0]
    return [line for line in section.splitlines() if line.startswith("python3 -m venv")]


def test_the_readme_has_two_set_up_commands() -> None:
    demo, suite = _readme_commands()
    assert demo.endswith("aiortu demo --duration 10")
    assert 'pip install -e ".[test]"' in suite
    assert suite.endswith("&& pytest")


def test_ci_runs_the_readme_test_command_verbatim() -> None:
    suite = _readme_commands()[1]
    ci_lines = (ROOT / ".ci" / "run").read_text(encoding="utf-8").splitlines()
    assert suite in ci_lines, "the README's test command differs from the one .ci/run runs"

"""``aiortu poll`` against a device whose map has holes: a merged read refused with exception 02
is split, so only a missing point fails; ``--max-gap``; and its exit codes as its help, the
docs and the code give them."""

from __future__ import annotations

import re
from collections.abc import Iterator
from pathlib import Path

import pytest

from tests.cli.cli_helpers import run_aiortu, serving_tcp

pytestmark = pytest.mark.timeout(60)

ROOT = Path(__file__).parents[2]


@pytest.fixture(scope="module")
def tcp_url() -> Iterator[str]:
    """`aiortu serve` of examples/devices.toml: unit 17 has holding registers 107..109."""
    with serving_tcp(ROOT / "examples" / "devices.toml") as url:
        yield url


def _values(stdout: str) -> dict[str, str]:
    """The POINT -> VALUE column of the last table printed."""
    last = stdout.strip("\n").split("\n\n")[-1].splitlines()
    return {line.split()[0]: line.split(None, 2)[2] for line in last[2:] if "  " in line[:20]}


def test_a_hole_fails_only_the_missing_point(tcp_url: str) -> None:
    result = run_aiortu("poll", tcp_url, "--point", "a=17:40108", "--point", "b=17:40112",
                        "--point", "c=17:40109", "--cycles", "2", "--interval", "0.05")  # fmt: skip
    assert result.returncode == 0, result.stderr
    for block in result.stdout.strip("\n").split("\n\n"):
        lines = block.splitlines()
        assert lines[2] == "a                  17  44609"
        assert lines[3] == "b                  17  -- exception 02 (illegal data address)"
        assert lines[4] == "c                  17  22098"


def test_max_gap_keeps_points_apart(tcp_url: str) -> None:
    # With no gap allowed, 40108 and 40112 are two reads from the start; with the help's
    # bad value, one line.
    apart = run_aiortu("poll", tcp_url, "--point", "a=17:40108", "--point", "b=17:40112",
                       "--max-gap", "0", "--cycles", "1", "--json")  # fmt: skip
    assert apart.returncode == 0, apart.stderr
    assert '"value": 44609' in apart.stdout
    bad = run_aiortu("poll", tcp_url, "--ref", "40108", "--unit", "17", "--max-gap", "-1")
    assert bad.returncode == 2
    assert bad.stderr == "aiortu poll: error: argument --max-gap: must be 0 or more, not -1\n"


def _codes(text: str) -> set[int]:
    return {int(code) for code in re.findall(r"^\s*\|?\s*(\d)\s", text, re.MULTILINE)}


def test_the_exit_codes_agree_in_help_docs_and_code(tcp_url: str) -> None:
    help_text = run_aiortu("poll", "--help").stdout
    in_help = _codes(help_text.split("exit codes:\n", 1)[1])
    docs = (ROOT / "docs" / "cli.md").read_text()
    section = docs.split("| code | meaning of `poll`'s exit code |", 1)[1].split("\n\n", 1)[0]
    assert in_help == _codes(section) == {0, 1, 2}
    # A unit that never answers is shown in the table: exit 0, as both say.
    dead = run_aiortu("poll", tcp_url, "--unit", "99", "--ref", "40001", "--cycles", "1",
                      "--timeout", "0.1")  # fmt: skip
    assert dead.returncode == 0, dead.stderr
    assert "unit 99:" in dead.stdout

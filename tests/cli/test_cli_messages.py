"""Every error the ``aiortu`` command prints for bad input, against the wording rules: one
line on stderr, ``aiortu COMMAND: ...`` once, no "outside the allowed range" where no range
is meant, no prefix said twice, no exception reprs, no Python names."""

from __future__ import annotations

import re
from collections.abc import Iterator
from pathlib import Path

import pytest

from aiortu.cli import main
from aiortu.core.serial import LineSettings
from aiortu.testing import PtyBus

pytestmark = pytest.mark.timeout(60)

PORT = "{port}"
"""Replaced by a pty with nobody on the other side."""

OVERLAP = """
[[slave]]
unit = 1
[[slave.holding_registers]]
start = 0
count = 10
[[slave.holding_registers]]
start = 5
count = 10
"""

BAD_INPUT = [
    # read (and the options every master command shares)
    ["read", PORT, "--unit", "0", "--ref", "40001"],
    ["read", PORT, "--unit", "-1", "--ref", "40001"],
    ["read", PORT, "--unit", "248", "--ref", "40001"],
    ["read", PORT, "--unit", "x", "--ref", "40001"],
    ["read", PORT, "--unit", "1", "--ref", "4001"],
    ["read", PORT, "--unit", "1", "--ref", "40000"],
    ["read", PORT, "--unit", "1", "--ref", "90001"],
    ["read", PORT, "--unit", "1", "--ref", "abc"],
    ["read", PORT, "--unit", "1", "--ref", "40001", "--count", "0"],
    ["read", PORT, "--unit", "1", "--ref", "40001", "--count", "126"],
    ["read", PORT, "--unit", "1", "--ref", "00001", "--count", "2001"],
    ["read", PORT, "--unit", "1", "--table", "holding", "--address", "-1"],
    ["read", PORT, "--unit", "1", "--table", "holding", "--address", "65535", "--count", "2"],
    ["read", PORT, "--unit", "1", "--table", "holding"],
    ["read", PORT, "--unit", "1", "--table", "holding", "--address", "0", "--ref", "40001"],
    ["read", PORT, "--unit", "1", "--ref", "40001", "--parity", "Q"],
    ["read", PORT, "--unit", "1", "--ref", "40001", "--stopbits", "3"],
    ["read", PORT, "--unit", "1", "--ref", "40001", "--timeout", "0"],
    ["read", PORT, "--unit", "1", "--ref", "40001", "--timeout", "soon"],
    ["read", PORT, "--unit", "1", "--ref", "40001", "--baudrate", "0"],
    ["read", PORT, "--unit", "1", "--ref", "40001", "--retries", "-1"],
    # write
    ["write", PORT, "--unit", "1", "--ref", "40001", "--values", "1,,2"],
    ["write", PORT, "--unit", "1", "--ref", "40001", "--values", "70000"],
    ["write", PORT, "--unit", "1", "--ref", "40001", "--values", "x"],
    ["write", PORT, "--unit", "1", "--ref", "00001", "--values", "maybe"],
    ["write", PORT, "--unit", "1", "--ref", "30001", "--values", "1"],
    ["write", PORT, "--unit", "0", "--ref", "40001", "--values", "1"],
    # poll
    ["poll", PORT, "--unit", "0", "--ref", "40001"],
    ["poll", PORT, "--unit", "-1", "--ref", "40001"],
    ["poll", PORT, "--unit", "1,,2", "--ref", "40001"],
    ["poll", PORT, "--unit", "248", "--ref", "40001"],
    ["poll", PORT, "--unit", "1", "--ref", "4001"],
    ["poll", PORT, "--ref", "40001"],
    ["poll", PORT],
    ["poll", PORT, "--point", "flow"],
    ["poll", PORT, "--point", "flow=1:40001:float99"],
    ["poll", PORT, "--point", "flow=1:40001:float32:XYZW"],
    ["poll", PORT, "--point", "flow=1:4001"],
    ["poll", PORT, "--point", "a=1:40001", "--point", "a=1:40002"],
    ["poll", PORT, "--unit", "1", "--ref", "40001", "--interval", "0"],
    ["poll", PORT, "--unit", "1", "--ref", "40001", "--cycles", "0"],
    ["poll", PORT, "--unit", "1", "--ref", "40001", "--type", "float99"],
    # serve
    ["serve", PORT, "--config", "{missing}"],
    ["serve", PORT, "--config", "{overlap}"],
    ["serve", PORT, "--config", "{devices}", "--frame-gap", "-1"],
    ["serve", PORT, "--config", "{devices}", "--timing", "loose"],
    ["serve", PORT, "--config", "{devices}", "--parity", "mark"],
    # scan
    ["scan", PORT, "--units", "1,,2"],
    ["scan", PORT, "--units", "0"],
    ["scan", PORT, "--units", "300"],
    ["scan", PORT, "--baudrates", "fast"],
    ["scan", PORT, "--parities", "Q"],
    ["scan", PORT, "--timeout", "100"],
    # monitor
    ["monitor", PORT, "--parity", "Q"],
    ["monitor", PORT, "--timing", "loose"],
    # virtual-bus and demo
    ["virtual-bus", "--ports", "0"],
    ["virtual-bus", "--bit-error-rate", "2"],
    ["virtual-bus", "--gap", "-1"],
    ["demo", "--duration", "0"],
    ["demo", "--baudrate", "x"],
    ["no-such-command"],
    [],
]

_REPR = re.compile(r"\b[A-Z]\w*\(")
_DOTTED = re.compile(r"\b[a-z_]+\.[a-z_]+\b")
_SNAKE = re.compile(r"\b[a-z]+_[a-z_]+\b")


@pytest.fixture(scope="module")
def port() -> Iterator[str]:
    settings = LineSettings(19200, parity="N", stopbits=2)
    with PtyBus(2, settings=settings).running_in_thread() as bus:
        yield bus.paths[0]


def _fill(argv: list[str], port: str, tmp_path: Path) -> list[str]:
    (tmp_path / "overlap.toml").write_text(OVERLAP, encoding="utf-8")
    places = {
        "{port}": port,
        "{missing}": str(tmp_path / "missing.toml"),
        "{overlap}": str(tmp_path / "overlap.toml"),
        "{devices}": str(Path(__file__).parents[2] / "examples" / "devices.toml"),
    }
    return [places.get(word, word) for word in argv]


def run(argv: list[str], capsys: pytest.CaptureFixture[str]) -> tuple[int, str, str]:
    try:
        code = main(argv)
    except SystemExit as exc:
        code = exc.code if isinstance(exc.code, int) else 1
    captured = capsys.readouterr()
    return code, captured.out, captured.err


@pytest.mark.parametrize("argv", BAD_INPUT, ids=" ".join)
def test_every_bad_input_gets_one_sentence(
    argv: list[str], port: str, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    code, out, err = run(_fill(argv, port, tmp_path), capsys)
    assert code == 2
    assert out == ""
    assert err.count("\n") == 1, err
    assert err.startswith("aiortu")
    # Paths (the port, a file) may hold any characters; the words around them may not.
    words = " ".join(word for word in err.split() if "/" not in word)
    assert "outside the allowed range" not in words
    assert words.count("aiortu") == 1 or argv == [], err
    assert words.count("error:") == 1, err
    assert not _REPR.search(words), err
    assert not _DOTTED.search(words), err
    # A device description's own keys (holding_registers) are the user's words.
    assert not _SNAKE.search(words.replace("holding_registers", "")), err


def test_a_device_description_with_overlapping_blocks(
    port: str, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    argv = _fill(["serve", PORT, "--config", "{overlap}"], port, tmp_path)
    assert run(argv, capsys)[2] == (
        f"aiortu serve: error: {tmp_path / 'overlap.toml'}: slave[0]: holding_registers: "
        "the block at 5..14 overlaps the block at 0..9\n"
    )


def test_unit_0_and_unit_minus_1_say_the_same_kind_of_thing(
    port: str, capsys: pytest.CaptureFixture[str]
) -> None:
    messages = [
        run(["read", port, "--unit", unit, "--ref", "40001"], capsys)[2]
        for unit in ("0", "-1", "248")
    ]
    assert messages == [
        "aiortu read: error: argument --unit: must be a unit address 1..247, not 0 "
        "(0 is the broadcast address, which gets no reply)\n",
        "aiortu read: error: argument --unit: must be a unit address 1..247 (0..255 over "
        "tcp://, udp://, tls://), not -1\n",
        "aiortu read: error: argument --unit: must be a unit address 1..247, not 248\n",
    ]


def test_a_four_digit_register_reference_is_refused(
    port: str, capsys: pytest.CaptureFixture[str]
) -> None:
    code, _, err = run(["read", port, "--unit", "1", "--ref", "4001"], capsys)
    assert code == 2
    assert err == (
        "aiortu read: error: --ref 4001 is ambiguous: write 40001 for holding register 1, "
        "or 04001 for coil 4001\n"
    )


@pytest.mark.parametrize("parity", ["n", "none", "NONE", "N", "None"])
def test_parity_takes_letters_and_words_in_any_case(
    parity: str, port: str, capsys: pytest.CaptureFixture[str]
) -> None:
    argv = ["read", port, "--unit", "1", "--ref", "40001", "--timeout", "0.05", "--parity", parity]
    code, _, err = run(argv, capsys)
    # Nobody answers on this pty: the settings were taken and the request went out.
    assert (code, err) == (3, "aiortu read: no reply from unit 1 to function 0x03 within 0.05 s\n")

"""`--timing` and `--no-reconnect` mean the same in every command that has them: one
definition, one help text, and each command hands the value on."""

from __future__ import annotations

import argparse
import contextlib
from collections.abc import AsyncIterator

import pytest

from aiortu.cli import build_parser
from aiortu.core.rtu import TimingMode
from aiortu.errors import PortError

TIMING = ("serve", "monitor", "poll")
RECONNECT = ("serve", "poll")


def _option(command: str, flag: str) -> argparse.Action:
    parser = build_parser(command)
    commands = next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction))
    sub = commands.choices[command]
    return next(action for action in sub._actions if flag in action.option_strings)


def test_timing_is_one_option_with_the_receivers_modes() -> None:
    options = [_option(command, "--timing") for command in TIMING]
    assert {option.help for option in options} == {options[0].help}
    for option in options:
        assert option.choices is not None
        assert sorted(option.choices) == sorted(mode.value for mode in TimingMode)
        assert option.default == TimingMode.TOLERANT.value


def test_no_reconnect_is_one_option() -> None:
    options = [_option(command, "--no-reconnect") for command in RECONNECT]
    assert {option.help for option in options} == {options[0].help}
    assert all(option.dest == "reconnect" and option.default is True for option in options)


@pytest.mark.parametrize("flags", [[], ["--timing", "strict", "--no-reconnect"]])
def test_poll_opens_its_master_with_the_options_given(
    monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str], flags: list[str]
) -> None:
    from aiortu.cli import _poll

    seen: dict[str, object] = {}

    @contextlib.asynccontextmanager
    async def open_master(port: str, **options: object) -> AsyncIterator[None]:
        seen.update(options)
        raise PortError(port, "no such port")
        yield None

    monkeypatch.setattr("aiortu.master.open_master", open_master)
    args = build_parser("poll").parse_args(
        ["poll", "/dev/null", "--unit", "1", "--ref", "40001", *flags]
    )
    assert _poll.run(args) == 1
    assert capsys.readouterr().err == "aiortu poll: /dev/null: no such port\n"
    expected = ("strict", False) if flags else ("tolerant", True)
    assert (seen["timing"], seen["reconnect"]) == expected

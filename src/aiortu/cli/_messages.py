"""Failures as the `aiortu` command shows them: one sentence each, for people.

The library's errors name Python arguments (`count`) and carry exception reprs from the
layers below (`EndOfStream()`); the command shows the option a user typed (`--count`)
and what happened to the port, without doubling a prefix the message already has.
"""

from __future__ import annotations

import re

from aiortu.cli._arguments import PTY_LINE, is_pty
from aiortu.errors import (
    ConnectionLost,
    InvalidValue,
    PortError,
    ResponseTimeout,
    UnsupportedSettings,
)

__all__ = ("config_problem", "invalid_value", "line_failure", "no_reply", "port_failure")

_OPTIONS = {
    "address": "--address",
    "count": "--count",
    "unit": "--unit",
    "values": "--values",
    "value": "--values",
    "port": "PORT",
    "port_or_url": "PORT",
    "reference": "--ref",
    "address + count": "--address plus --count",
    "type": "the value type",
    "layout": "the layout",
}
"""The command's name for an argument the library names."""

_CAUSES = {
    "EndOfStream": "the port closed",
    "BrokenResourceError": "the port is gone",
    "ClosedResourceError": "the port was closed",
}

_REPR = re.compile(r"\b([A-Z]\w*)\((.*)\)")
_FAILED = "the line failed: "


def invalid_value(error: InvalidValue) -> str:
    """`error` as one sentence: what was given, what is allowed, under the option's name."""
    field = _OPTIONS.get(error.field, error.field)
    allowed = error.allowed
    if isinstance(allowed, range):
        allowed = f"{allowed.start}..{allowed.stop - 1}"
    detail = _detail(error)
    given = _plain(error.value)
    sentence = f"{field} must be {allowed}" + (f", not {given}" if given is not None else "")
    return f"{sentence} ({detail})" if detail else sentence


def _detail(error: InvalidValue) -> str:
    """The detail after the library's own wording, if its message has one."""
    text = str(error)
    _, colon, rest = text.partition(" is outside the allowed range ")
    if not colon:
        return ""
    _, separator, detail = rest.partition(": ")
    return detail if separator else ""


def _plain(value: object) -> str | None:
    """`value` as a person typed it; None for values that only have a Python spelling."""
    if isinstance(value, bool):
        return str(value).lower()
    if isinstance(value, str | int | float):
        return str(value)
    return None


_TEMPLATE = re.compile(
    r"(?P<field>[\w.\[\] +]+) = (?P<value>.+?) is outside the allowed range (?P<allowed>.+?)"
    r"(?:: (?P<detail>.*))?"
)


def config_problem(problem: str) -> str:
    """The problem a device description has, without the library's range template."""
    found = _TEMPLATE.fullmatch(problem)
    if found is None:
        return problem
    field, value, allowed = found["field"], found["value"].strip("'\""), found["allowed"]
    sentence = f"{field} must be {allowed}, not {value}"
    return f"{sentence} ({found['detail']})" if found["detail"] else sentence


def port_failure(error: PortError) -> str:
    """A port that could not be opened; on a pty refusing a parity, which flags to use."""
    message = str(error)
    if isinstance(error, UnsupportedSettings) and is_pty(error.port):
        message += f"; a pseudo-terminal keeps no parity: use {PTY_LINE}, or leave both out"
    return message


def line_failure(error: ConnectionLost) -> str:
    """A line that failed under a command: `the line failed: WHY`, once."""
    text = str(error)
    while text.startswith(_FAILED):
        text = text[len(_FAILED) :]
    text = _REPR.sub(_cause, text)
    return f"{_FAILED}{text}"


def _cause(match: re.Match[str]) -> str:
    name, inside = match.group(1), match.group(2).strip("'\"")
    if name in _CAUSES:
        return _CAUSES[name] + (f" ({inside})" if inside else "")
    return inside or name


def no_reply(error: ResponseTimeout) -> str:
    """No reply in time: `no reply ...` once."""
    text = str(error)
    return text if text.startswith("no reply") else f"no reply: {text}"

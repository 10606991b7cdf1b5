"""Failures as the `aiortu` command shows them: one sentence each, for people.

The library words its errors for people; the command only names an argument as the user
typed it (`--count`, not `count`) and, on a pseudo-terminal that refuses a parity, says
which flags to use. It never parses the library's text.
"""

from __future__ import annotations

from aiortu.cli._arguments import PTY_LINE, is_pty
from aiortu.errors import InvalidValue, PortError, UnsupportedSettings

__all__ = ("invalid_value", "port_failure")

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


def invalid_value(error: InvalidValue) -> str:
    """`error` as one sentence: what was given, what is allowed, under the option's name."""
    field = _OPTIONS.get(error.field, error.field)
    allowed = error.allowed
    if isinstance(allowed, range):
        allowed = f"{allowed.start}..{allowed.stop - 1}"
    given = _plain(error.value)
    sentence = f"{field} must be {allowed}" + (f", not {given}" if given is not None else "")
    return f"{sentence} ({error.detail})" if error.detail else sentence


def _plain(value: object) -> str | None:
    """`value` as a person typed it; None for values that only have a Python spelling."""
    if isinstance(value, bool):
        return str(value).lower()
    if isinstance(value, str | int | float):
        return str(value)
    return None


def port_failure(error: PortError) -> str:
    """A port that could not be opened; on a pty refusing a parity, which flags to use."""
    message = str(error)
    if isinstance(error, UnsupportedSettings) and is_pty(error.port):
        message += f"; a pseudo-terminal keeps no parity: use {PTY_LINE}, or leave both out"
    return message

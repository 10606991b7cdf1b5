"""Failures as the `aiortu` command shows them: one sentence each, for people.

The library words its errors for people; the command only names an argument as the user
typed it (`--count`, not `count`) and, on a pseudo-terminal that refuses a parity, says
which flags to use. It never parses the library's text.
"""

from __future__ import annotations

import contextlib
import logging
import re
import sys
from collections.abc import Iterator

from aiortu.cli._arguments import PTY_LINE, is_pty
from aiortu.errors import InvalidValue, PortError, PortNotFound, UnsupportedSettings

__all__ = ("invalid_value", "library_warnings_on_stderr", "port_failure")

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
    """A port that could not be opened; on a pty refusing a parity or 7 data bits, which flags
    to use; for a missing device named like `host:port`, the Modbus TCP URL meant most likely."""
    message = str(error)
    if isinstance(error, UnsupportedSettings) and is_pty(error.port):
        # The library said what the pty kept; on a pty every flag's default fits it.
        message += f"; on the command line: --bytesize 8 {PTY_LINE}, or leave them out"
    elif isinstance(error, PortNotFound) and _HOST_PORT.fullmatch(error.port):
        message += f"; for Modbus TCP write tcp://{error.port} (RTU over TCP: rtu+tcp://)"
    return message


_HOST_PORT = re.compile(r"(\[[0-9A-Fa-f:.]+\]|[\w.-]+):\d{1,5}")
"""A port given as `host:port` without a scheme."""


class _OneLine(logging.Formatter):
    """A record as one line of the command's: `aiortu serve: MESSAGE (ERROR)`, no traceback."""

    def __init__(self, command: str) -> None:
        super().__init__()
        self.command = command

    def format(self, record: logging.LogRecord) -> str:
        message = record.getMessage()
        error = record.exc_info[1] if record.exc_info else None
        if error is not None and str(error):
            message = f"{message} ({error})"
        return f"aiortu {self.command}: {message}"


@contextlib.contextmanager
def library_warnings_on_stderr(command: str) -> Iterator[None]:
    """Show the library's warnings and errors on stderr while a long-running command runs,
    one line each (the library itself logs to nobody until told)."""
    handler = logging.StreamHandler(sys.stderr)
    handler.setLevel(logging.WARNING)
    handler.setFormatter(_OneLine(command))
    logger = logging.getLogger("aiortu")
    logger.addHandler(handler)
    try:
        yield
    finally:
        logger.removeHandler(handler)

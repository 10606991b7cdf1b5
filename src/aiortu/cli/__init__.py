"""The `aiortu` command: one subcommand per module of this package.

Each public module here (`virtual_bus.py`, ...) defines `register(subparsers)`, which
adds its parser and sets `run` (a function from the parsed arguments to an exit code)
as a default. `main` finds the modules by itself, so adding a subcommand means adding
one module.

Exit codes: 0 success, 1 a runtime failure (reported on one line), 2 bad arguments (one
line on stderr, as `aiortu COMMAND: error: ...`), 130 interrupted before a command could
install its own signal handling.
"""

from __future__ import annotations

import sys
from typing import TYPE_CHECKING, NoReturn, TypeAlias

if TYPE_CHECKING:
    import argparse
    from collections.abc import Callable

__all__ = ("SUMMARIES", "CommandFailed", "Subparsers", "build_parser", "main")

Subparsers: TypeAlias = "argparse._SubParsersAction[argparse.ArgumentParser]"
"""The type of the object a command module's `register` receives."""

Runner: TypeAlias = "Callable[[argparse.Namespace], int]"

SUMMARIES: dict[str, str] = {
    "bridge": "publish the devices of lines to an MQTT broker (Home Assistant, Sparkplug B)",
    "demo": "watch three simulated devices being polled on a virtual bus (no hardware)",
    "gateway": "share serial lines with many Modbus TCP, UDP and TLS clients (the line server)",
    "identify": "read what a device says it is: identification objects and server id",
    "monitor": "watch a bus: print every frame with its meaning, never send",
    "poll": "poll points on one or more units and show them as a live table",
    "profile": "check device profiles; read and write a device's points by name",
    "read": "read coils, discrete inputs or registers from a device once",
    "scan": "find the units that answer on a port, and their line settings",
    "serve": "simulate Modbus devices described in a TOML file or a profile",
    "virtual-bus": "a virtual RS-485 bus of pseudo-terminals that any program can open",
    "write": "write coils or holding registers of a device once",
}
"""Each subcommand's one-line help. Each lives in a private module `_NAME` (dashes as
underscores) with a `register(subparsers)`; only the command run is imported, so that
`aiortu --help` and each command start fast."""


class CommandFailed(Exception):
    """A command could not do its job; the message is shown on one line. Caused by the environment.

    Raised by command modules (a device that cannot be opened, ...); `main` turns
    it into its `exit_code`: 1, or 2 for a bad argument or file found only once running.
    """

    def __init__(self, message: str, exit_code: int = 1) -> None:
        super().__init__(message)
        self.exit_code = exit_code


def build_parser(command: str | None = None) -> argparse.ArgumentParser:
    """Return the parser of the `aiortu` command: `command` registered in full (every
    command when None), the others by name and summary only."""
    import argparse
    import importlib

    from aiortu import __version__

    class Parser(argparse.ArgumentParser):
        """An argument parser whose errors are one line on stderr and exit code 2."""

        def error(self, message: str) -> NoReturn:
            self.exit(2, f"{self.prog}: error: {_plain_choices(message)}\n")

    parser = Parser(
        prog="aiortu",
        description=(
            "Modbus tools (RTU and ASCII on serial lines; Modbus TCP, UDP and TLS): a master, a "
            "slave simulator, a line server, an MQTT bridge and virtual serial lines."
        ),
        epilog="Run 'aiortu COMMAND --help' for the options and examples of a command.",
    )
    parser.add_argument("--version", action="version", version=f"aiortu {__version__}")
    subparsers = parser.add_subparsers(
        dest="command", metavar="COMMAND", required=True, parser_class=Parser
    )
    for name, summary in SUMMARIES.items():
        if command is None or name == command:
            module = importlib.import_module(f"{__name__}._{name.replace('-', '_')}")
            module.register(subparsers)
        else:
            subparsers.add_parser(name, help=summary)
    return parser


def _plain_choices(message: str) -> str:
    """argparse's `invalid choice: 'x' (choose from 'a', 'b')` in the command's words."""
    import re

    found = re.fullmatch(r"(argument \S+: )invalid choice: '?(.*?)'? \(choose from (.*)\)", message)
    if found is None:
        return message
    choices = found.group(3).replace("'", "")
    return f"{found.group(1)}must be one of {choices}, not {found.group(2)}"


def _command_in(argv: list[str]) -> str | None:
    """The subcommand `argv` names: its first word that is not an option."""
    return next((word for word in argv if not word.startswith("-")), None)


def main(argv: list[str] | None = None) -> int:
    """Run the `aiortu` command with `argv` (default: `sys.argv[1:]`); return the exit code.

    Exit codes: 0 success, 1 a runtime failure (reported on one line), 2 bad arguments
    (one line on stderr, as `aiortu COMMAND: error: ...`), 130 interrupted by Ctrl-C
    before a command installed its own handling (while starting, for instance), without
    a traceback.
    """
    try:
        return _main(sys.argv[1:] if argv is None else argv)
    except KeyboardInterrupt:
        return 130


def _main(argv: list[str]) -> int:
    command = _command_in(argv)
    # Only the command run is imported; "" registers none in full (``aiortu --help``).
    parser = build_parser(command if command in SUMMARIES else "")
    args = parser.parse_args(argv)
    run: Runner = args.run
    prog = f"aiortu {args.command}"
    from aiortu.cli._messages import invalid_value
    from aiortu.errors import InvalidValue

    try:
        return run(args)
    except InvalidValue as exc:
        print(f"{prog}: error: {invalid_value(exc)}", file=sys.stderr)
        return 2
    except CommandFailed as exc:
        print(f"{prog}: {exc}", file=sys.stderr)
        return exc.exit_code

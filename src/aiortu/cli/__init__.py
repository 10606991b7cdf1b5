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

import argparse
import importlib
import sys
from collections.abc import Callable
from typing import NoReturn, TypeAlias

from aiortu.errors import InvalidValue

__all__ = ("CommandFailed", "Subparsers", "build_parser", "main")

Subparsers: TypeAlias = "argparse._SubParsersAction[argparse.ArgumentParser]"
"""The type of the object a command module's `register` receives."""

Runner = Callable[[argparse.Namespace], int]


class CommandFailed(Exception):
    """A command could not do its job; the message is shown on one line. Caused by the environment.

    Raised by command modules (a device that cannot be opened, ...); `main` turns
    it into exit code 1.
    """


class _Parser(argparse.ArgumentParser):
    """An argument parser whose errors are one line on stderr and exit code 2."""

    def error(self, message: str) -> NoReturn:
        self.exit(2, f"{self.prog}: error: {message}\n")


_COMMANDS = ("demo", "monitor", "poll", "read", "scan", "serve", "virtual_bus", "write")
"""The subcommands, each a private module `_NAME` with a `register(subparsers)`."""


def _command_modules() -> list[str]:
    return [f"{__name__}._{name}" for name in _COMMANDS]


def build_parser() -> argparse.ArgumentParser:
    """Return the parser of the `aiortu` command, with every subcommand registered."""
    from aiortu import __version__

    parser = _Parser(
        prog="aiortu",
        description="Modbus RTU tools: a master, a slave simulator and virtual serial lines.",
        epilog="Run 'aiortu COMMAND --help' for the options and examples of a command.",
    )
    parser.add_argument("--version", action="version", version=f"aiortu {__version__}")
    subparsers = parser.add_subparsers(dest="command", metavar="COMMAND", required=True)
    for name in _command_modules():
        importlib.import_module(name).register(subparsers)
    return parser


def main(argv: list[str] | None = None) -> int:
    """Run the `aiortu` command with `argv` (default: `sys.argv[1:]`); return the exit code."""
    parser = build_parser()
    args = parser.parse_args(argv)
    run: Runner = args.run
    prog = f"aiortu {args.command}"
    try:
        return run(args)
    except InvalidValue as exc:
        print(f"{prog}: error: {exc}", file=sys.stderr)
        return 2
    except CommandFailed as exc:
        print(f"{prog}: {exc}", file=sys.stderr)
        return 1
    except KeyboardInterrupt:
        return 130

"""What the master's commands (`read`, `write`, `poll`) share: line options, number
parsing, opening the master, and turning failures into one line and an exit code.

Exit codes of those commands:

====  =========================================================================
0     success
1     the port could not be opened or failed (the line is gone)
2     bad arguments (including values out of the spec's range)
3     no reply in time (after the retries)
4     the device answered with a Modbus exception
5     a reply came but was not valid (CRC or framing error, malformed content)
====  =========================================================================
"""

from __future__ import annotations

import argparse
import sys
from collections.abc import AsyncIterator, Awaitable, Callable
from contextlib import asynccontextmanager
from typing import TYPE_CHECKING

from aiortu.cli._arguments import (
    add_line_settings,
    address,
    positive_int,
    resolve_line_settings,
    seconds,
    unit,
)
from aiortu.cli._messages import invalid_value, port_failure
from aiortu.cli._transport_options import add_transport_options, transport_options
from aiortu.core.model import Reference, Table, parse_reference
from aiortu.errors import (
    ConnectionLost,
    ExceptionResponse,
    FrameError,
    InvalidValue,
    PortError,
    ResponseTimeout,
)

if TYPE_CHECKING:
    from aiortu.master import Master

__all__ = (
    "EXIT_CODES_HELP",
    "UsageError",
    "LINE_FLAGS_HELP",
    "TABLES",
    "add_line_options",
    "address",
    "open_from_args",
    "positive_int",
    "reference",
    "run_master",
    "seconds",
    "unit",
)

EXIT_CODES_HELP = """\
exit codes:
  0  success
  1  the port could not be opened, or failed
  2  bad arguments (one line on stderr)
  3  no reply in time
  4  the device answered with a Modbus exception
  5  an invalid reply (CRC or framing error, malformed content)
"""

LINE_FLAGS_HELP = """\
aiortu and mbpoll side by side (mbpoll -m rtu ...):
  --unit 17                mbpoll -a 17
  --baudrate 9600          mbpoll -b 9600
  --parity E|O|N           mbpoll -P even|odd|none (none, even, odd work too)
  --stopbits 2             mbpoll -s 2
  --timeout 0.5            mbpoll -o 0.5
"""


class UsageError(Exception):
    """Arguments that do not go together; shown as `error: ...` with exit code 2."""


TABLES: dict[str, Table] = {
    "coils": Table.COILS,
    "discrete": Table.DISCRETE_INPUTS,
    "input": Table.INPUT_REGISTERS,
    "holding": Table.HOLDING_REGISTERS,
}
"""The `--table` names and the tables they mean."""

TABLE_NAMES: dict[Table, str] = {table: name for name, table in TABLES.items()}


def add_line_options(parser: argparse.ArgumentParser) -> None:
    """Add the port argument and `--baudrate --parity --stopbits --timeout --retries`."""
    parser.add_argument(
        "port",
        metavar="PORT",
        help="a serial device path, rtu+tcp://, ascii+tcp://, tcp://, udp:// or tls://host:port",
    )
    add_transport_options(parser)
    line = parser.add_argument_group("line settings")
    add_line_settings(line)
    line.add_argument(
        "--timeout", type=seconds, default=1.0, help="response timeout in seconds (1.0)"
    )
    line.add_argument(
        "--retries", type=address, default=0, help="extra attempts after a timeout (0)"
    )


def reference(text: str) -> Reference:
    """The reference `--ref` gives; a 4-digit one that reads as a register is refused."""
    digits = text.strip()
    if len(digits) == 4 and digits.isdigit() and digits[0] in "134":
        kind = {"1": "discrete input", "3": "input register", "4": "holding register"}
        number = int(digits[1:])
        raise UsageError(
            f"--ref {digits} is ambiguous: write {digits[0]}{number:04d} for "
            f"{kind[digits[0]]} {number}, or 0{digits} for coil {int(digits)}"
        )
    return parse_reference(text)


@asynccontextmanager
async def open_from_args(
    args: argparse.Namespace, *, reconnect: bool = False, **options: object
) -> AsyncIterator[Master]:
    """Open a master on `args.port` with the line options of `args`.

    With `reconnect` the master reopens the port after it disappears; without, a lost
    line fails the command (exit 1)."""
    # Imported here, not above: ``--help`` and bad arguments need none of the master.
    from aiortu.master import open_master

    resolve_line_settings(args)
    async with open_master(
        args.port,
        baudrate=args.baudrate,
        bytesize=args.bytesize,
        parity=args.parity,
        stopbits=args.stopbits,
        timeout=args.timeout,
        retries=args.retries,
        reconnect=reconnect,
        **transport_options(args),
        **options,  # type: ignore[arg-type]
    ) as master:
        yield master


def _describe(error: BaseException) -> tuple[int, str]:
    if isinstance(error, InvalidValue):
        return 2, f"error: {invalid_value(error)}"
    if isinstance(error, UsageError):
        return 2, f"error: {error}"
    if isinstance(error, PortError):
        return 1, port_failure(error)
    if isinstance(error, ConnectionLost):
        return 1, str(error)
    if isinstance(error, ResponseTimeout):
        return 3, str(error)
    if isinstance(error, ExceptionResponse):
        return 4, str(error)
    if isinstance(error, FrameError):
        return 5, f"invalid reply: {error}"
    raise error


def run_master(args: argparse.Namespace, body: Callable[[], Awaitable[int]]) -> int:
    """Run `body` in an event loop; print a failure as one line on stderr, return the code."""
    prog = f"aiortu {args.command}"
    try:
        import anyio

        return anyio.run(body)
    except* (UsageError, InvalidValue, PortError, ConnectionLost, ResponseTimeout) as group:
        code, message = _describe(_first(group))
    except* FrameError as group:
        code, message = _describe(_first(group))
    except* ExceptionResponse as group:
        code, message = _describe(_first(group))
    print(f"{prog}: {message}", file=sys.stderr)
    return code


async def until_signal(work: Callable[[], Awaitable[object]]) -> None:
    """Await `work()` until it ends or SIGINT or SIGTERM comes; a signal ends it cleanly."""
    import signal

    import anyio

    with anyio.open_signal_receiver(signal.SIGINT, signal.SIGTERM) as signals:
        async with anyio.create_task_group() as tasks:

            async def stop_on_signal() -> None:
                async for _ in signals:
                    tasks.cancel_scope.cancel()

            tasks.start_soon(stop_on_signal)
            await work()
            tasks.cancel_scope.cancel()


def _first(group: BaseExceptionGroup[BaseException]) -> BaseException:
    error: BaseException = group
    while isinstance(error, BaseExceptionGroup):
        error = error.exceptions[0]
    return error

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
    seconds_or_zero,
    unit,
    unit_id,
)
from aiortu.cli._messages import invalid_value, port_failure
from aiortu.cli._transport_options import (
    add_transport_options,
    misplaced_option,
    transport_options,
)
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
    "add_rs485_options",
    "rs485_options",
    "address",
    "open_from_args",
    "positive_int",
    "reference",
    "run_master",
    "seconds",
    "unit",
    "unit_id",
    "check_span",
    "check_unit_for_port",
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
    add_rs485_options(parser)


def add_rs485_options(parser: argparse.ArgumentParser) -> None:
    """Add the kernel RS-485 mode's options (`RS485Options`); any of them turns it on."""
    rs485 = parser.add_argument_group(
        "RS-485 (the driver switches the transceiver with RTS; needs a UART that supports it)"
    )
    rs485.add_argument(
        "--rs485",
        action="store_true",
        help="RTS high while sending, low while receiving (mbpoll -R)",
    )
    rs485.add_argument(
        "--rs485-rts-low",
        action="store_true",
        help="RTS low while sending, high while receiving, for inverted adapters (mbpoll -F)",
    )
    rs485.add_argument(
        "--rs485-delay-before-tx",
        type=seconds_or_zero,
        default=None,
        metavar="S",
        help="seconds between raising RTS and the first bit (the driver's own)",
    )
    rs485.add_argument(
        "--rs485-delay-before-rx",
        type=seconds_or_zero,
        default=None,
        metavar="S",
        help="seconds between the last bit and releasing RTS (the driver's own)",
    )
    rs485.add_argument(
        "--rs485-receive-during-tx",
        action="store_true",
        help="keep the receiver on while sending; the echo of each request is dropped",
    )


def rs485_options(args: argparse.Namespace) -> dict[str, object]:
    """The transport options of `args`' RS-485 flags: none unless one is given."""
    wanted = (
        args.rs485
        or args.rs485_rts_low
        or args.rs485_receive_during_tx
        or args.rs485_delay_before_tx is not None
        or args.rs485_delay_before_rx is not None
    )
    if not wanted:
        return {}
    if "://" in args.port:
        raise UsageError("the --rs485 options are for a serial port, not a URL")
    from aiortu.transport import RS485Options

    options = RS485Options(
        rts_level_for_tx=not args.rs485_rts_low,
        rts_level_for_rx=args.rs485_rts_low,
        delay_before_tx=args.rs485_delay_before_tx,
        delay_before_rx=args.rs485_delay_before_rx,
        receive_during_tx=args.rs485_receive_during_tx,
    )
    # A receiver kept on hears our own requests: drop them.
    return {"rs485": options, "local_echo": args.rs485_receive_during_tx}


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


_AT_ONCE: dict[tuple[Table, str], int] = {
    (Table.COILS, "read"): 2000,
    (Table.DISCRETE_INPUTS, "read"): 2000,
    (Table.INPUT_REGISTERS, "read"): 125,
    (Table.HOLDING_REGISTERS, "read"): 125,
    (Table.COILS, "written"): 1968,
    (Table.HOLDING_REGISTERS, "written"): 123,
}
"""The most elements one request may read or write, as the spec allows."""

_ELEMENTS = {
    Table.COILS: "coils",
    Table.DISCRETE_INPUTS: "discrete inputs",
    Table.INPUT_REGISTERS: "input registers",
    Table.HOLDING_REGISTERS: "registers",
}


def check_span(table: Table, start: int, count: int, verb: str) -> None:
    """Refuse, in words, a read or write (`verb` "read" or "written") of `count` elements
    from `start` that one request cannot carry, before the port is opened."""
    noun = _ELEMENTS[table]
    most = _AT_ONCE[table, verb]
    if count > most:
        raise UsageError(f"at most {most} {noun} can be {verb} at once, not {count}")
    last = start + count - 1
    if last > 0xFFFF:
        raise UsageError(
            f"the {noun} {verb} must end at address 65535 or before, not {last} "
            f"({start} + {count} {noun})"
        )


def check_unit_for_port(port: str, unit_address: int) -> None:
    """Refuse a unit id the port's framing cannot take: a serial line (or RTU or ASCII over
    TCP) takes 1..247, Modbus TCP, UDP and TLS any id 0..255, as given in their header."""
    if port.strip().lower().startswith(("tcp://", "udp://", "tls://")):
        return
    try:
        unit(str(unit_address))
    except argparse.ArgumentTypeError as error:
        raise UsageError(f"argument --unit: {error}") from None


@asynccontextmanager
async def open_from_args(
    args: argparse.Namespace, *, reconnect: bool = False, **options: object
) -> AsyncIterator[Master]:
    """Open a master on `args.port` with the line options of `args`.

    With `reconnect` the master reopens the port after it disappears; without, a lost
    line fails the command (exit 1)."""
    # Imported here, not above: ``--help`` and bad arguments need none of the master.
    from aiortu.master import open_master

    if getattr(args, "unit", None) is not None and isinstance(args.unit, int):
        check_unit_for_port(args.port, args.unit)
    misplaced = misplaced_option(args)
    if misplaced is not None:
        raise UsageError(misplaced)
    resolve_line_settings(args)
    options = {**rs485_options(args), **options}
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

"""`aiortu read`: read coils, discrete inputs, input or holding registers once, and print them.

One line per element (`ADDRESS VALUE`), or with `--json` exactly one JSON object,
`{"unit": U, "table": "...", "address": A, "values": [...]}` (bits as `true` and
`false`). Failures give one line on stderr and the exit codes of
`aiortu.cli`.
"""

from __future__ import annotations

import argparse
import json

from aiortu.cli import SUMMARIES, Subparsers
from aiortu.cli._master import (
    EXIT_CODES_HELP,
    LINE_FLAGS_HELP,
    TABLE_NAMES,
    TABLES,
    UsageError,
    add_line_options,
    address,
    check_span,
    open_from_args,
    positive_int,
    reference,
    run_master,
    unit_id,
)
from aiortu.core.model import Reference, Table, format_reference

__all__ = ("print_values", "register", "run", "target")

_EXAMPLES = f"""\
examples:
  aiortu read /dev/ttyUSB0 --unit 17 --table holding --address 0x6B --count 3
      holding registers 107..109 of unit 17 at 19200 8E1
  aiortu read /dev/ttyUSB0 --unit 17 --ref 40108 --count 3
      the same, by reference (40108 = holding register 107), printed as 40108 ...
  aiortu read /dev/ttyUSB0 --unit 1 --table coils --address 0 --count 16 --json
      16 coils as one JSON object
  aiortu read rtu+tcp://10.0.0.5:4001 --unit 2 --table input --address 0 --count 4
      through a serial device server
  aiortu read tcp://10.0.0.7:502 --unit 1 --table holding --address 0 --count 10
      from a Modbus TCP device (the line settings are not used)

the same reads with mbpoll:
  aiortu read ... --table coils      mbpoll -t 0
  aiortu read ... --table discrete   mbpoll -t 1
  aiortu read ... --table input      mbpoll -t 3
  aiortu read ... --table holding    mbpoll -t 4
  aiortu read ... --address 107      mbpoll -r 108 (mbpoll counts from 1)
  aiortu read ... --count 3          mbpoll -c 3
  aiortu read ... --hex              mbpoll -t 4:hex
  aiortu read ... --rs485            mbpoll -R (--rs485-rts-low: mbpoll -F)

{LINE_FLAGS_HELP}
{EXIT_CODES_HELP}"""


def register(subparsers: Subparsers) -> None:
    """Add the `read` subcommand to `subparsers`."""
    parser = subparsers.add_parser(
        "read",
        help=SUMMARIES["read"],
        description=(
            "Read COUNT elements of one table of one unit, from a protocol address "
            "(--table and --address, decimal or 0x hex) or a reference such as 40108 "
            "(--ref), and print them: one 'ADDRESS VALUE' line per element, or one JSON "
            "object with --json."
        ),
        epilog=_EXAMPLES,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    add_line_options(parser)
    what = parser.add_argument_group("what to read")
    what.add_argument(
        "--unit",
        type=unit_id,
        required=True,
        help="unit address 1..247 (0..255 over tcp://, udp://, tls://)",
    )
    what.add_argument("--table", choices=tuple(TABLES), help="the table (with --address)")
    what.add_argument("--address", type=address, help="the first protocol address (0-based)")
    what.add_argument("--ref", help="a 5- or 6-digit reference instead, e.g. 40108 or 100001")
    what.add_argument("--count", type=positive_int, default=1, help="how many elements (1)")
    shown = parser.add_argument_group("output")
    shown.add_argument("--json", action="store_true", help="print one JSON object")
    shown.add_argument(
        "--hex", action="store_true", help="registers in hex, 0xAE41 (text output; mbpoll :hex)"
    )
    parser.set_defaults(run=run)


def target(args: argparse.Namespace, parser_name: str) -> tuple[Table, int]:
    """The table and address from `--ref` or `--table` and `--address`."""
    if args.ref is not None:
        if args.table is not None or args.address is not None:
            raise UsageError("give either --ref, or --table and --address, not both")
        found = reference(args.ref)
        return found.table, found.address
    if args.table is None or args.address is None:
        raise UsageError(f"{parser_name} needs --table and --address, or --ref")
    return TABLES[args.table], args.address


def run(args: argparse.Namespace) -> int:
    """Read what `args` ask for and print it; return the exit code."""

    async def body() -> int:
        table, start = target(args, "read")
        check_span(table, start, args.count, "read")
        async with open_from_args(args) as master:
            unit, count = args.unit, args.count
            values: list[bool] | list[int]
            if table is Table.COILS:
                values = await master.read_coils(unit, start, count)
            elif table is Table.DISCRETE_INPUTS:
                values = await master.read_discrete_inputs(unit, start, count)
            elif table is Table.INPUT_REGISTERS:
                values = await master.read_input_registers(unit, start, count)
            else:
                values = await master.read_holding_registers(unit, start, count)
        print_values(args, unit, table, start, values)
        return 0

    return run_master(args, body)


def print_values(
    args: argparse.Namespace, unit: int, table: Table, start: int, values: list[bool] | list[int]
) -> None:
    """Print `values` read or written at `start`: one JSON object, or a line each, the
    address in the notation given (a reference after `--ref`, else the protocol address)
    and registers in hex with `--hex`."""
    if args.json:
        document = {"unit": unit, "table": TABLE_NAMES[table], "address": start}
        print(json.dumps({**document, "values": values}), flush=True)
        return
    digits = 6 if args.ref is not None and len(args.ref.strip()) == 6 else 5
    lines = []
    for index, value in enumerate(values):
        address = start + index
        if args.ref is not None:
            where = format_reference(Reference(table, address), 6 if address >= 9999 else digits)
        else:
            where = str(address)
        if isinstance(value, bool):
            shown = str(int(value))
        else:
            shown = f"0x{value:04X}" if getattr(args, "hex", False) else str(value)
        lines.append(f"{where} {shown}")
    print("\n".join(lines), flush=True)

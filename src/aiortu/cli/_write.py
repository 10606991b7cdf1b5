"""`aiortu write`: write coils or holding registers once.

One value goes out as a single write (05 or 06), several as a multiple write (0F or 10);
`--multiple` forces the multiple form for one value. Prints what was written, one
`ADDRESS VALUE` line each, or with `--json` exactly one JSON object,
`{"unit": U, "table": "...", "address": A, "values": [...]}`. Failures give one line on
stderr and the exit codes of `aiortu.cli`.
"""

from __future__ import annotations

import argparse

from aiortu.cli import SUMMARIES, Subparsers
from aiortu.cli._master import (
    EXIT_CODES_HELP,
    LINE_FLAGS_HELP,
    UsageError,
    add_line_options,
    address,
    check_span,
    open_from_args,
    run_master,
    unit_id,
)
from aiortu.cli._read import print_values, target
from aiortu.core.model import Table
from aiortu.errors import InvalidValue

__all__ = ("parse_values", "register", "run")

_EXAMPLES = f"""\
examples:
  aiortu write /dev/ttyUSB0 --unit 17 --table holding --address 0x10 --values 1,2,3
      write holding registers 16..18 of unit 17 (function 10)
  aiortu write /dev/ttyUSB0 --unit 17 --ref 40017 --values 0xBEEF
      one holding register by reference (function 06)
  aiortu write /dev/ttyUSB0 --unit 1 --table coils --address 0 --values on,off,1,0 --json
      four coils (function 0F); coils take 1/0, true/false, on/off

the same writes with mbpoll:
  aiortu write ... --table coils --values 1,0       mbpoll -t 0 ... 1 0
  aiortu write ... --table holding --values 1,2,3   mbpoll -t 4 ... 1 2 3
  aiortu write ... --address 16                     mbpoll -r 17 (mbpoll counts from 1)

{LINE_FLAGS_HELP}
{EXIT_CODES_HELP}"""

_BITS = {"1": True, "0": False, "true": True, "false": False, "on": True, "off": False}


def register(subparsers: Subparsers) -> None:
    """Add the `write` subcommand to `subparsers`."""
    parser = subparsers.add_parser(
        "write",
        help=SUMMARIES["write"],
        description=(
            "Write VALUES to coils or holding registers of one unit, from a protocol "
            "address (--table and --address, decimal or 0x hex) or a reference such as "
            "40017 (--ref)."
        ),
        epilog=_EXAMPLES,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    add_line_options(parser)
    what = parser.add_argument_group("what to write")
    what.add_argument(
        "--unit",
        type=unit_id,
        required=True,
        help="unit address 1..247 (0..255 over tcp://, udp://, tls://)",
    )
    what.add_argument("--table", choices=("coils", "holding"), help="the table (with --address)")
    what.add_argument("--address", type=address, help="the first protocol address (0-based)")
    what.add_argument("--ref", help="a 5- or 6-digit reference instead, e.g. 40017 or 00001")
    what.add_argument(
        "--values",
        required=True,
        help="comma-separated: registers 0..65535 (decimal or 0x hex); coils 1/0/true/false/on/off",
    )
    what.add_argument("--multiple", action="store_true", help="use 0F/10 even for a single value")
    parser.add_argument("--json", action="store_true", help="print one JSON object")
    parser.set_defaults(run=run)


def parse_values(text: str, table: Table) -> list[bool] | list[int]:
    """The comma-separated `text` as coil states or register values for `table`.

    Raises [`InvalidValue`][aiortu.errors.InvalidValue] for an empty list or a bad item.
    """
    items = [item.strip() for item in text.split(",")]
    if not items or any(not item for item in items):
        raise InvalidValue("--values", text, "a comma-separated list without empty items")
    if table is Table.COILS:
        bits: list[bool] = []
        for item in items:
            if item.lower() not in _BITS:
                raise InvalidValue("--values", item, "1, 0, true, false, on or off")
            bits.append(_BITS[item.lower()])
        return bits
    registers: list[int] = []
    for item in items:
        try:
            value = address(item)
        except argparse.ArgumentTypeError:
            raise InvalidValue("--values", item, "0..65535, decimal or 0x hex") from None
        if value > 0xFFFF:
            raise InvalidValue("--values", item, "0..65535, decimal or 0x hex")
        registers.append(value)
    return registers


def run(args: argparse.Namespace) -> int:
    """Write what `args` ask for and print it; return the exit code."""

    async def body() -> int:
        table, start = target(args, "write")
        if not table.writable:
            kind = table.value.replace("_", " ")
            raise UsageError(f"cannot write {kind}: only coils and holding registers are writable")
        values = parse_values(args.values, table)
        check_span(table, start, len(values), "written")
        async with open_from_args(args) as master:
            unit = args.unit
            single = len(values) == 1 and not args.multiple
            if table is Table.COILS:
                bits = [bool(v) for v in values]
                if single:
                    await master.write_coil(unit, start, bits[0])
                else:
                    await master.write_coils(unit, start, bits)
            else:
                registers = [int(v) for v in values]
                if single:
                    await master.write_register(unit, start, registers[0])
                else:
                    await master.write_registers(unit, start, registers)
        print_values(args, unit, table, start, values)
        return 0

    return run_master(args, body)

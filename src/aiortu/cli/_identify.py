"""`aiortu identify`: what a device says it is: its identification objects (function 2B/0E)
and its server id (function 11).

One `NAME: VALUE` line per object, then the server id, or with `--json` exactly one JSON
object, `{"unit": U, "device_identification": {...} | null, "server_id": {...} | null}`. A
device that refuses one of the two (an exception reply) gets a line saying so and `null`
in JSON; the command fails (exit 4) only when it refuses both. Failures give one line on
stderr and the exit codes of `aiortu read`.
"""

from __future__ import annotations

import argparse
import json
from typing import TYPE_CHECKING

from aiortu.cli import SUMMARIES, Subparsers
from aiortu.cli._master import (
    EXIT_CODES_HELP,
    LINE_FLAGS_HELP,
    add_line_options,
    open_from_args,
    run_master,
    unit_id,
)
from aiortu.core.codes import DeviceIdObject, DeviceIdReadCode, ExceptionCode
from aiortu.errors import ExceptionResponse

if TYPE_CHECKING:
    from aiortu.core.pdu import ReportServerIdResponse
    from aiortu.master import UnitHandle

__all__ = ("register", "run")

_EXAMPLES = f"""\
examples:
  aiortu identify /dev/ttyUSB0 --unit 17
      vendor, product code, revision and the other objects, then the server id
  aiortu identify tcp://10.0.0.7:502 --unit 255 --json
      the same from a Modbus TCP device, as one JSON object

the same with mbpoll:
  aiortu identify ... --unit 17      mbpoll -a 17 -u (the server id only)

{LINE_FLAGS_HELP}
{EXIT_CODES_HELP}"""

_LEVELS = {
    "basic": DeviceIdReadCode.BASIC,
    "regular": DeviceIdReadCode.REGULAR,
    "extended": DeviceIdReadCode.EXTENDED,
}

_NOT_THERE = (ExceptionCode.ILLEGAL_DATA_ADDRESS, ExceptionCode.ILLEGAL_DATA_VALUE)
"""What a device answers to a level of identification it does not have."""


def register(subparsers: Subparsers) -> None:
    """Add the `identify` subcommand to `subparsers`."""
    parser = subparsers.add_parser(
        "identify",
        help=SUMMARIES["identify"],
        description=(
            "Read what a unit says it is: its device identification objects (function "
            "2B/0E: vendor name, product code, revision, and the regular and extended "
            "objects it has) and its server id (function 11: the id, the run indicator "
            "and additional data)."
        ),
        epilog=_EXAMPLES,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    add_line_options(parser)
    parser.add_argument(
        "--unit",
        type=unit_id,
        required=True,
        help="unit address 1..247 (0..255 over tcp://, udp://, tls://)",
    )
    parser.add_argument(
        "--level",
        choices=tuple(_LEVELS),
        default="extended",
        help="the objects to read; a device that has fewer gets the basic read (extended)",
    )
    parser.add_argument("--json", action="store_true", help="print one JSON object")
    parser.set_defaults(run=run)


def _text(value: bytes) -> str:
    """An object's bytes as text: UTF-8 where they are, else hex."""
    try:
        text = value.decode()
    except UnicodeDecodeError:
        return value.hex(" ")
    return text if text.isprintable() else value.hex(" ")


def _object_name(object_id: int) -> str:
    try:
        return DeviceIdObject(object_id).name.lower()
    except ValueError:
        return f"0x{object_id:02X}"


def _refusal(error: ExceptionResponse) -> str:
    code = error.code
    name = code.name.lower().replace("_", " ") if isinstance(code, ExceptionCode) else "?"
    return f"refused (exception {int(code):02X}, {name})"


def run(args: argparse.Namespace) -> int:
    """Read and print what `args.unit` says it is; return the exit code."""

    async def body() -> int:
        async with open_from_args(args) as master:
            unit = master.slave(args.unit)
            objects = await _identification(unit, _LEVELS[args.level])
            try:
                server: ReportServerIdResponse | ExceptionResponse = await unit.report_server_id()
            except ExceptionResponse as error:
                server = error
        if isinstance(objects, ExceptionResponse) and isinstance(server, ExceptionResponse):
            raise objects
        _print(args, objects, server)
        return 0

    return run_master(args, body)


async def _identification(
    unit: UnitHandle, level: DeviceIdReadCode
) -> dict[int, bytes] | ExceptionResponse:
    """The objects `unit` has at `level`; a device that has fewer (it answers 02 or 03)
    gets the basic read; the exception it answers to that, if it refuses."""
    try:
        return await unit.read_device_identification(level)
    except ExceptionResponse as error:
        if error.code not in _NOT_THERE or level == DeviceIdReadCode.BASIC:
            return error
    try:
        return await unit.read_device_identification(DeviceIdReadCode.BASIC)
    except ExceptionResponse as error:
        return error


def _print(
    args: argparse.Namespace,
    objects: dict[int, bytes] | ExceptionResponse,
    server: ReportServerIdResponse | ExceptionResponse,
) -> None:
    named = (
        None
        if isinstance(objects, ExceptionResponse)
        else {_object_name(key): _text(value) for key, value in sorted(objects.items())}
    )
    reported = (
        None
        if isinstance(server, ExceptionResponse)
        else {
            "id": server.server_id.hex(),
            "running": server.run_indicator,
            "data": _text(server.additional_data),
        }
    )
    if args.json:
        document = {"unit": args.unit, "device_identification": named, "server_id": reported}
        print(json.dumps(document), flush=True)
        return
    lines = (
        [f"device identification: {_refusal(objects)}"]
        if isinstance(objects, ExceptionResponse)
        else [f"{name.replace('_', ' ')}: {value}" for name, value in (named or {}).items()]
    )
    if isinstance(server, ExceptionResponse):
        lines.append(f"server id: {_refusal(server)}")
    else:
        running = "on" if server.run_indicator else "off"
        lines.append(f"server id: 0x{server.server_id.hex().upper()}, run indicator {running}")
        if server.additional_data:
            lines.append(f"additional data: {_text(server.additional_data)}")
    print("\n".join(lines), flush=True)

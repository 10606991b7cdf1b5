"""`aiortu monitor`: a passive sniffer that prints every frame on a bus with its meaning.

Opens the port (a device path or `rtu+tcp://host:port`), listens with a receiver in
the `MONITOR` role and never sends. Each frame becomes one line on stdout: the time,
the direction, the CRC status and a description from
[`BusDecoder`][aiortu.core.rtu.BusDecoder], or, with `--json`, one JSON object. Runs
until SIGINT or SIGTERM and exits 0; a port that cannot be opened, or that fails while
listening, gives one line on stderr and exit code 1.
"""

from __future__ import annotations

import argparse
import datetime
import json
import os
import signal
import sys
import time
from collections.abc import AsyncIterator
from typing import TextIO

import anyio
import anyio.abc

from aiortu.cli import SUMMARIES, CommandFailed, Subparsers
from aiortu.cli._arguments import add_line_settings, add_timing, resolve_line_settings
from aiortu.cli._messages import port_failure
from aiortu.cli._monitor_ascii import monitor_ascii
from aiortu.core.rtu import BusDecoder, DecodedFrame, Role
from aiortu.core.serial import LineSettings
from aiortu.errors import ConnectionLost, InvalidValue, PortError
from aiortu.line import Link
from aiortu.transport import ModbusTcpAddress, open_stream, parse_port_url

__all__ = ("FramePrinter", "register", "run")

_EXAMPLES = """\
examples:
  aiortu monitor /dev/ttyUSB0
      watch a bus at 19200 8E1 (the spec's default)
  aiortu monitor /dev/ttyUSB0 --baudrate 9600 --parity N --stopbits 2 --raw
      9600 8N2, with each frame in hex too
  aiortu monitor rtu+tcp://192.168.1.50:4001 --json | jq 'select(.crc != "ok")'
      through a serial device server; one JSON object per frame, errors only
  aiortu monitor /dev/ttyUSB0 --timing strict --time iso
      the spec's t1.5 rule (gaps inside frames break them), wall-clock times
  aiortu monitor /dev/ttyUSB0 --framing ascii --baudrate 9600
      a Modbus ASCII bus at 9600 7E1 (the spec's ASCII default)

line settings as mbpoll spells them (mbpoll -m rtu ...):
  aiortu monitor --baudrate 9600    mbpoll -b 9600
  aiortu monitor --parity E|O|N     mbpoll -P even|odd|none
  aiortu monitor --stopbits 2       mbpoll -s 2

output: time, direction, CRC status, meaning (and " | " and the hex with --raw):
      0.0157 request   ok        unit 17 read holding registers 107..109 (3)
      0.0221 reply     ok        unit 17 reply holding 107..109 = [44609, 22098, 17216]
      0.5303 unknown   error     CRC error: 11 03 06 AE 41 56 52 43 40 49 AE

exit codes:
  0  stopped by SIGINT (Ctrl-C) or SIGTERM
  1  the port could not be opened, or failed while listening (one line on stderr)
  2  bad arguments
"""


def register(subparsers: Subparsers) -> None:
    """Add the `monitor` subcommand to `subparsers`."""
    parser = subparsers.add_parser(
        "monitor",
        help=SUMMARIES["monitor"],
        description=(
            "Listen to a Modbus RTU bus (or ASCII, with --framing ascii) without ever "
            "transmitting, and print each frame "
            "on one line: when it arrived, whether it is a request, a reply, an exception "
            "reply or a broadcast, its CRC status, and what it means (function, addresses, "
            "values; a reply is paired with its request so that it names its addresses). "
            "Runs until interrupted (SIGINT or SIGTERM)."
        ),
        epilog=_EXAMPLES,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    parser.add_argument("port", metavar="PORT", help="a serial device path or rtu+tcp://host:port")
    line = parser.add_argument_group("line settings")
    add_line_settings(line)
    add_timing(line)
    line.add_argument(
        "--framing",
        choices=("rtu", "ascii"),
        default="rtu",
        help="the bus's framing: rtu, or ascii (7E1 by default, 8N2 on a pseudo-terminal) (rtu)",
    )
    output = parser.add_argument_group("output")
    output.add_argument(
        "--json", action="store_true", help="one JSON object per line instead of text"
    )
    output.add_argument("--raw", action="store_true", help="add the bytes of each frame in hex")
    output.add_argument(
        "--time",
        choices=("relative", "iso"),
        default="relative",
        help="seconds since the start, or ISO 8601 local time (relative)",
    )
    parser.set_defaults(run=run)


class FramePrinter:
    """Writes decoded frames to `out`, one line each, flushed at once.

    `start` is the receiver-clock time that relative times count from, and `wall_start`
    the wall-clock time (seconds since the epoch) at that moment, for ISO times.
    """

    def __init__(
        self,
        out: TextIO,
        *,
        start: float,
        wall_start: float,
        json_lines: bool = False,
        raw: bool = False,
        iso_time: bool = False,
    ) -> None:
        self.out = out
        self.start = start
        self.wall_start = wall_start
        self.json_lines = json_lines
        self.raw = raw
        self.iso_time = iso_time

    def timestamp(self, clock_time: float) -> float | str:
        """Relative seconds (rounded to the microsecond), or an ISO 8601 local time."""
        elapsed = clock_time - self.start
        if self.iso_time:
            moment = datetime.datetime.fromtimestamp(self.wall_start + elapsed).astimezone()
            return moment.isoformat(timespec="microseconds")
        return round(elapsed, 6)

    def format(self, record: DecodedFrame) -> str:
        """The line for `record`, without the newline."""
        stamp = self.timestamp(record.time)
        if self.json_lines:
            data = record.to_dict(raw=self.raw)
            data["time"] = stamp
            data["end"] = self.timestamp(record.end)
            return json.dumps(data, separators=(",", ":"))
        when = f"{stamp:10.4f}" if isinstance(stamp, float) else stamp
        line = f"{when} {record.direction.value:<9} {record.crc.value:<9} {record.description}"
        if self.raw:
            line += f" | {record.frame.hex(' ').upper()}"
        return line

    def emit(self, record: DecodedFrame) -> None:
        """Write and flush the line for `record`."""
        self.out.write(self.format(record) + "\n")
        self.out.flush()


def run(args: argparse.Namespace) -> int:
    """Monitor the port described by `args` until SIGINT or SIGTERM; return the exit code."""
    return anyio.run(_monitor, args)


async def _monitor(args: argparse.Namespace) -> int:
    resolve_line_settings(args)
    settings = LineSettings(args.baudrate, args.bytesize, args.parity, args.stopbits)
    if isinstance(parse_port_url(args.port), ModbusTcpAddress):
        raise InvalidValue(
            "PORT",
            args.port,
            "a serial device path or rtu+tcp://host:port",
            "a Modbus TCP connection carries only its own requests and replies",
        )
    # The handlers go in first, so that a signal while the port opens still ends cleanly.
    with anyio.open_signal_receiver(signal.SIGINT, signal.SIGTERM) as signals:
        try:
            stream = await open_stream(args.port, settings)
        except PortError as exc:
            raise CommandFailed(f"cannot open the port: {port_failure(exc)}") from exc
        if args.framing == "ascii":
            return await _monitor_ascii(args, stream, settings, signals)
        failure: str | None = None
        async with Link(stream, settings, role=Role.MONITOR, timing=args.timing) as link:
            printer = FramePrinter(
                sys.stdout,
                start=link.clock(),
                wall_start=time.time(),
                json_lines=args.json,
                raw=args.raw,
                iso_time=args.time == "iso",
            )
            print(
                f"aiortu monitor: listening on {args.port} at {settings}"
                f" ({args.timing} timing); Ctrl-C to stop",
                file=sys.stderr,
                flush=True,
            )
            decoder = BusDecoder()
            async with anyio.create_task_group() as group:
                group.start_soon(_stop_on_signal, signals, group.cancel_scope)
                while True:
                    try:
                        event = await link.receive()
                    except ConnectionLost as exc:
                        failure = str(exc)
                        group.cancel_scope.cancel()
                        break
                    try:
                        printer.emit(decoder.feed(event))
                    except BrokenPipeError:
                        # The reader went away (``| head``): stop quietly, and keep
                        # Python from complaining when it flushes stdout at exit.
                        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
                        group.cancel_scope.cancel()
                        break
    if failure is not None:
        raise CommandFailed(failure)
    return 0


async def _monitor_ascii(
    args: argparse.Namespace,
    stream: anyio.abc.ByteStream,
    settings: LineSettings,
    signals: AsyncIterator[signal.Signals],
) -> int:
    clock = time.monotonic
    printer = FramePrinter(
        sys.stdout, start=clock(), wall_start=time.time(), json_lines=args.json, raw=args.raw,
        iso_time=args.time == "iso",
    )  # fmt: skip
    print(
        f"aiortu monitor: listening on {args.port} at {settings} (Modbus ASCII); Ctrl-C to stop",
        file=sys.stderr,
        flush=True,
    )
    failure: str | None = None
    async with stream, anyio.create_task_group() as group:
        group.start_soon(_stop_on_signal, signals, group.cancel_scope)
        try:
            await monitor_ascii(stream, settings, clock, printer.emit)
        except BrokenPipeError:
            os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        except (ConnectionLost, anyio.EndOfStream, anyio.BrokenResourceError) as exc:
            failure = str(exc) or f"{args.port}: the line closed"
        group.cancel_scope.cancel()
    if failure is not None:
        raise CommandFailed(failure)
    return 0


async def _stop_on_signal(signals: AsyncIterator[signal.Signals], scope: anyio.CancelScope) -> None:
    async for _ in signals:
        scope.cancel()
        return

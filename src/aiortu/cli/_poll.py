"""`aiortu poll`: poll points on one or more units and show them as a table.

The points come from `--ref` with `--count` (COUNT values of one type from that
reference, on every `--unit`) or from repeated `--point NAME=UNIT:REF[:TYPE[:LAYOUT]]`.
On a terminal the table is redrawn in place after each cycle (ANSI cursor movement);
when stdout is not a terminal each cycle is printed as plain lines followed by a blank
line, and with `--json` each sample is one JSON object per line. Each unit's health
(online, suspect or offline, failures in a row, latency, the next probe) is shown under the
points. Runs until `--cycles` or `--duration` is reached, or SIGINT/SIGTERM (exit 0).
When the port disappears the master reopens it, and the table says `line down,
reopening` meanwhile; with `--no-reconnect` a lost line ends the command (exit 1).
"""

from __future__ import annotations

import argparse
import json
import sys
from enum import Enum
from typing import TextIO

from aiortu.cli import SUMMARIES, Subparsers
from aiortu.cli._arguments import add_no_reconnect, add_timing, number, plural
from aiortu.cli._arguments import unit as unit_address
from aiortu.cli._master import (
    LINE_FLAGS_HELP,
    UsageError,
    add_line_options,
    address,
    open_from_args,
    positive_int,
    reference,
    run_master,
    seconds,
    until_signal,
)
from aiortu.core.model import Layout, Point, Reference, ValueType, format_reference
from aiortu.errors import (
    ConnectionLost,
    CRCError,
    ExceptionResponse,
    FrameError,
    InvalidValue,
    ResponseTimeout,
    UnitOffline,
    UnitSkipped,
)
from aiortu.master import CycleReport, Poller, Sample, UnitHealth, UnitState

__all__ = ("TablePrinter", "parse_point", "points_from_args", "register", "run")

POLL_EXIT_CODES_HELP = """\
exit codes:
  0  ran its --cycles or --duration, or stopped by Ctrl-C or SIGTERM; a point or a
     unit that fails (no reply, an exception) is shown in the table, not an exit code
  1  the port could not be opened, or was lost with --no-reconnect
  2  bad arguments (one line on stderr)
"""

_EXAMPLES = f"""\
examples:
  aiortu poll /dev/ttyUSB0 --unit 1 --ref 40001 --count 4
      four holding registers of unit 1, once a second
  aiortu poll /dev/ttyUSB0 --unit 1,2,3 --ref 30001 --count 2 --type float32 --layout CDAB
      two word-swapped floats from the input registers of units 1, 2 and 3
  aiortu poll /dev/ttyUSB0 --point temp=1:30001:int16 --point flow=2:40108:float32:CDAB \\
        --interval 0.5 --cycles 10
      named points on two units, ten cycles, twice a second
  aiortu poll /dev/ttyUSB0 --unit 1 --ref 00001 --count 8 --json | jq .value
      eight coils, one JSON object per sample

the same with mbpoll (which polls one unit and one range):
  aiortu poll ... --unit 1 --ref 40001 --count 4     mbpoll -a 1 -t 4 -r 1 -c 4
  aiortu poll ... --type float32 --layout CDAB       mbpoll -t 4:float
  aiortu poll ... --type float32 --layout ABCD       mbpoll -t 4:float -B
  aiortu poll ... --type int32 --layout CDAB         mbpoll -t 4:int
  aiortu poll ... --interval 0.5                     mbpoll -l 500
  aiortu poll ... --cycles 1                         mbpoll -1
  aiortu poll ... --hex                              mbpoll -t 4:hex

{LINE_FLAGS_HELP}
{POLL_EXIT_CODES_HELP}"""


def register(subparsers: Subparsers) -> None:
    """Add the `poll` subcommand to `subparsers`."""
    parser = subparsers.add_parser(
        "poll",
        help=SUMMARIES["poll"],
        description=(
            "Poll points at an interval and show their values with each unit's health. "
            "Neighbouring points of a unit are read together (--max-gap); a device that "
            "refuses such a read for a hole in its map gets the points' own reads instead, "
            "from then on. The table refreshes in place "
            "on a terminal; piped, each cycle is printed as plain lines."
        ),
        epilog=_EXAMPLES,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    add_line_options(parser)
    add_timing(parser)
    what = parser.add_argument_group("what to poll")
    what.add_argument(
        "--unit", help="unit address(es) for --ref: 1..247, comma-separated for several"
    )
    what.add_argument("--ref", help="the first reference, e.g. 40001 (with --unit)")
    what.add_argument("--profile", help="poll every point of a profile (a file or a shipped name)")
    what.add_argument("--count", type=positive_int, default=1, help="values from --ref (1)")
    what.add_argument(
        "--type",
        choices=[kind.value for kind in ValueType],
        default=ValueType.UINT16.value,
        help="register value type (uint16)",
    )
    what.add_argument(
        "--layout",
        choices=[layout.value for layout in Layout],
        default=Layout.ABCD.value,
        help="word and byte order of wider values (ABCD: big-endian)",
    )
    what.add_argument("--scale", type=number, default=None, help="multiply values by this")
    what.add_argument(
        "--max-gap",
        type=address,
        default=10,
        metavar="N",
        help=(
            "read neighbouring points of a unit together when at most N unused registers "
            "(16 N bits) lie between them; 0 reads only adjacent points together (10)"
        ),
    )
    what.add_argument(
        "--point",
        action="append",
        default=[],
        metavar="NAME=UNIT:REF[:TYPE[:LAYOUT]]",
        help="a named point; repeat for several",
    )
    timing = parser.add_argument_group("when")
    timing.add_argument("--interval", type=seconds, default=1.0, help="seconds per cycle (1.0)")
    timing.add_argument("--cycles", type=positive_int, default=None, help="stop after N cycles")
    timing.add_argument("--duration", type=seconds, default=None, help="stop after S seconds")
    timing.add_argument(
        "--probe-interval",
        type=seconds,
        default=5.0,
        help="seconds between probes of an offline unit (5.0)",
    )
    parser.add_argument("--json", action="store_true", help="one JSON object per sample")
    parser.add_argument(
        "--hex", action="store_true", help="whole numbers in hex in the table (mbpoll :hex)"
    )
    add_no_reconnect(parser)
    parser.set_defaults(run=run)


def parse_point(text: str) -> Point:
    """A point from `NAME=UNIT:REF[:TYPE[:LAYOUT]]`; InvalidValue if malformed."""
    name, equals, spec = text.partition("=")
    fields = spec.split(":")
    if not equals or not name or not 2 <= len(fields) <= 4:
        raise InvalidValue("--point", text, "NAME=UNIT:REF[:TYPE[:LAYOUT]]")
    unit = _unit(fields[0])
    kind = fields[2] if len(fields) > 2 else ValueType.UINT16.value
    layout = fields[3] if len(fields) > 3 else Layout.ABCD.value
    reference(fields[1])
    return Point.of(name, unit, fields[1], kind, layout=layout)


def _unit(text: str) -> int:
    if not text.strip():
        raise UsageError("--unit must be unit addresses 1..247, comma-separated, without gaps")
    try:
        return unit_address(text)
    except argparse.ArgumentTypeError as error:
        raise UsageError(f"--unit {error}") from None


def points_from_args(args: argparse.Namespace) -> list[Point]:
    """The points `args` describe (`--ref` on each `--unit`, then each `--point`)."""
    found = [parse_point(text) for text in args.point]
    if args.ref is not None:
        if args.unit is None:
            raise UsageError("--ref needs --unit")
        units = [_unit(item) for item in args.unit.split(",")]
        reference(args.ref)
        first = Point.of("first", units[0], args.ref, args.type, layout=args.layout)
        for unit in units:
            for index in range(args.count):
                start = first.address + index * first.width
                name = _reference_name(Reference(first.table, start))
                found.append(
                    Point(
                        name if len(units) == 1 else f"{unit}/{name}",
                        unit,
                        first.table,
                        start,
                        first.type,
                        first.layout,
                        args.scale,
                    )
                )
    if not found:
        raise UsageError("give --ref (with --unit) or at least one --point")
    names = [point.name for point in found]
    for name in names:
        if names.count(name) > 1:
            raise UsageError(f"--point {name} is given twice: each point needs a name of its own")
    return found


def _reference_name(reference: Reference) -> str:
    return format_reference(reference, 5 if reference.number <= 9999 else 6)


_FAILURES: tuple[tuple[type[Exception], str], ...] = (
    (UnitSkipped, "skipped, unit offline"),
    (UnitOffline, "unit offline"),
    (ResponseTimeout, "no reply"),
    (CRCError, "bad CRC"),
    (FrameError, "bad reply"),
    (ConnectionLost, "line lost"),
)
"""What the table shows for a point that could not be read, by error (first match)."""


def _failure(error: Exception) -> str:
    """Why a point has no value, in a few words: `no reply`, `exception 02 (illegal data
    address)`, `line lost`."""
    if isinstance(error, ExceptionResponse):
        code = error.code
        meaning = f" ({code.name.lower().replace('_', ' ')})" if isinstance(code, Enum) else ""
        return f"exception {int(code):02X}{meaning}"
    for kind, words in _FAILURES:
        if isinstance(error, kind):
            return words
    return "failed"


def _format_value(sample: Sample, *, hex_digits: bool = False) -> str:
    """A sample's value as the table shows it; whole numbers in hex with `hex_digits`,
    as wide as the point (0x002A for one register, 0x0000002A for two)."""
    if sample.error is not None:
        return f"-- {_failure(sample.error)}"
    value = sample.value
    if isinstance(value, bool):
        return "1" if value else "0"
    if isinstance(value, float):
        return f"{value:.6g}"
    if hex_digits and value is not None:
        digits = 4 * sample.point.width
        # A negative number as its two's complement, as it sits in the registers.
        return f"0x{value & ((1 << (4 * digits)) - 1):0{digits}X}"
    return str(value)


class TablePrinter:
    """Prints cycles to `out`: redrawn in place with `ansi`, else as plain blocks."""

    def __init__(
        self, out: TextIO, poller: Poller, *, ansi: bool, hex_digits: bool = False
    ) -> None:
        self.out = out
        self.poller = poller
        self.ansi = ansi
        self.hex_digits = hex_digits
        self._latest: dict[str, Sample] = {}
        self._shown = 0

    def lines(self, report: CycleReport) -> list[str]:
        """The table after `report`: a header, the points, each unit's health."""
        for sample in report.samples:
            self._latest[sample.name] = sample
        stats = self.poller.cycle_time
        mean = (stats.mean or 0.0) * 1000
        lines = [
            f"cycle {report.index + 1}  time {report.duration * 1000:.1f} ms  mean {mean:.1f} ms",
            f"{'POINT':<16}{'UNIT':>5}  VALUE",
        ]
        for point in self.poller.points:
            latest = self._latest.get(point.name)
            shown = "--"
            if latest is not None:
                shown = _format_value(latest, hex_digits=self.hex_digits)
            lines.append(f"{point.name:<16}{point.unit:>5}  {shown}")
        if self.poller.master.connected:
            now = self.poller.master.link.clock()
            lines.extend(health_line(health, now) for health in self.poller.health().values())
        else:
            lines.append("line down, reopening")
        return lines

    def show(self, report: CycleReport) -> None:
        """Print the table after `report`."""
        lines = self.lines(report)
        if self.ansi:
            # Back to the first line of the previous table, and clear it all.
            prefix = f"\x1b[{self._shown}F\x1b[J" if self._shown else ""
            self.out.write(prefix + "\n".join(lines) + "\n")
            self._shown = len(lines)
        else:
            self.out.write("\n".join(lines) + "\n\n")
        self.out.flush()


def health_line(health: UnitHealth, now: float) -> str:
    """One unit's health as the table shows it, at `now` on the master's clock."""
    parts = [f"unit {health.unit}: {health.state.value}"]
    if health.state is UnitState.OFFLINE:
        parts[0] = f"unit {health.unit}: OFFLINE"
    failures = health.consecutive_failures
    if failures:
        parts.append(f"{plural(failures, 'failure')} in a row")
    if health.next_probe is not None:
        parts.append(f"next probe in {max(0.0, health.next_probe - now):.1f} s")
    elif health.last_latency is not None:
        parts.append(f"latency {health.last_latency * 1000:.1f} ms")
    return ", ".join(parts)


def _fail_on_lost_line(report: CycleReport) -> None:
    """Without reconnecting, a lost line ends the command once its cycle is shown."""
    for sample in report.samples:
        if isinstance(sample.error, ConnectionLost):
            raise sample.error


def _json_sample(sample: Sample) -> str:
    # Cycles are numbered from 1, as in the table.
    document = {
        "cycle": sample.cycle + 1,
        "name": sample.name,
        "unit": sample.unit,
        "value": sample.value,
        "error": None if sample.error is None else str(sample.error),
    }
    return json.dumps(document)


def run(args: argparse.Namespace) -> int:
    """Poll what `args` ask for until told to stop; return the exit code."""
    if args.profile is not None:
        from aiortu.cli._profile import run_poll

        return run_poll(args)

    async def body() -> int:
        points = points_from_args(args)
        async with open_from_args(args, reconnect=args.reconnect, timing=args.timing) as master:
            poller = Poller(
                master,
                points,
                interval=args.interval,
                max_gap=args.max_gap,
                offline_probe_interval=args.probe_interval,
            )
            if args.json:
                poller.on_sample(lambda s: print(_json_sample(s), flush=True))
            else:
                printer = TablePrinter(
                    sys.stdout, poller, ansi=sys.stdout.isatty(), hex_digits=args.hex
                )
                poller.on_cycle(printer.show)
            if not args.reconnect:
                poller.on_cycle(_fail_on_lost_line)
            await until_signal(lambda: poller.run(cycles=args.cycles, duration=args.duration))
        return 0

    return run_master(args, body)

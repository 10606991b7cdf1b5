# ruff: noqa: ASYNC109
# ``timeout=`` here is each probe's response timeout, counted from when the request has
# left the wire; a cancel scope around the call cannot express that.
"""`aiortu scan`: find the units that answer on a port, and the line settings they use.

For each combination of baud rate, parity and stop bits, the port is opened once with
those settings, and each unit is sent a cheap request: read one holding register at
address 0 (function 03). Any reply whose CRC checks counts as a device, an exception
reply included: a device that has no register 0 still says "illegal data address". Bytes
that fail the CRC or the framing are counted as garbled traffic: something is talking,
but most likely at other settings.

A reply that comes after its probe timed out is still credited to the unit that sent it,
so a slow device is found even when the timeout is short (it may then show up while
the next unit is probed).

Exit codes: 0 at least one unit answered, 1 none did (or the port cannot be opened at
all), 2 bad arguments.
"""

from __future__ import annotations

import argparse
import math
import os
import signal
import sys
from collections.abc import AsyncIterator, Callable, Iterable, Sequence
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, TextIO

import anyio
import anyio.abc

from aiortu.cli import SUMMARIES, CommandFailed, Subparsers
from aiortu.cli._arguments import is_pty, plural
from aiortu.cli._messages import port_failure
from aiortu.core.codes import EXCEPTION_BIT, UNIT_ADDRESSES, ExceptionCode, FunctionCode
from aiortu.core.pdu import (
    ExceptionPDU,
    ReadHoldingRegistersRequest,
    ReadHoldingRegistersResponse,
    decode_response,
)
from aiortu.core.rtu import FrameReceived, Role, encode_frame
from aiortu.core.serial import LineSettings, Parity
from aiortu.errors import (
    ConfigError,
    ConnectionLost,
    ModbusError,
    PortError,
    PortNotFound,
    UnsupportedSettings,
)
from aiortu.line import Link
from aiortu.transport import open_stream

if TYPE_CHECKING:
    from aiortu.core.model import Profile

__all__ = (
    "DEFAULT_BAUDRATES",
    "DEFAULT_PARITIES",
    "Answer",
    "SettingResult",
    "parse_units",
    "probe_units",
    "register",
    "report",
    "run",
    "scan",
    "settings_to_try",
)

_EXAMPLES = """\
examples:
  aiortu scan /dev/ttyUSB0
      every unit 1-247 at 19200, 9600, 38400, 57600 and 115200 baud, parity E, N and O
  aiortu scan /dev/ttyUSB0 --baudrates 9600,19200 --parities E --units 1-20
      a quick look: 40 probes, about 4 seconds
  aiortu scan /dev/ttyUSB0 --first --quiet
      stop at the first line settings at which a unit answers, no progress output
  aiortu scan /dev/ttyUSB0 --units 1,2,10-12 --timeout 0.5
      only some units, with a longer timeout for slow devices
  aiortu scan rtu+tcp://192.168.1.50:4001 --baudrates 19200
      through a serial device server (its serial settings are set on the server)

line settings as mbpoll spells them (mbpoll -m rtu ...; mbpoll has no scan, so
each setting and unit would be one mbpoll run):
  aiortu scan --baudrates 9600     mbpoll -b 9600
  aiortu scan --parities E,O,N     mbpoll -P even / -P odd / -P none
  aiortu scan --stopbits 2         mbpoll -s 2
  aiortu scan --units 1-10         mbpoll -a 1 ... mbpoll -a 10
  aiortu scan --timeout 0.2        mbpoll -o 0.2
  (each probe is mbpoll -t 4 -r 1 -c 1 -1, holding register 40001)

exit codes:
  0  at least one unit answered
  1  no unit answered, or the port cannot be opened (one line on stderr)
  2  bad arguments
"""

DEFAULT_BAUDRATES = (19200, 9600, 38400, 57600, 115200)
"""The baud rates tried when none are given: the spec's default first."""

DEFAULT_PARITIES = (Parity.EVEN, Parity.NONE, Parity.ODD)
"""The parities tried when none are given: the spec's default first."""

_PROBE = ReadHoldingRegistersRequest(0, 1)
_PARITY_NAMES = {"N": "N", "E": "E", "O": "O", "NONE": "N", "EVEN": "E", "ODD": "O"}


@dataclass(frozen=True, slots=True)
class Answer:
    """A unit that answered at `settings`: what it said, and how long after the probe
    went out (None for a late reply credited after its probe timed out)."""

    unit: int
    settings: LineSettings
    answer: str
    latency: float | None


@dataclass(slots=True)
class SettingResult:
    """What one line setting gave: the units that answered, the bad frames seen, and
    whether the port refused the setting (`skipped`, with the reason)."""

    settings: LineSettings
    answers: list[Answer] = field(default_factory=list)
    garbled: int = 0
    """Runs of bytes that failed the CRC or the framing."""
    probed: int = 0
    skipped: str | None = None

    @property
    def units(self) -> list[int]:
        """The units that answered, in order."""
        return sorted(answer.unit for answer in self.answers)


# -- argument parsing ----------------------------------------------------------------


def parse_units(text: str) -> list[int]:
    """Unit addresses from `"1-247"`, `"5"` or `"1,2,10-12"`, in order, once each.

    Raises `argparse.ArgumentTypeError` outside 1..247 or for a malformed list.
    """
    units: set[int] = set()
    for part in text.split(","):
        first, dash, last = part.strip().partition("-")
        try:
            low = int(first)
            high = int(last) if dash else low
        except ValueError:
            raise argparse.ArgumentTypeError(
                f"must be units 1-247 and ranges such as 1,2,10-12, not {text}"
            ) from None
        if not 1 <= low <= high <= 247:
            raise argparse.ArgumentTypeError(
                f"must be units 1-247, a range low to high, not {part.strip()}"
            )
        units.update(range(low, high + 1))
    return sorted(units)


def _baudrates(text: str) -> list[int]:
    rates: list[int] = []
    for part in text.split(","):
        try:
            rate = int(part)
        except ValueError:
            rate = 0
        if rate < 1:
            raise argparse.ArgumentTypeError(f"must be baud rates such as 9600,19200, not {part}")
        if rate not in rates:
            rates.append(rate)
    return rates


def _parities(text: str) -> list[Parity]:
    parities: list[Parity] = []
    for part in text.split(","):
        name = _PARITY_NAMES.get(part.strip().upper())
        if name is None:
            raise argparse.ArgumentTypeError(
                f"must be parities N, E or O (or none, even, odd), not {part}"
            )
        if Parity(name) not in parities:
            parities.append(Parity(name))
    return parities


def _timeout(text: str) -> float:
    try:
        value = float(text)
    except ValueError:
        value = math.nan
    if not 0 < value <= 60:
        raise argparse.ArgumentTypeError(
            f"must be a number of seconds, more than 0 and at most 60, not {text}"
        )
    return value


def settings_to_try(
    baudrates: Iterable[int], parities: Iterable[Parity], stopbits: int | None = None
) -> list[LineSettings]:
    """Every combination, baud rate by baud rate. Without `stopbits`, the spec's rule:
    2 stop bits with no parity, 1 with a parity bit (11 bits a character either way)."""
    return [
        LineSettings(
            rate,
            parity=parity,
            stopbits=stopbits if stopbits else (2 if parity is Parity.NONE else 1),
        )
        for rate in baudrates
        for parity in parities
    ]


def register(subparsers: Subparsers) -> None:
    """Add the `scan` subcommand to `subparsers`."""
    parser = subparsers.add_parser(
        "scan",
        help=SUMMARIES["scan"],
        description=(
            "Probe every unit at every line setting given, with a read of one holding "
            "register at address 0, and list the units that answer. Any reply counts, an "
            "exception reply included. Bad frames at a setting are reported as garbled "
            "traffic: a device is there, at other settings most likely. The port is "
            "opened once per setting. Progress goes to stderr, the results to stdout."
        ),
        epilog=_EXAMPLES,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    parser.add_argument("port", metavar="PORT", help="a serial device path or rtu+tcp://host:port")
    parser.add_argument(
        "--baudrates",
        type=_baudrates,
        default=list(DEFAULT_BAUDRATES),
        metavar="B,B,...",
        help=(
            "baud rates to try (19200,9600,38400,57600,115200; only the first on a "
            "pseudo-terminal, which ignores the baud rate)"
        ),
    )
    parser.add_argument(
        "--parities",
        type=_parities,
        default=None,
        metavar="P,P,...",
        help="parities to try, N, E and O (E,N,O; only N on a pseudo-terminal)",
    )
    parser.add_argument(
        "--stopbits",
        type=int,
        choices=(1, 2),
        default=None,
        help="stop bits (default: 2 with parity N, 1 with E or O, as the spec says)",
    )
    parser.add_argument(
        "--units", type=parse_units, default=list(UNIT_ADDRESSES), help="units to probe (1-247)"
    )
    parser.add_argument(
        "--timeout",
        type=_timeout,
        default=0.1,
        metavar="S",
        help="seconds to wait for each reply after the request has left the wire (0.1)",
    )
    parser.add_argument(
        "--first", action="store_true", help="stop after the first setting at which units answer"
    )
    parser.add_argument(
        "--local-echo",
        action="store_true",
        help="drop the echo of our own requests (adapters that hear themselves)",
    )
    parser.add_argument("-q", "--quiet", action="store_true", help="no progress on stderr")
    parser.add_argument(
        "--profile",
        action="append",
        dest="profiles",
        metavar="PROFILE",
        help="say which of these profiles (files or shipped names) each unit found matches",
    )
    parser.add_argument("--match", action="store_true", help="--profile with every shipped one")
    parser.set_defaults(run=run)


# -- probing -------------------------------------------------------------------------


def _describe(pdu: bytes) -> str:
    """What a reply to the probe said, in a few words."""
    try:
        reply = decode_response(pdu)
    except ModbusError as error:
        return f"a malformed reply ({error})"
    if isinstance(reply, ExceptionPDU):
        code = reply.exception_code
        name = code.name if isinstance(code, ExceptionCode) else "not in the spec"
        return f"exception {int(code):02X} ({name}) to read holding register 0"
    if isinstance(reply, ReadHoldingRegistersResponse) and reply.values:
        value = reply.values[0]
        return f"holding register 0 (40001) = {value} (0x{value:04X})"
    return f"a reply with function code 0x{pdu[0]:02X}"


def _is_probe_reply(event: FrameReceived) -> bool:
    return event.pdu[:1] in (
        bytes((FunctionCode.READ_HOLDING_REGISTERS,)),
        bytes((FunctionCode.READ_HOLDING_REGISTERS | EXCEPTION_BIT,)),
    )


async def probe_units(
    stream: anyio.abc.ByteStream,
    settings: LineSettings,
    units: Sequence[int],
    *,
    timeout: float,
    on_probe: Callable[[int, SettingResult], object] | None = None,
) -> SettingResult:
    """Probe each of `units` on `stream` at `settings`; return who answered.

    `on_probe` is called after each unit with the unit and the result so far. The
    stream is closed on return. Raises [`ConnectionLost`][aiortu.errors.ConnectionLost] if the
    stream fails.
    """
    result = SettingResult(settings)
    probed: set[int] = set()
    found: set[int] = set()

    def note(event: object, waiting_for: int | None, sent: float) -> bool:
        """Record *event*; True if it is the reply of *waiting_for*."""
        if not isinstance(event, FrameReceived):
            result.garbled += 1
            return False
        if not _is_probe_reply(event):
            return False
        unit = event.unit
        if unit == waiting_for and unit not in found:
            found.add(unit)
            latency = event.end - sent
            result.answers.append(Answer(unit, settings, _describe(event.pdu), latency))
            return True
        if unit in probed and unit not in found:
            # A late reply to an earlier probe: the unit is there, just slow.
            found.add(unit)
            result.answers.append(Answer(unit, settings, _describe(event.pdu), None))
        return False

    async with Link(stream, settings, role=Role.MASTER) as link:
        for unit in units:
            while (event := link.receive_nowait()) is not None:
                note(event, None, 0.0)
            sent = await link.send(encode_frame(unit, _PROBE.encode()))
            probed.add(unit)
            with anyio.move_on_at(sent + timeout):
                while not note(await link.receive(), unit, sent):
                    pass
            result.probed += 1
            if on_probe is not None:
                on_probe(unit, result)
        # Give the last unit's late reply the same chance as the others'.
        with anyio.move_on_after(timeout):
            while True:
                note(await link.receive(), None, 0.0)
    return result


async def scan(
    port: str,
    settings: Sequence[LineSettings],
    units: Sequence[int],
    *,
    timeout: float,
    first: bool = False,
    on_setting: Callable[[LineSettings], object] | None = None,
    on_probe: Callable[[int, SettingResult], object] | None = None,
    on_result: Callable[[SettingResult], object] | None = None,
    **options: object,
) -> list[SettingResult]:
    """Probe `units` on `port` at each of `settings` in turn, opening the port for each.

    A setting the port refuses is skipped (`SettingResult.skipped`). With `first`,
    stop after the first setting at which a unit answered. `options` go to
    [`open_stream`][aiortu.transport.open_stream]. Raises [`PortError`][aiortu.errors.PortError] if
    the port cannot be opened at all, [`ConnectionLost`][aiortu.errors.ConnectionLost] if it fails.
    """
    results: list[SettingResult] = []
    for line in settings:
        if on_setting is not None:
            on_setting(line)
        try:
            stream = await open_stream(port, line, **options)
        except UnsupportedSettings as error:
            result = SettingResult(line, skipped=str(error))
        else:
            result = await probe_units(stream, line, units, timeout=timeout, on_probe=on_probe)
        results.append(result)
        if on_result is not None:
            on_result(result)
        if first and result.answers:
            break
    return results


# -- output --------------------------------------------------------------------------


class _Progress:
    """Progress on `err`: a bar redrawn in place on a terminal, else a line per setting."""

    def __init__(self, err: TextIO, total: int, *, quiet: bool) -> None:
        self.err = err
        self.total = max(1, total)
        self.done = 0
        self.quiet = quiet
        self.bar = not quiet and err.isatty()
        self.settings: LineSettings | None = None

    def setting(self, settings: LineSettings) -> None:
        self.settings = settings
        if not self.quiet and not self.bar:
            self.err.write(f"aiortu scan: probing at {settings}\n")
            self.err.flush()

    def probe(self, unit: int, result: SettingResult) -> None:
        self.done += 1
        if not self.bar:
            return
        width = 30
        filled = width * self.done // self.total
        bar = "#" * filled + "." * (width - filled)
        text = (
            f"\r[{bar}] {100 * self.done // self.total:3d}%  {result.settings}  unit {unit:>3}"
            f"  found {len(result.answers)}"
        )
        self.err.write(text + "\x1b[K")
        self.err.flush()

    def interrupted(self) -> None:
        if self.bar:
            self.err.write("\r\x1b[K")
        self.err.write("aiortu scan: interrupted; the units found so far:\n")
        self.err.flush()

    def result(self, result: SettingResult, units: int) -> None:
        if result.skipped is not None:
            # The probes of a refused setting count as done.
            self.done += units
        if self.quiet:
            if result.skipped is not None:
                self.err.write(f"aiortu scan: {result.settings} skipped: {result.skipped}\n")
            return
        if self.bar:
            self.err.write("\r\x1b[K")
        if result.skipped is not None:
            line = f"skipped: {result.skipped}"
        else:
            found = ", ".join(map(str, result.units)) or "none"
            line = f"units answering: {found}"
            if result.garbled:
                line += f"; {result.garbled} garbled frames"
        self.err.write(f"aiortu scan: {result.settings}: {line}\n")
        self.err.flush()


def _order(settings: LineSettings) -> tuple[int, str, float]:
    """Line settings in the order people read them: by baud rate as a number."""
    return settings.baudrate, str(settings.parity), settings.stopbits


def report(results: Sequence[SettingResult], out: TextIO) -> bool:
    """Write what `results` found to `out`; return whether any unit answered."""
    answers = [answer for result in results for answer in result.answers]
    if answers:
        out.write(f"{'unit':>4}  {'settings':<11} {'reply':>8}  answer\n")
        for answer in sorted(answers, key=lambda a: (a.unit, _order(a.settings))):
            latency = "late" if answer.latency is None else f"{answer.latency * 1000:.1f} ms"
            out.write(f"{answer.unit:>4}  {answer.settings!s:<11} {latency:>8}  {answer.answer}\n")
    garbled = [r for r in results if r.garbled and not r.answers]
    for result in garbled:
        out.write(
            f"traffic but garbled at {result.settings}: {result.garbled} bad frames,"
            " no valid reply (wrong line settings likely)\n"
        )
    units = sorted({answer.unit for answer in answers})
    if units:
        where = ", ".join(str(s) for s in sorted({a.settings for a in answers}, key=_order))
        found = plural(len(units), "unit")
        out.write(f"found {found} ({', '.join(map(str, units))}) at {where}\n")
    else:
        tried = [r for r in results if r.skipped is None]
        out.write(f"no unit answered at {plural(len(tried), 'line setting')}\n")
    out.flush()
    return bool(units)


def run(args: argparse.Namespace) -> int:
    """Scan the port described by `args`; return the exit code (0 found, 1 nothing, 2 a
    profile to match that cannot be opened, said before the scan)."""
    profiles: list[Profile] = []
    if args.profiles or args.match:
        from aiortu.cli._profile import open_profiles

        try:
            profiles = open_profiles(args.profiles or [])
        except ConfigError as error:
            print(f"aiortu scan: error: {error}", file=sys.stderr)
            return 2
    return anyio.run(_scan, args, profiles)


async def _scan(args: argparse.Namespace, profiles: list[Profile]) -> int:
    _check_port_exists(args.port)
    pty = is_pty(args.port)
    parities = args.parities
    if parities is None:
        # A pty keeps no parity bit: E and O would only be refused.
        parities = [Parity.NONE] if pty else list(DEFAULT_PARITIES)
    baudrates: list[int] = args.baudrates
    if pty and len(baudrates) > 1:
        # A pty carries bytes at once whatever its baud rate: every rate would find the
        # same units again.
        baudrates = baudrates[:1]
        if not args.quiet:
            sys.stderr.write(
                f"aiortu scan: {args.port} is a pseudo-terminal, which ignores the baud rate:"
                f" probing once, at {baudrates[0]}\n"
            )
    settings = settings_to_try(baudrates, parities, args.stopbits)
    units: list[int] = args.units
    progress = _Progress(sys.stderr, len(settings) * len(units), quiet=args.quiet)
    if not args.quiet:
        # The slowest case: every probe waits its whole timeout.
        worst = len(settings) * len(units) * (args.timeout + 0.01)
        sys.stderr.write(
            f"aiortu scan: {plural(len(units), 'unit')} at"
            f" {plural(len(settings), 'line setting')} on {args.port};"
            f" at most {_duration(worst)}\n"
        )
    options = {"local_echo": True} if args.local_echo else {}
    # What was found so far, so that Ctrl-C still reports it.
    results: list[SettingResult] = []
    current: list[SettingResult] = []

    def on_result(result: SettingResult) -> None:
        results.append(result)
        current.clear()
        progress.result(result, len(units))

    def on_probe(unit: int, result: SettingResult) -> None:
        current[:] = [result]
        progress.probe(unit, result)

    interrupted: list[signal.Signals] = []
    failure: str | None = None
    with anyio.open_signal_receiver(signal.SIGINT, signal.SIGTERM) as signals:
        async with anyio.create_task_group() as group:
            group.start_soon(_cancel_on_signal, signals, group.cancel_scope, interrupted)
            try:
                await scan(
                    args.port, settings, units, timeout=args.timeout, first=args.first,
                    on_setting=progress.setting, on_probe=on_probe, on_result=on_result,
                    **options,
                )  # fmt: skip
            except PortError as error:
                failure = f"cannot open the port: {port_failure(error)}"
            except ConnectionLost as error:
                failure = str(error)
            group.cancel_scope.cancel()
    # Raised out here, not wrapped in the task group's ExceptionGroup.
    if failure is not None:
        raise CommandFailed(failure)
    if interrupted:
        progress.interrupted()
        report(results + current, sys.stdout)
        return 128 + interrupted[0]  # 130 for Ctrl-C, as a shell reports it
    if all(result.skipped is not None for result in results):
        raise CommandFailed(f"{args.port}: the port refused every line setting tried")
    if not report(results, sys.stdout):
        return 1
    if profiles:
        from aiortu.cli._profile import report_matches

        found = [(a.unit, a.settings) for r in results for a in r.answers]
        await report_matches(args.port, found, profiles, response_timeout=1.0, out=sys.stdout)
    return 0


def _check_port_exists(port: str) -> None:
    """A device path that does not exist fails the scan at once, before any promise of
    how long it will take."""
    if "://" in port or os.path.exists(port):
        return
    missing = PortNotFound(port, "no such serial device")
    raise CommandFailed(f"cannot open the port: {port_failure(missing)}")


async def _cancel_on_signal(
    signals: AsyncIterator[signal.Signals],
    scope: anyio.CancelScope,
    caught: list[signal.Signals],
) -> None:
    async for signum in signals:
        caught.append(signum)
        scope.cancel()
        return


def _duration(seconds: float) -> str:
    if seconds < 90:
        return f"{math.ceil(seconds)} s"
    return f"{math.ceil(seconds / 60)} min"

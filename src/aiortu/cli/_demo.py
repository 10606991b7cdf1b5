"""`aiortu demo`: three simulated devices on an in-memory bus, polled live.

Runs `Demo` (no ports, no hardware) and shows what the poller
reads: on a terminal, a table redrawn in place after every poll cycle; otherwise (a pipe,
a file) plain lines, a block a second plus one line per event. Stops after `--duration`
seconds, or at SIGINT (Ctrl-C) or SIGTERM, and exits 0.
"""

from __future__ import annotations

import argparse
import contextlib
import os
import re
import shutil
import signal
import sys
from collections.abc import AsyncIterator
from typing import TextIO

import anyio

from aiortu.cli import SUMMARIES, Subparsers
from aiortu.cli._arguments import plural, positive_int, seconds
from aiortu.cli._demo_system import Demo, DeviceView, ReadingView, Snapshot
from aiortu.core.model import Table

__all__ = ("PlainRenderer", "TableRenderer", "header_lines", "register", "run")

_EXAMPLES = """\
examples:
  aiortu demo
      run until Ctrl-C: a live table of three devices on a virtual bus at 19200 baud
  aiortu demo --duration 10 --baudrate 9600
      ten seconds at 9600 baud: the poll cycle takes about twice as long
  aiortu demo --duration 5 | cat
      plain lines instead of a table, as when the output is not a terminal

the devices (unit, what is simulated, where):
  1  energy meter            float32 in CDAB word order: voltage 30001, current 30007,
                             power 30013, energy 30343
  2  temperature controller  setpoint 40001 (int16, x10, writable), process value 30001
                             (x10), heater output 30002 (%)
  3  digital I/O module      coils 00001-00004, discrete inputs 10001-10004

exit codes:
  0  the duration passed, or stopped by SIGINT (Ctrl-C) or SIGTERM
  2  bad arguments
"""

_ANSI = re.compile(r"\x1b\[[0-9;?]*[A-Za-z]")
_HIDE_CURSOR = "\x1b[?25l"
_SHOW_CURSOR = "\x1b[?25h"


def register(subparsers: Subparsers) -> None:
    """Add the `demo` subcommand to `subparsers`."""
    parser = subparsers.add_parser(
        "demo",
        help=SUMMARIES["demo"],
        description=(
            "Start an in-memory RS-485 bus paced at the baud rate, with three simulated "
            "devices served by aiortu slaves (an energy meter, a temperature controller "
            "and a digital I/O module), poll their typed values with aiortu.Poller and "
            "show them live, with each unit's health and the poll cycle time. Partway "
            "through, the master writes a new setpoint and the process value follows it."
        ),
        epilog=_EXAMPLES,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    parser.add_argument(
        "--duration",
        type=seconds,
        default=None,
        metavar="SECONDS",
        help="stop after this many seconds (default: run until Ctrl-C)",
    )
    parser.add_argument(
        "--baudrate", type=positive_int, default=19200, help="the bus's baud rate (19200)"
    )
    parser.add_argument(
        "--interval",
        type=seconds,
        default=0.5,
        metavar="SECONDS",
        help="poll interval (0.5)",
    )
    parser.add_argument(
        "--seed", type=int, default=None, help="repeat the same simulated values on every run"
    )
    parser.set_defaults(run=run)


class _Symbols:
    """The characters the output can use: Unicode when the stream can encode it."""

    def __init__(self, out: TextIO) -> None:
        encoding = getattr(out, "encoding", None) or "ascii"
        try:
            "°↑↓·".encode(encoding)
            fancy = True
        except (UnicodeEncodeError, LookupError):
            fancy = False
        self.degree = "°C" if fancy else "degC"
        self.up = "↑" if fancy else "^"
        self.down = "↓" if fancy else "v"
        self.dot = "·" if fancy else "|"

    def trend(self, trend: int) -> str:
        return self.up if trend > 0 else self.down if trend < 0 else " "


def header_lines(demo: Demo, degree: str = "°C") -> list[str]:
    """The lines that say what is simulated and what the demo will do."""
    devices = demo.devices
    lines = [
        f"aiortu demo: {len(devices)} simulated Modbus RTU devices on an in-memory RS-485 bus"
        f" at {demo.settings}",
    ]
    lines += [f"  unit {d.unit}  {d.title:<23} {d.register_map}" for d in devices]
    points = len(demo.poller.points)
    reads = len(demo.poller.reads)
    plan = (
        f"aiortu.Poller reads {points} typed points in {reads} requests every {demo.interval:g} s"
    )
    if demo.first_change is not None:
        targets = " and ".join(f"{value:g} {degree}" for value in demo.setpoints)
        plan += f"; the master writes setpoint {targets} from {demo.first_change:g} s"
        if demo.change_every is not None:
            plan += f", every {demo.change_every:g} s"
    lines.append(plan + ".")
    return lines


def _value_text(view: ReadingView) -> tuple[str, str]:
    """The number (or on/off) and the unit of measure of `view`, apart."""
    reading = view.reading
    if view.value is None:
        return "-", reading.unit_of_measure
    if isinstance(view.value, bool):
        return ("on" if view.value else "off"), ""
    if isinstance(view.value, float):
        return f"{view.value:.{reading.digits}f}", reading.unit_of_measure
    return str(view.value), reading.unit_of_measure


def _health_text(device: DeviceView, separator: str) -> tuple[str, bool]:
    """A short health summary of `device`, parts joined by `separator`, and whether it is
    online."""
    health, stats = device.health, device.stats
    # The poller's states: online, suspect (a read failed lately), OFFLINE (probed only).
    state = health.state.value
    parts = [state if health.online else state.upper()]
    if health.last_latency is not None:
        parts.append(f"{health.last_latency * 1000:.1f} ms")
    parts.append(f"{stats.successes} ok")
    if stats.failures:
        parts.append(f"{stats.failures} failed")
    return separator.join(parts), health.online


def _cycle_text(snapshot: Snapshot) -> str:
    stats = snapshot.cycle_time
    if stats.last is None or stats.mean is None or stats.longest is None:
        return f"poll cycle: waiting for the first ({snapshot.reads_per_cycle} reads)"
    return (
        f"poll cycle {stats.last * 1000:.1f} ms (mean {stats.mean * 1000:.1f},"
        f" longest {stats.longest * 1000:.1f}) for {snapshot.reads_per_cycle} reads;"
        f" {plural(snapshot.cycle, 'cycle')}"
    )


class TableRenderer:
    """Draws snapshots as a table on a terminal, redrawing it in place each time.

    `color` adds ANSI colours (bold names, green online, red offline); `symbols` choose
    Unicode or ASCII. `close` shows the cursor again.
    """

    def __init__(self, out: TextIO, *, color: bool = True) -> None:
        self.out = out
        self.color = color
        self.symbols = _Symbols(out)
        self._drawn = 0

    def _style(self, text: str, code: str) -> str:
        return f"\x1b[{code}m{text}\x1b[0m" if self.color else text

    def lines(self, snapshot: Snapshot) -> list[str]:
        """The table for `snapshot`, one string per line, styled."""
        symbols = self.symbols
        title = f"  {snapshot.elapsed:6.1f} s   {_cycle_text(snapshot)}"
        out = [self._style(title, "1"), ""]
        for device in snapshot.devices:
            health, online = _health_text(device, f" {symbols.dot} ")
            name = f"unit {device.unit}  {device.title}"
            state = self._style(health, "32" if online else "31;1")
            out.append(f"  {self._style(f'{name:<38}', '1')} {state}")
            bits: dict[Table, list[ReadingView]] = {}
            for view in device.readings:
                table = view.reading.point.table
                if table.is_bit:
                    bits.setdefault(table, []).append(view)
                    continue
                number, uom = _value_text(view)
                arrow = symbols.trend(view.trend)
                stale = self._style(" (stale)", "33") if view.error else ""
                out.append(
                    f"          {view.reading.label:<15}{number:>10} {uom:<4} {arrow}{stale}"
                )
            for table, views in bits.items():
                label = "outputs" if table is Table.COILS else "inputs"
                states = "   ".join(
                    f"{v.reading.label} {self._style('on', '32') if v.value else 'off'}"
                    for v in views
                )
                out.append(f"          {label:<15}{states}")
        out.append("")
        if snapshot.next_change is not None:
            due = max(0.0, snapshot.next_change - snapshot.elapsed)
            out.append(f"  next setpoint change in {due:.0f} s")
        out.append(self._style("  events", "1"))
        if not snapshot.events:
            out.append("    (none yet)")
        out += [f"    {event.time:6.1f} s  {event.text}" for event in snapshot.events]
        out.append(self._style("  Ctrl-C to stop", "2"))
        return out

    def draw(self, snapshot: Snapshot) -> None:
        """Replace the table drawn last with the one for `snapshot`."""
        width = shutil.get_terminal_size((100, 24)).columns
        lines = [self._fit(line, width) for line in self.lines(snapshot)]
        parts = []
        if self._drawn == 0:
            parts.append(_HIDE_CURSOR)
        else:
            # Up to the first line of the last table, then clear to the end of the screen.
            parts.append(f"\x1b[{self._drawn}F\x1b[J")
        parts.append("\n".join(lines) + "\n")
        self.out.write("".join(parts))
        self.out.flush()
        self._drawn = len(lines)

    def _fit(self, line: str, width: int) -> str:
        # A line that wraps would take two rows and throw off the redraw.
        plain = _ANSI.sub("", line)
        if len(plain) < width:
            return line
        return plain[: max(1, width - 1)]

    def close(self) -> None:
        """Show the cursor again."""
        self.out.write(_SHOW_CURSOR)
        self.out.flush()


class PlainRenderer:
    """Writes snapshots as plain lines: a block of values every `every` poll cycles (and
    the first), and each event as it comes."""

    def __init__(self, out: TextIO, *, every: int = 2) -> None:
        self.out = out
        self.every = every
        self._events_seen = 0

    def lines(self, snapshot: Snapshot, *, block: bool = True) -> list[str]:
        """The lines for `snapshot`: its new events, and with `block` every device's values."""
        stamp = f"[{snapshot.elapsed:7.1f} s]"
        out: list[str] = []
        if block:
            for device in snapshot.devices:
                values = ", ".join(
                    f"{view.reading.label} {' '.join(filter(None, _value_text(view)))}"
                    for view in device.readings
                )
                health, _ = _health_text(device, ", ")
                out.append(f"{stamp} unit {device.unit} {device.title}: {values} ({health})")
            out.append(f"{stamp} {_cycle_text(snapshot)}")
        new = snapshot.event_count - self._events_seen
        if new > 0:
            out += [f"[{e.time:7.1f} s] {e.text}" for e in snapshot.events[-new:]]
        self._events_seen = snapshot.event_count
        return out

    def draw(self, snapshot: Snapshot) -> None:
        """Write what is due for `snapshot`."""
        lines = self.lines(snapshot, block=snapshot.cycle % self.every == 1 % self.every)
        if lines:
            self.out.write("\n".join(lines) + "\n")
            self.out.flush()

    def finish(self, snapshot: Snapshot) -> None:
        """Write the last values and any events not written yet."""
        self.out.write("\n".join(self.lines(snapshot)) + "\n")
        self.out.flush()

    def close(self) -> None:
        """Nothing to restore for plain lines."""


def run(args: argparse.Namespace) -> int:
    """Run the demo described by `args`; return the exit code."""
    return anyio.run(_demo, args)


def _first_change(duration: float | None) -> float:
    # A short run still has to show the new setpoint taking effect.
    return 4.0 if duration is None else min(4.0, duration * 0.3)


async def _demo(args: argparse.Namespace) -> int:
    out = sys.stdout
    tty = out.isatty()
    symbols = _Symbols(out)
    demo = Demo(
        baudrate=args.baudrate,
        interval=args.interval,
        first_change=_first_change(args.duration),
        seed=args.seed,
        degree=symbols.degree,
    )
    renderer: TableRenderer | PlainRenderer
    if tty:
        renderer = TableRenderer(out, color="NO_COLOR" not in os.environ)
    else:
        # About a block a second, whatever the interval.
        renderer = PlainRenderer(out, every=max(1, round(1.0 / args.interval)))
    with anyio.open_signal_receiver(signal.SIGINT, signal.SIGTERM) as signals:
        try:
            out.write("\n".join(header_lines(demo, symbols.degree)) + "\n\n")
            out.flush()
            reader_gone = False
            async with demo, anyio.create_task_group() as group:
                group.start_soon(_stop_on_signal, signals, group.cancel_scope)
                with anyio.move_on_after(args.duration if args.duration else float("inf")):
                    while True:
                        snapshot = await demo.next_snapshot()
                        # Caught here, not outside: the task groups would wrap it.
                        try:
                            renderer.draw(snapshot)
                        except BrokenPipeError:
                            reader_gone = True
                            break
                group.cancel_scope.cancel()
            if reader_gone:
                raise BrokenPipeError
            final = demo.snapshot()
            if isinstance(renderer, PlainRenderer):
                renderer.finish(final)
            transactions = sum(device.stats.requests for device in final.devices)
            failures = sum(device.stats.failures for device in final.devices)
            out.write(
                f"demo stopped after {final.elapsed:.1f} s: {plural(final.cycle, 'poll cycle')},"
                f" {plural(transactions, 'transaction')}, {failures} failed\n"
            )
            out.flush()
        except BrokenPipeError:
            # The reader went away (``| head``): stop quietly, and keep Python from
            # complaining when it flushes stdout at exit.
            os.dup2(os.open(os.devnull, os.O_WRONLY), out.fileno())
        finally:
            if tty:
                # The cursor comes back however the demo ends.
                with contextlib.suppress(OSError):
                    renderer.close()
    return 0


async def _stop_on_signal(signals: AsyncIterator[signal.Signals], scope: anyio.CancelScope) -> None:
    async for _ in signals:
        scope.cancel()
        return

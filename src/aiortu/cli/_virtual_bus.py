"""`aiortu virtual-bus`: a virtual RS-485 bus of pseudo-terminals for other programs.

Prints one device path per port on stdout, one a line, as soon as the bus is up; then
relays until SIGINT or SIGTERM and exits 0.
"""

from __future__ import annotations

import argparse
import signal
import sys

import anyio

from aiortu.cli import SUMMARIES, CommandFailed, Subparsers
from aiortu.cli._arguments import PTY_LINE, parity, positive_int, probability, seconds_or_zero
from aiortu.core.serial import LineSettings
from aiortu.errors import PortError
from aiortu.testing import FaultPlan, PtyBus

__all__ = ("register", "run")

_EXAMPLES = """\
examples:
  aiortu virtual-bus --ports 2
      two ports at 19200 8N2; prints e.g. /dev/pts/5 and /dev/pts/6
  aiortu virtual-bus --ports 3 --baudrate 9600 --link-dir /tmp/rtu
      a three-drop bus at 9600 8N2 with stable names /tmp/rtu/port0 .. port2
  aiortu virtual-bus --no-pacing --chunk-size 62 --latency 0.016
      no baud-rate pacing, delivery in chunks as through a USB adapter
  aiortu virtual-bus --bit-error-rate 1e-4 --gap-rate 0.001 --gap 0.01 --seed 7
      a noisy line, the same noise on every run with the same seed

ptys keep no parity bit, so the bus is 8N2 (the same 11 bits a character as the spec's
8E1), and aiortu's commands use 8N2 on a pty by default; other programs need it said:
  aiortu serve /dev/pts/6 --config examples/devices.toml
  aiortu read /dev/pts/5 --unit 17 --ref 40108 --count 3
  mbpoll -m rtu -a 17 -b 19200 -P none -s 2 -t 4 -r 108 -c 3 -1 /dev/pts/5

exit codes: 0 stopped by Ctrl-C (SIGINT) or SIGTERM; 1 the ptys cannot be created, or
another virtual bus keeps its links in --link-dir; 2 bad arguments
"""


def register(subparsers: Subparsers) -> None:
    """Add the `virtual-bus` subcommand to `subparsers`."""
    parser = subparsers.add_parser(
        "virtual-bus",
        help=SUMMARIES["virtual-bus"],
        description=(
            "Create a virtual multi-drop serial bus of pseudo-terminals. What a program "
            "writes to one port reaches the programs on all the other ports, at the "
            "character rate of the line settings. Prints one device path per line, then "
            "relays until interrupted (SIGINT or SIGTERM)."
        ),
        epilog=_EXAMPLES,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    parser.add_argument("--ports", type=positive_int, default=2, help="number of ports (2)")
    line = parser.add_argument_group("line settings (for pacing)")
    line.add_argument("--baudrate", type=positive_int, default=19200, help="baud rate (19200)")
    line.add_argument(
        "--parity",
        type=parity,
        default="N",
        metavar="N|E|O",
        help=f"N, E or O, or none, even, odd (N: ptys keep no parity; use {PTY_LINE})",
    )
    line.add_argument(
        "--stopbits",
        type=int,
        choices=(1, 2),
        default=None,
        help="stop bits (2 with parity N, else 1)",
    )
    line.add_argument(
        "--no-pacing", action="store_true", help="deliver at once, not at the character rate"
    )
    adapter = parser.add_argument_group("adapter model")
    adapter.add_argument(
        "--chunk-size", type=positive_int, default=None, help="at most this many bytes per read"
    )
    adapter.add_argument(
        "--latency",
        type=seconds_or_zero,
        default=0.0,
        help="hold received bytes this long (seconds)",
    )
    faults = parser.add_argument_group("faults")
    faults.add_argument(
        "--bit-error-rate", type=probability, default=0.0, metavar="R",
        help="probability that a data bit is flipped (0)",
    )  # fmt: skip
    faults.add_argument(
        "--drop-rate", type=probability, default=0.0, metavar="R",
        help="probability that a byte is lost, after taking its time on the wire (0)",
    )  # fmt: skip
    faults.add_argument(
        "--garbage-rate", type=probability, default=0.0, metavar="R",
        help="probability that random bytes are inserted into a write (0)",
    )  # fmt: skip
    faults.add_argument(
        "--gap-rate", type=probability, default=0.0, metavar="R",
        help="probability of a pause of --gap seconds after a byte (0)",
    )  # fmt: skip
    faults.add_argument(
        "--gap", type=seconds_or_zero, default=0.0, metavar="S",
        help="the length of those pauses in seconds (0; needed with --gap-rate)",
    )  # fmt: skip
    faults.add_argument("--seed", type=int, default=0, help="seed of the fault generator (0)")
    parser.add_argument(
        "--link-dir",
        default=None,
        metavar="DIR",
        help="make links DIR/port0, DIR/port1, ... (refused while another bus has DIR)",
    )
    parser.set_defaults(run=run)


def run(args: argparse.Namespace) -> int:
    """Run the bus described by `args` until SIGINT or SIGTERM; return the exit code."""
    if args.gap_rate > 0 and args.gap == 0:
        # Said here in the flags' names; the fault plan would name its fields.
        print("aiortu virtual-bus: error: --gap-rate needs --gap SECONDS, the length of each "
              "pause", file=sys.stderr)  # fmt: skip
        return 2
    settings = (
        None
        if args.no_pacing
        else LineSettings(
            args.baudrate,
            parity=args.parity,
            stopbits=args.stopbits or (2 if args.parity == "N" else 1),
        )
    )
    plan = FaultPlan(
        bit_error_rate=args.bit_error_rate,
        drop_rate=args.drop_rate,
        garbage_rate=args.garbage_rate,
        gap_rate=args.gap_rate,
        gap=args.gap,
        seed=args.seed,
    )
    bus = PtyBus(
        args.ports,
        settings=settings,
        chunk_size=args.chunk_size,
        latency=args.latency,
        faults=None if plan.is_clean else plan,
        link_dir=args.link_dir,
    )
    try:
        return anyio.run(_relay, bus)
    except PortError as exc:
        raise CommandFailed(str(exc)) from exc
    except OSError as exc:
        raise CommandFailed(f"cannot create the bus: {exc}") from exc


async def _relay(bus: PtyBus) -> int:
    # The handlers go in before the paths are printed: whoever reads the paths may signal
    # at once.
    with anyio.open_signal_receiver(signal.SIGINT, signal.SIGTERM) as signals:
        async with bus:
            sys.stdout.write("".join(f"{device}\n" for device in bus.devices))
            sys.stdout.flush()
            async for _ in signals:
                break
    return 0

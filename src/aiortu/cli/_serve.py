"""``aiortu serve``: simulate the devices a TOML file describes on a serial port.

Reads the description (see :mod:`aiortu.slave._config`), opens the port, and serves the
units until SIGINT or SIGTERM (exit 0). A bad file is one line on stderr naming the file,
the key and the problem (exit 2); a port that cannot be opened is one line (exit 1).
``--trace`` logs every frame on stderr, in hex, with its meaning.
"""

from __future__ import annotations

import argparse
import signal
import sys
import time
from collections.abc import Mapping

import anyio

from aiortu.cli import CommandFailed, Subparsers
from aiortu.cli._arguments import seconds_or_zero
from aiortu.core.bus_decoder import describe_frame
from aiortu.core.frame import encode_frame
from aiortu.errors import PortError
from aiortu.slave._config import ConfigError, load_config
from aiortu.slave._server import serve
from aiortu.slave._store import MemoryStore

__all__ = ("register", "run")

_EXAMPLES = """\
examples:
  aiortu serve /dev/ttyUSB0 --config examples/devices.toml
      serve the units of the file at 19200 8E1
  aiortu serve /dev/pts/5 --config devices.toml --parity N --stopbits 2 --trace
      8N2 (as on a pty bus), logging every frame with its meaning
  aiortu serve rtu+tcp://10.0.0.7:4001 --config devices.toml --frame-gap 0
      behind a serial device server, no silence kept before replies
  aiortu serve tcp://0.0.0.0:1502 --config devices.toml
      Modbus TCP on every interface, many clients at once
  aiortu serve rtu+tcp://0.0.0.0:5020 --config devices.toml
      RTU framing over TCP, listening (a wildcard host listens, any other connects)

several processes can share one bus, each with its own units:
  aiortu virtual-bus --ports 3 --parity N --stopbits 2     # prints three paths
  aiortu serve /dev/pts/6 --config meters.toml --parity N --stopbits 2
  aiortu serve /dev/pts/7 --config valves.toml --parity N --stopbits 2
  mbpoll -m rtu -a 17 -b 19200 -P none -s 2 -t 4 -r 1 -c 3 -1 /dev/pts/5

exit codes: 0 stopped by Ctrl-C (SIGINT) or SIGTERM; 1 the port cannot be opened or
failed; 2 bad arguments or a bad configuration file (one line naming file, key, problem)
"""


def register(subparsers: Subparsers) -> None:
    """Add the ``serve`` subcommand to *subparsers*."""
    parser = subparsers.add_parser(
        "serve",
        help="simulate Modbus RTU devices described in a TOML file",
        description=(
            "Serve the units a TOML device description defines (tables, read-only ranges, "
            "FIFOs, files, device identification, server id) on a serial port or an "
            "rtu+tcp:// URL, or listening for Modbus TCP on a tcp:// URL, until interrupted "
            "(SIGINT or SIGTERM). See docs/slave.md."
        ),
        epilog=_EXAMPLES,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    parser.add_argument(
        "port",
        metavar="PORT",
        help="serial device path, rtu+tcp://host:port, or tcp://host:port to listen on",
    )
    parser.add_argument(
        "--config", required=True, metavar="FILE.toml", help="the device description"
    )
    line = parser.add_argument_group("line settings")
    line.add_argument("--baudrate", type=int, default=19200, help="baud rate (19200)")
    line.add_argument("--parity", choices=("N", "E", "O"), default="E", help="parity (E)")
    line.add_argument("--stopbits", type=int, choices=(1, 2), default=1, help="stop bits (1)")
    line.add_argument(
        "--frame-gap",
        type=seconds_or_zero,
        default=None,
        metavar="SECONDS",
        help="silence kept before each reply (t3.5 of the line settings)",
    )
    parser.add_argument(
        "--trace", action="store_true", help="log every frame on stderr, in hex, with its meaning"
    )
    parser.set_defaults(run=run)


def run(args: argparse.Namespace) -> int:
    """Serve until SIGINT or SIGTERM; return the exit code."""
    try:
        config = load_config(args.config)
    except ConfigError as error:
        print(f"aiortu serve: error: {error}", file=sys.stderr)
        return 2
    return anyio.run(_serve, args, config.units)


def _trace_mbap(kind: str, data: bytes) -> None:
    # A Modbus TCP ADU, with the meaning of the same request as an RTU frame.
    _trace(kind, data, encode_frame(data[6], data[7:]))


def _trace(kind: str, data: bytes, frame: bytes | None = None) -> None:
    stamp = time.strftime("%H:%M:%S")
    if kind == "discarded":
        meaning = f"discarded {len(data)} bytes"
    else:
        direction = "reply" if kind == "sent" else None
        meaning = describe_frame(data if frame is None else frame, direction=direction)
    arrow = {"received": "<-", "sent": "->"}.get(kind, "xx")
    sys.stderr.write(f"{stamp} {arrow} {data.hex(' ')}  {meaning}\n")
    sys.stderr.flush()


async def _serve(args: argparse.Namespace, units: Mapping[int, MemoryStore]) -> int:
    # The handlers go in before the port opens: a supervisor may signal at once.
    with anyio.open_signal_receiver(signal.SIGINT, signal.SIGTERM) as signals:
        try:
            async with serve(
                args.port,
                units,
                baudrate=args.baudrate,
                parity=args.parity,
                stopbits=args.stopbits,
                frame_gap=args.frame_gap,
                trace=(_trace_mbap if args.port.lower().startswith("tcp:") else _trace)
                if args.trace
                else None,
            ) as slave:
                listing = ", ".join(str(unit) for unit in sorted(units))
                where = args.port
                local = getattr(slave, "local_address", None)
                if local is not None:  # listening: say the port, which may have been 0
                    where = f"{args.port} (port {local[1]})"
                sys.stderr.write(f"aiortu serve: units {listing} on {where}\n")
                sys.stderr.flush()
                async with anyio.create_task_group() as group:

                    async def stop_on_signal() -> None:
                        async for _ in signals:
                            break
                        group.cancel_scope.cancel()

                    async def stop_on_failure() -> None:
                        await slave.wait_stopped()
                        group.cancel_scope.cancel()

                    group.start_soon(stop_on_signal)
                    group.start_soon(stop_on_failure)
                if slave.connection_error is not None:
                    raise CommandFailed(f"the line failed: {slave.connection_error}")
        except PortError as error:
            raise CommandFailed(str(error)) from error
    return 0

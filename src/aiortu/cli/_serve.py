"""`aiortu serve`: simulate the devices a TOML file describes on a serial port.

Reads the description (see [`aiortu.slave`][aiortu.slave]), opens the port, and serves the
units until SIGINT or SIGTERM (exit 0). A bad file is one line on stderr naming the file,
the key and the problem (exit 2); a port that cannot be opened is one line (exit 1).
When the port disappears under it (a USB adapter unplugged), `serve` says so on stderr
and reopens it, with the same stores, until it is back; with `--no-reconnect` it exits 1.
`--trace` logs every frame on stderr, in hex, with its meaning.
"""

from __future__ import annotations

import argparse
import os
import signal
import sys
import time
from collections.abc import Mapping
from typing import Any

import anyio

from aiortu.cli import SUMMARIES, CommandFailed, Subparsers
from aiortu.cli._arguments import (
    add_frame_gap,
    add_line_settings,
    add_no_reconnect,
    add_timing,
    resolve_line_settings,
)
from aiortu.cli._messages import invalid_value, library_warnings_on_stderr, port_failure
from aiortu.cli._transport_options import (
    add_transport_options,
    misplaced_option,
    transport_options,
)
from aiortu.core.codes import UNIT_ADDRESSES
from aiortu.core.pdu import Request, decode_request
from aiortu.core.rtu import describe_frame, encode_frame
from aiortu.errors import ConnectionLost, InvalidValue, ModbusError, PortError
from aiortu.slave import ConfigError, MemoryStore, load_config, serve

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
  aiortu serve tcp://0.0.0.0:1502 --config devices.toml --serial-line-codes \\
                                  --unit-alias 255=17 --unit-alias 0=17
      the same, answering the server id (11) and the other serial-line codes, and
      unit ids 255 and 0 as unit 17
  aiortu serve rtu+tcp://0.0.0.0:5020 --config devices.toml
      RTU framing over TCP, listening (a wildcard host listens, any other connects)
  aiortu serve ascii+tcp://0.0.0.0:5021 --config devices.toml
      Modbus ASCII over TCP, listening, for serial device servers that connect in

several processes can share one bus, each with its own units:
  aiortu virtual-bus --ports 3 --parity N --stopbits 2     # prints three paths
  aiortu serve /dev/pts/6 --config meters.toml --parity N --stopbits 2
  aiortu serve /dev/pts/7 --config valves.toml --parity N --stopbits 2
  mbpoll -m rtu -a 17 -b 19200 -P none -s 2 -t 4 -r 1 -c 3 -1 /dev/pts/5

on a pseudo-terminal (such as aiortu virtual-bus makes) the line is 8N2 unless
--parity says otherwise: ptys keep no parity bit

exit codes: 0 stopped by Ctrl-C (SIGINT) or SIGTERM; 1 the port cannot be opened, or it
failed with --no-reconnect; 2 bad arguments or a bad configuration file (one line naming
file, key, problem)
"""


def register(subparsers: Subparsers) -> None:
    """Add the `serve` subcommand to `subparsers`."""
    parser = subparsers.add_parser(
        "serve",
        help=SUMMARIES["serve"],
        description=(
            "Serve the units a TOML device description defines (tables, read-only ranges, "
            "FIFOs, files, device identification, server id), or a device profile, on a "
            "serial port or an rtu+tcp:// or ascii+tcp:// URL, or listening on a tcp:// "
            "(Modbus TCP), udp:// (Modbus UDP) or tls:// (Modbus/TCP Security) URL, until "
            "interrupted (SIGINT or SIGTERM). See docs/slave.md."
        ),
        epilog=_EXAMPLES,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    parser.add_argument(
        "port",
        metavar="PORT",
        help="serial device path, rtu+tcp://host:port or ascii+tcp://host:port, or "
        "tcp://, udp:// or tls://host:port to listen on",
    )
    add_transport_options(parser, server=True)
    parser.add_argument("--config", metavar="FILE.toml", help="the device description")
    parser.add_argument(
        "--profile", metavar="PROFILE", help="serve a device profile instead (file or shipped name)"
    )
    parser.add_argument("--unit", type=int, default=1, help="the unit of --profile (1)")
    parser.add_argument(
        "--move",
        type=float,
        default=None,
        metavar="SECONDS",
        help="with --profile: move the measurements (float points) every SECONDS",
    )
    line = parser.add_argument_group("line settings")
    add_line_settings(line)
    add_frame_gap(line, before="reply")
    add_timing(line)
    tcp = parser.add_argument_group("Modbus TCP (tcp://, udp:// and tls:// only)")
    tcp.add_argument(
        "--serial-line-codes",
        action="store_true",
        help=(
            "answer the serial-line-only codes 07, 08, 0B, 0C and 11 (server id) as a serial "
            "device would; without it they get exception 01, as the spec marks them (also "
            "serial_line_codes in the file's [modbus_tcp] table)"
        ),
    )
    tcp.add_argument(
        "--unit-alias",
        type=unit_alias,
        action="append",
        default=[],
        metavar="ID=UNIT",
        help=(
            "answer unit id ID (0..255) as the served UNIT; repeat for several, added to "
            "the file's [modbus_tcp] unit_aliases (default, with one unit: 0 and 255 are it)"
        ),
    )
    parser.add_argument(
        "--trace", action="store_true", help="log every frame on stderr, in hex, with its meaning"
    )
    add_no_reconnect(parser)
    parser.set_defaults(run=run)


def run(args: argparse.Namespace) -> int:
    """Serve until SIGINT or SIGTERM; return the exit code."""
    if (args.config is None) == (args.profile is None):
        print("aiortu serve: error: give --config or --profile (one of them)", file=sys.stderr)
        return 2
    misplaced = misplaced_option(args)
    if misplaced is not None:
        print(f"aiortu serve: error: {misplaced}", file=sys.stderr)
        return 2
    if args.profile is not None:
        from aiortu.cli._profile import serve_profile

        return serve_profile(args, _serve)
    if not os.path.isfile(args.config):
        problem = (
            "is a directory, not a TOML file" if os.path.isdir(args.config) else "does not exist"
        )
        print(f"aiortu serve: error: --config {args.config} {problem}", file=sys.stderr)
        return 2
    try:
        config = load_config(args.config)
    except ConfigError as error:
        print(f"aiortu serve: error: {error}", file=sys.stderr)
        return 2
    if _tcp_options(args) and not _mbap(args.port):
        given = "--serial-line-codes" if args.serial_line_codes else "--unit-alias"
        print(
            f"aiortu serve: error: {given} is for a Modbus TCP server (tcp://, udp://, tls://): "
            "a serial line serves every code and has no unit ids but its units",
            file=sys.stderr,
        )
        return 2
    unknown = sorted({unit for _, unit in args.unit_alias} - set(config.units))
    if unknown:
        print(
            f"aiortu serve: error: --unit-alias names unit {unknown[0]}, which {args.config} "
            f"does not describe (it has {', '.join(map(str, sorted(config.units)))})",
            file=sys.stderr,
        )
        return 2
    args.modbus_tcp = config.modbus_tcp
    resolve_line_settings(args)
    with library_warnings_on_stderr("serve"):
        return anyio.run(_serve, args, config.units)


class Tracer:
    """Writes each frame the slave sees or sends on stderr, a reply described with the
    request it answers (so that a read of 3 coils shows 3, not the 8 of its byte).

    With `mbap`, what it sees are Modbus TCP ADUs: each is shown as it came, with the
    meaning of the same request or reply as an RTU frame."""

    def __init__(self, *, mbap: bool = False) -> None:
        self.request: Request | None = None
        self.mbap = mbap

    def __call__(self, kind: str, data: bytes) -> None:
        now = time.time()
        stamp = time.strftime("%H:%M:%S", time.localtime(now)) + f".{int(now * 1000) % 1000:03d}"
        frame = encode_frame(data[6], data[7:]) if self.mbap and kind != "discarded" else data
        if kind == "discarded":
            meaning = f"discarded {len(data)} bytes"
        elif kind == "sent":
            meaning = describe_frame(frame, direction="reply", request=self.request)
        else:
            meaning = describe_frame(frame, direction="request")
            try:
                self.request = decode_request(frame[1:-2])
            except ModbusError:
                self.request = None
        arrow = {"received": "<-", "sent": "->"}.get(kind, "xx")
        sys.stderr.write(f"{stamp} {arrow} {data.hex(' ')}  {meaning}\n")
        sys.stderr.flush()


async def _serve(args: argparse.Namespace, units: Mapping[int, MemoryStore]) -> int:
    # The handlers go in before the port opens: a supervisor may signal at once.
    failure: CommandFailed | None = None
    with anyio.open_signal_receiver(signal.SIGINT, signal.SIGTERM) as signals:
        async with anyio.create_task_group() as group:

            async def stop_on_signal() -> None:
                async for _ in signals:
                    break
                group.cancel_scope.cancel()

            group.start_soon(stop_on_signal)
            try:
                await _serve_until_stopped(args, units)
            except CommandFailed as error:
                failure = error
            group.cancel_scope.cancel()
    # Raised out here, not wrapped in the task group's ExceptionGroup.
    if failure is not None:
        raise failure
    return 0


async def _serve_until_stopped(args: argparse.Namespace, units: Mapping[int, MemoryStore]) -> None:
    """Serve; after the line fails, reopen the port (backing off) unless told not to."""
    tracer = Tracer(mbap=args.port.lower()[:4] in ("tcp:", "udp:", "tls:")) if args.trace else None
    backoff = _Backoff()
    opened = False
    while True:
        try:
            error = await _serve_once(args, units, tracer)
        except (InvalidValue, ConfigError) as failure:  # a TLS file or rule file, say
            shown = invalid_value(failure) if isinstance(failure, InvalidValue) else failure
            raise CommandFailed(f"error: {shown}", exit_code=2) from failure
        except PortError as failure:
            # The port must open the first time; once served, it may be gone a while.
            if not opened:
                raise CommandFailed(port_failure(failure)) from failure
            await backoff.wait()
            continue
        opened = True
        if not args.reconnect:
            raise CommandFailed(str(error))
        _say(f"{error}; reopening {args.port}")
        backoff.reset()
        await backoff.wait()


async def _serve_once(
    args: argparse.Namespace, units: Mapping[int, MemoryStore], tracer: Tracer | None
) -> ConnectionLost:
    """Open the port and serve on it until the line fails; return why it failed."""
    async with serve(
        args.port,
        units,
        baudrate=args.baudrate,
        bytesize=args.bytesize,
        parity=args.parity,
        stopbits=args.stopbits,
        frame_gap=args.frame_gap,
        timing=args.timing,
        trace=tracer,
        **transport_options(args),
        **_modbus_tcp_settings(args),
    ) as slave:
        listing = ", ".join(str(unit) for unit in sorted(units))
        which = "unit" if len(units) == 1 else "units"
        local = getattr(slave, "local_address", None)
        if local is not None:  # listening: say the port, which may have been 0
            where = f"{args.port} (port {local[1]})"
        else:
            where = f"{args.port} at {args.baudrate} {args.bytesize}{args.parity}{args.stopbits}"
        _say(f"{which} {listing} on {where}; Ctrl-C to stop")
        await slave.wait_stopped()
    error = slave.connection_error
    if isinstance(error, ConnectionLost):
        return error
    # A listener that stopped: say why in the same terms as a line that failed.
    return ConnectionLost("the line closed" if error is None else str(error))


def unit_alias(text: str) -> tuple[int, int]:
    """`ID=UNIT`: a unit id 0..255 answered as the served unit UNIT (1..247)."""
    alias, equals, unit = text.partition("=")
    try:
        pair = int(alias, 0), int(unit, 0)
    except ValueError:
        pair = (-1, -1)
    if not equals or pair[0] not in range(256) or pair[1] not in UNIT_ADDRESSES:
        raise argparse.ArgumentTypeError(
            f"must be ID=UNIT, a unit id 0..255 and a served unit 1..247 (255=17), not {text}"
        )
    return pair


def _mbap(port: str) -> bool:
    """Whether `port` is served by a Modbus TCP server (MBAP framing: TCP, UDP or TLS)."""
    return port.strip().lower().startswith(("tcp://", "udp://", "tls://"))


def _tcp_options(args: argparse.Namespace) -> dict[str, Any]:
    """What `--serial-line-codes` and `--unit-alias` ask of the Modbus TCP server."""
    options: dict[str, Any] = {}
    if args.serial_line_codes:
        options["serial_line_codes"] = True
    if args.unit_alias:
        options["unit_aliases"] = dict(args.unit_alias)
    return options


def _modbus_tcp_settings(args: argparse.Namespace) -> dict[str, Any]:
    """The Modbus TCP server's settings: the file's `[modbus_tcp]` table, then the flags
    (a flag wins, and `--unit-alias` adds to the file's aliases); none for another port."""
    if not _mbap(args.port):
        return {}
    settings = dict(getattr(args, "modbus_tcp", {}))
    flags = _tcp_options(args)
    if "unit_aliases" in flags:
        flags["unit_aliases"] = {**settings.get("unit_aliases", {}), **flags["unit_aliases"]}
    return {**settings, **flags}


def _say(message: str) -> None:
    sys.stderr.write(f"aiortu serve: {message}\n")
    sys.stderr.flush()


class _Backoff:
    """Seconds to wait before reopening the port: 0.1 doubling up to 5."""

    def __init__(self) -> None:
        self.delay = 0.1

    def reset(self) -> None:
        self.delay = 0.1

    async def wait(self) -> None:
        await anyio.sleep(self.delay)
        self.delay = min(2 * self.delay, 5.0)

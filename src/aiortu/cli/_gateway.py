"""`aiortu gateway`: share one serial line with Modbus TCP clients (the line server).

Opens the serial port, listens on each `--listen` URL and forwards every client's requests
through the one master of the line (see [`aiortu.gateway`][aiortu.gateway]) until SIGINT or
SIGTERM (exit 0). A port or listen address that cannot be opened is one line on stderr (exit 1);
bad arguments are one line (exit 2). While the port is gone, clients get exception 0A and the
port is reopened with back-off.
"""

from __future__ import annotations

import argparse
import signal
import ssl
import sys
from typing import Any

import anyio

from aiortu.cli import SUMMARIES, CommandFailed, Subparsers
from aiortu.cli._arguments import (
    add_frame_gap,
    add_line_settings,
    is_pty,
    positive_int,
    resolve_line_settings,
    seconds,
    unit,
)
from aiortu.cli._messages import library_warnings_on_stderr, port_failure
from aiortu.errors import ConfigError, InvalidValue, PortError
from aiortu.gateway import (
    DEFAULT_RETRIES,
    DEFAULT_TIMEOUT,
    Gateway,
    GatewayLine,
    Listen,
    gateway,
)
from aiortu.transport import server_tls_context

__all__ = ("register", "run")

_FRAMINGS = ("rtu", "ascii")

_EXAMPLES = """\
examples:
  aiortu gateway /dev/ttyUSB0 --listen tcp://0.0.0.0:502
      Modbus TCP on port 502 of every interface, to the line at 19200 8E1
  aiortu gateway /dev/ttyUSB0 --listen tcp://0.0.0.0:502 --listen rtu+tcp://0.0.0.0:5020
      Modbus TCP clients, and RTU over TCP ones (serial device server drivers)
  aiortu gateway /dev/ttyUSB0 --listen tcp://0.0.0.0:1502 --default-unit 1
      requests to unit id 255 go to unit 1 (otherwise they get exception 0B)
  aiortu gateway /dev/ttyUSB0 --listen tcp://127.0.0.1:1502,priority=-1 \\
                              --listen tcp://0.0.0.0:1503
      local clients (the SCADA) go before those of the other listener
  aiortu gateway /dev/ttyUSB0 --listen 'unix:/run/aiortu-ttyUSB0.sock?mode=0660&group=modbus'
      Modbus TCP framing on a Unix socket, for programs of group modbus on this machine
  aiortu gateway /dev/ttyUSB0 --listen tcp://0.0.0.0:1502,rules=viewer.toml \\
                              --listen tcp://127.0.0.1:1503
      clients of port 1502 may do what viewer.toml allows (exception 01 otherwise);
      see "Exposing a line safely" in docs/gateway.md
  aiortu gateway /dev/ttyUSB0 --listen tls://0.0.0.0:802,rules=roles.toml \\
                 --certfile gw.crt --keyfile gw.key --cafile clients.pem
      Modbus/TCP Security: each client certificate's role gets its rule
  aiortu gateway --line /dev/ttyUSB0:1-20 --line /dev/ttyUSB1:21-40 \\
                 --listen tcp://0.0.0.0:502
      two lines, each with its own master; units 41..247 get exception 0A
  aiortu gateway /dev/ttyUSB0 --framing ascii --listen tcp://0.0.0.0:502 \\
                              --listen udp://0.0.0.0:502
      a Modbus ASCII line (7E1) for Modbus TCP and Modbus UDP clients
  aiortu gateway --line /dev/ttyUSB0:1-20 --line /dev/ttyUSB1:21-40,framing=ascii \\
                 --listen tcp://0.0.0.0:502
      an RTU line and an ASCII line behind one address
  aiortu gateway /dev/ttyUSB0 --listen tcp://0.0.0.0:502 --cache-ms 500 \\
                 --stats 60 --metrics http://127.0.0.1:9102/metrics
      reads answered again for 500 ms, statistics on stderr every minute and
      for Prometheus on port 9102

two programs sharing one virtual line:
  aiortu virtual-bus --ports 2                      # prints /dev/pts/5 and /dev/pts/6
  aiortu serve /dev/pts/6 --config examples/devices.toml
  aiortu gateway /dev/pts/5 --listen tcp://127.0.0.1:1502
  mbpoll -m tcp -p 1502 -a 17 -t 4 -r 108 -c 3 -1 127.0.0.1   # from any number of programs

a client whose unit does not answer gets exception 0B (gateway target device failed to
respond) within 1 s with the defaults (--timeout 0.3 --retries 1), at once while the unit is
offline; 0A (gateway path unavailable) while the port is gone. A write to unit 0 is a
broadcast: executed, never answered; a read to unit 0 gets exception 01 at once. 08/04
(force listen-only) is answered at once with its echo; the unit then gets 0B at once until
an 08/01 brings it back.

as a service, one instance per serial device: examples/aiortu-gateway@.service

exit codes: 0 stopped by Ctrl-C (SIGINT) or SIGTERM; 1 a serial port, a listen address or
the metrics address cannot be opened; 2 bad arguments (overlapping --line ranges too)
"""


def register(subparsers: Subparsers) -> None:
    """Add the `gateway` subcommand to `subparsers`."""
    parser = subparsers.add_parser(
        "gateway",
        help=SUMMARIES["gateway"],
        description=(
            "Share a serial line (or several, routed by unit) with many Modbus TCP, UDP and "
            "TLS clients: every request goes through the line's one master, at frame level "
            "(every function code), fairly between connections, until interrupted (SIGINT or "
            "SIGTERM). See docs/gateway.md."
        ),
        epilog=_EXAMPLES,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    parser.add_argument(
        "port",
        metavar="SERIAL",
        nargs="?",
        help="serial device path or rtu+tcp://host:port (or give --line instead)",
    )
    parser.add_argument(
        "--line",
        action="append",
        default=[],
        metavar="SERIAL:FIRST-LAST",
        help="a line and the unit ids routed to it (as /dev/ttyUSB0:1-20); repeat for several",
    )
    parser.add_argument(
        "--listen",
        action="append",
        required=True,
        metavar="URL[,priority=N][,rules=FILE]",
        help=(
            "tcp://host:port (Modbus TCP), udp://host:port (Modbus UDP), rtu+tcp://host:port "
            "(RTU frames), tls://host:port (Modbus/TCP Security: --certfile, --keyfile, "
            "--cafile and rules) or unix:PATH[?mode=0660&group=NAME] (Modbus TCP on a Unix "
            "socket, with its file mode and group) to listen on; repeat for several; lower "
            "priorities go first (0); rules=FILE: what the listener's clients may do (a rule "
            "file, as for tls://; a refused request gets exception 01)"
        ),
    )
    tls = parser.add_argument_group("tls:// listeners")
    tls.add_argument("--certfile", metavar="PEM", help="the gateway's certificate")
    tls.add_argument("--keyfile", metavar="PEM", help="the gateway's private key")
    tls.add_argument("--cafile", metavar="PEM", help="the CAs of the trusted clients")
    line = parser.add_argument_group("line settings")
    add_line_settings(line)
    add_frame_gap(line, before="request")
    line.add_argument(
        "--framing",
        choices=_FRAMINGS,
        default="rtu",
        help="the lines' framing: rtu, or ascii (7E1 by default; 8N2 on a pseudo-terminal); "
        "per line as --line PORT:1-20,framing=ascii (rtu)",
    )
    master = parser.add_argument_group("the master on the line")
    master.add_argument(
        "--timeout", type=seconds, default=DEFAULT_TIMEOUT,
        help=f"response timeout ({DEFAULT_TIMEOUT}; with --retries, a unit that does not "
        "answer gets 0B within 1 s; give a slow line more, as --timeout 1 --retries 2)",
    )  # fmt: skip
    master.add_argument(
        "--retries", type=int, default=DEFAULT_RETRIES,
        help=f"extra attempts of a read (01-04, 07, 0B, 0C, 11, 14, 18, 2B) after a timeout or "
        f"a bad frame; writes and diagnostics are sent once ({DEFAULT_RETRIES})",
    )  # fmt: skip
    master.add_argument(
        "--offline-after",
        type=positive_int,
        default=3,
        metavar="N",
        help="failures in a row after which a unit gets 0B at once, probed every 5 s (3)",
    )
    _add_client_options(parser.add_argument_group("clients"))
    _add_statistics(parser.add_argument_group("statistics"))
    parser.set_defaults(run=run)


def _add_client_options(clients: argparse._ArgumentGroup) -> None:
    clients.add_argument(
        "--max-in-flight", type=positive_int, default=4, metavar="N",
        help="requests a connection may have waiting (4)",
    )  # fmt: skip
    clients.add_argument(
        "--max-connections", type=positive_int, default=32, metavar="N",
        help="connections served at once (32)",
    )  # fmt: skip
    clients.add_argument(
        "--idle-timeout", type=seconds, default=120.0, metavar="SECONDS",
        help="close a connection silent this long with nothing waiting (120)",
    )  # fmt: skip
    clients.add_argument(
        "--default-unit", type=unit, default=None, metavar="UNIT",
        help="the unit a request to unit id 255 goes to (none: exception 0B)",
    )  # fmt: skip
    clients.add_argument(
        "--no-coalesce", dest="coalesce", action="store_false",
        help="send every read, even while an identical one is in flight",
    )  # fmt: skip
    clients.add_argument(
        "--cache-ms", type=non_negative_float, default=0, metavar="MS",
        help="answer a read of the same block again for MS milliseconds (0: off)",
    )  # fmt: skip


def _add_statistics(watch: argparse._ArgumentGroup) -> None:
    watch.add_argument(
        "--stats", type=seconds, default=None, metavar="SECONDS",
        help="print statistics per line, unit and client on stderr at this interval",
    )  # fmt: skip
    watch.add_argument(
        "--metrics", default=None, metavar="URL",
        help="serve them as Prometheus text, as http://127.0.0.1:9102/metrics",
    )  # fmt: skip
    watch.add_argument(
        "--stats-clients", type=positive_int, default=256, metavar="N",
        help="client hosts counted one by one, the most recent; the others added up (256)",
    )  # fmt: skip


def non_negative_float(text: str) -> float:
    """A number of 0 or more, for argparse."""
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not a number") from None
    if not value >= 0:
        raise argparse.ArgumentTypeError(f"{text} is negative: give 0 or more")
    return value


def _ports(args: argparse.Namespace) -> str | list[GatewayLine]:
    """The positional port, or the `--line` values; raises InvalidValue when wrong."""
    if args.port is not None and args.line:
        raise InvalidValue(
            "--line", args.line, "", message="give either SERIAL or --line, not both"
        )
    if args.port is not None:
        return str(args.port)
    if not args.line:
        raise InvalidValue("SERIAL", None, "", message="give a SERIAL port or --line")
    return [_parse_line(text) for text in args.line]


def _listens(texts: list[str]) -> list[Listen] | str:
    """The `--listen` values as [`Listen`][aiortu.gateway.Listen]s, or what is wrong with one."""
    listens = []
    for text in texts:
        url, *options = text.split(",")
        priority, rules = 0, None
        for option in options:
            name, _, value = option.partition("=")
            try:
                if name == "priority":
                    priority = int(value)
                elif name == "rules" and value:
                    rules = value
                else:
                    raise ValueError(name)
            except ValueError:
                return (
                    f"--listen {text}: after the URL only ',priority=N' (an integer) and "
                    "',rules=FILE' are allowed"
                )
        listens.append(Listen(url, priority, rules))
    return listens


def run(args: argparse.Namespace) -> int:
    """Serve until SIGINT or SIGTERM; return the exit code."""
    listens = _listens(args.listen)
    try:
        if isinstance(listens, str):
            raise InvalidValue("--listen", args.listen, "", message=listens)
        ports = _ports(args)
    except InvalidValue as error:
        print(f"aiortu gateway: error: {error}", file=sys.stderr)
        return 2
    # Every line shares the baud rate and parity; the first port's kind picks the defaults.
    given, bytesize = args.port, args.bytesize
    args.port = ports if isinstance(ports, str) else str(ports[0].port)
    resolve_line_settings(args)
    args.port, args.bytesize = given, bytesize  # per line, by its framing and kind
    with library_warnings_on_stderr("gateway"):
        return anyio.run(_serve, args, ports, listens)


def _parse_line(text: str) -> GatewayLine:
    """A `--line PORT:FIRST-LAST[,framing=ascii]` value (or `PORT:UNIT`); raises InvalidValue
    when wrong. The framing goes in the line's options (see `_line_options`)."""
    where, _, option = text.partition(",")
    port, colon, units = where.rpartition(":")
    first, dash, last = units.partition("-")
    name, _, framing = option.partition("=")
    try:
        if not (colon and port) or (option and (name != "framing" or framing not in _FRAMINGS)):
            raise ValueError(text)
        low = int(first)
        high = int(last) if dash else low
    except ValueError:
        raise InvalidValue(
            "--line", text, "PORT:FIRST-LAST", message=f"--line {text}: expected "
            "PORT:FIRST-LAST[,framing=rtu|ascii] with unit ids in 1..247, as /dev/ttyUSB0:1-20"
        ) from None  # fmt: skip
    if not 1 <= low <= high <= 247:
        raise InvalidValue(
            "--line", text, "PORT:FIRST-LAST", message=f"--line {text}: the units must be "
            "FIRST-LAST with 1 <= FIRST <= LAST <= 247"
        )  # fmt: skip
    return GatewayLine(port, range(low, high + 1), options={"framing": framing} if option else {})


def _line_options(args: argparse.Namespace, port: str, framing: str) -> dict[str, Any]:
    """The framing and data bits of the line on `port`: ASCII's 7 data bits unless
    `--bytesize` says otherwise or the port is a pseudo-terminal, which keeps 8."""
    if framing != "ascii":
        return {"bytesize": args.bytesize or 8}
    return {"framing": "ascii", "bytesize": args.bytesize or (8 if is_pty(port) else 7)}


def _with_options(
    args: argparse.Namespace, ports: str | list[GatewayLine]
) -> tuple[str | list[GatewayLine], dict[str, Any]]:
    """The lines, each with its framing and data bits, and the options of a single port."""
    if isinstance(ports, str):
        return ports, _line_options(args, ports, args.framing)
    lines = [
        GatewayLine(
            line.port,
            line.units,
            options=_line_options(args, str(line.port), line.options.get("framing", args.framing)),
        )
        for line in ports
    ]
    return lines, {}


async def _serve(
    args: argparse.Namespace, ports: str | list[GatewayLine], listens: list[Listen]
) -> int:
    failure: CommandFailed | None = None
    lines, options = _with_options(args, ports)
    with anyio.open_signal_receiver(signal.SIGINT, signal.SIGTERM) as signals:
        try:
            async with gateway(
                lines,
                listens,
                max_in_flight=args.max_in_flight,
                max_connections=args.max_connections,
                idle_timeout=args.idle_timeout,
                default_unit=args.default_unit,
                coalesce=args.coalesce,
                cache_ms=args.cache_ms,
                metrics=args.metrics,
                client_statistics=args.stats_clients,
                tls=_tls_context(args, listens),
                baudrate=args.baudrate,
                parity=args.parity,
                stopbits=args.stopbits,
                frame_gap=args.frame_gap,
                timeout=args.timeout,
                retries=args.retries,
                offline_after=args.offline_after,
                **options,
            ) as server:
                _say(f"{_shared_what(args, server)}; Ctrl-C to stop")
                async with anyio.create_task_group() as tasks:
                    if args.stats is not None:
                        tasks.start_soon(_print_stats, server, args.stats)
                    async for _ in signals:
                        break
                    tasks.cancel_scope.cancel()
        except PortError as error:
            failure = CommandFailed(port_failure(error))
        except (InvalidValue, ConfigError) as error:
            print(f"aiortu gateway: error: {error}", file=sys.stderr)
            return 2
    # Raised out here, not from inside the gateway's task group.
    if failure is not None:
        raise failure
    return 0


def _tls_context(args: argparse.Namespace, listens: list[Listen]) -> ssl.SSLContext | None:
    """The server context of the tls:// listeners (None when there is none); a certificate
    option without such a listener is an `InvalidValue` rather than quietly ignored."""
    if not any(item.url.lower().startswith("tls://") for item in listens):
        for name in ("certfile", "keyfile", "cafile"):
            if getattr(args, name) is not None:
                raise InvalidValue(
                    f"--{name}", getattr(args, name), "", message=f"--{name} is for a "
                    "--listen tls:// (Modbus/TCP Security), and no --listen is one",
                )  # fmt: skip
        return None
    return server_tls_context(args.certfile, args.keyfile, args.cafile)


def _shared_what(args: argparse.Namespace, server: Gateway) -> str:
    """What the gateway serves where, for its first line on stderr."""
    where = [f"{host}:{port}" for host, port in server.local_addresses] + server.unix_paths
    names = args.port or ", ".join(args.line)
    bits = args.bytesize or ("7" if args.framing == "ascii" else "8")
    text = f"{names} at {args.baudrate} {bits}{args.parity}{args.stopbits} shared on "
    text += ", ".join(where)
    if server.metrics_address is not None:
        host, port = server.metrics_address
        text += f"; metrics on http://{host}:{port}"
    return text


async def _print_stats(server: Gateway, interval: float) -> None:
    while True:
        await anyio.sleep(interval)
        for line in server.statistics.summary():
            _say(line)


def _say(message: str) -> None:
    sys.stderr.write(f"aiortu gateway: {message}\n")
    sys.stderr.flush()

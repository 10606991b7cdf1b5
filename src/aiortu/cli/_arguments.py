"""The argument types every command shares: each turns a command-line string into a value
or raises `argparse.ArgumentTypeError` naming the problem, which argparse prints
with the option's name before exiting with code 2."""

from __future__ import annotations

import argparse
import math
import os
import stat

__all__ = (
    "PTY_LINE",
    "add_line_settings",
    "add_no_reconnect",
    "add_timing",
    "address",
    "is_pty",
    "number",
    "parity",
    "plural",
    "positive_int",
    "probability",
    "resolve_line_settings",
    "seconds",
    "seconds_or_zero",
    "unit",
    "unit_id",
)

PTY_LINE = "--parity N --stopbits 2"
"""What to use on a pseudo-terminal: ptys keep no parity bit, and 8N2 has the same
character time (11 bits) as the spec's 8E1."""

_PARITIES = {"n": "N", "none": "N", "e": "E", "even": "E", "o": "O", "odd": "O"}


def plural(count: int, noun: str, nouns: str | None = None) -> str:
    """`1 cycle`, `2 cycles`: `count` and the noun that goes with it."""
    return f"{count} {noun if count == 1 else nouns or noun + 's'}"


def address(text: str) -> int:
    """An address or a count: decimal or `0x` hex."""
    value = _integer(text)
    if value < 0:
        raise argparse.ArgumentTypeError(f"must be 0 or more, not {text}")
    return value


def positive_int(text: str) -> int:
    """An integer >= 1, decimal or `0x` hex."""
    value = _integer(text)
    if value < 1:
        raise argparse.ArgumentTypeError(f"must be 1 or more, not {text}")
    return value


def unit(text: str) -> int:
    """A unit address for a request that gets a reply: 1..247."""
    value = _integer(text)
    if not 1 <= value <= 247:
        hint = " (0 is the broadcast address, which gets no reply)" if value == 0 else ""
        raise argparse.ArgumentTypeError(f"must be a unit address 1..247, not {text}{hint}")
    return value


def unit_id(text: str) -> int:
    """A unit id 0..255: what a Modbus TCP request may carry (a serial line takes 1..247;
    `aiortu.cli._master.check_unit_for_port` checks that once the port is known)."""
    value = _integer(text)
    if not 0 <= value <= 255:
        raise argparse.ArgumentTypeError(
            f"must be a unit address 1..247 (0..255 over tcp://, udp://, tls://), not {text}"
        )
    return value


def _integer(text: str) -> int:
    try:
        return int(text, 16) if text.lower().lstrip("+-").startswith("0x") else int(text, 10)
    except ValueError:
        message = f"must be a decimal or 0x hex number, not {text}"
        raise argparse.ArgumentTypeError(message) from None


def seconds(text: str) -> float:
    """A number of seconds > 0."""
    value = _number_of_seconds(text)
    if not 0 < value < float("inf"):
        raise argparse.ArgumentTypeError(f"must be a number of seconds more than 0, not {text}")
    return value


def seconds_or_zero(text: str) -> float:
    """A number of seconds >= 0."""
    value = _number_of_seconds(text)
    if not 0 <= value < float("inf"):
        raise argparse.ArgumentTypeError(f"must be a number of seconds, 0 or more, not {text}")
    return value


def number(text: str) -> float:
    """A finite number, such as a scale factor: `0.1`, `-2`, `1e3`."""
    try:
        value = float(text)
    except ValueError:
        value = math.nan
    if not math.isfinite(value):
        raise argparse.ArgumentTypeError(f"'{text}' is not a number")
    return value


def probability(text: str) -> float:
    """A probability, 0 to 1."""
    try:
        value = float(text)
    except ValueError:
        value = math.nan
    if not 0 <= value <= 1:
        raise argparse.ArgumentTypeError(f"must be a probability from 0 to 1, not {text}")
    return value


def _number_of_seconds(text: str) -> float:
    try:
        return float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"must be a number of seconds, not {text}") from None


def parity(text: str) -> str:
    """A parity: `N`, `E` or `O`, or `none`, `even`, `odd`, in any case."""
    found = _PARITIES.get(text.strip().lower())
    if found is None:
        raise argparse.ArgumentTypeError(f"must be N, E or O (or none, even, odd), not {text}")
    return found


def add_line_settings(group: argparse._ArgumentGroup) -> None:
    """Add `--baudrate`, `--bytesize`, `--parity` and `--stopbits`; see
    `resolve_line_settings`."""
    group.add_argument("--baudrate", type=positive_int, default=19200, help="baud rate (19200)")
    group.add_argument(
        "--bytesize",
        type=int,
        choices=(7, 8),
        default=None,
        help="data bits (8; 7 with --framing ascii, as the spec says, except on a "
        "pseudo-terminal, which keeps 8)",
    )
    group.add_argument(
        "--parity",
        type=parity,
        default=None,
        metavar="N|E|O",
        help="N, E or O, or none, even, odd (E; N on a pseudo-terminal, which keeps no parity)",
    )
    group.add_argument(
        "--stopbits",
        type=int,
        choices=(1, 2),
        default=None,
        help="stop bits (2 with parity N, else 1, as the spec says)",
    )


def add_frame_gap(group: argparse._ArgumentGroup, *, before: str) -> None:
    """Add `--frame-gap`, the silence kept before each `before` (`args.frame_gap`)."""
    group.add_argument(
        "--frame-gap",
        type=seconds_or_zero,
        default=None,
        metavar="SECONDS",
        help=f"silence kept before each {before} (t3.5 of the line settings)",
    )


def add_timing(group: argparse._ActionsContainer) -> None:
    """Add `--timing strict|tolerant`, the receiver's t1.5 mode (`args.timing`)."""
    group.add_argument(
        "--timing",
        choices=("strict", "tolerant"),  # TimingMode's values; the core is not imported yet
        default="tolerant",
        help=(
            "strict: a gap over t1.5 inside a frame breaks it and t3.5 ends it, as the spec "
            "says; tolerant: only a silence of t3.5 or 20 ms, whichever is longer, ends a "
            "frame, for USB adapters and virtual lines (tolerant)"
        ),
    )


def add_no_reconnect(parser: argparse.ArgumentParser) -> None:
    """Add `--no-reconnect`: `args.reconnect` is True unless it is given."""
    parser.add_argument(
        "--no-reconnect",
        dest="reconnect",
        action="store_false",
        help="exit 1 when the port is lost, instead of reopening it",
    )


def resolve_line_settings(args: argparse.Namespace) -> None:
    """Fill in the data bits, parity and stop bits `args` leave out: the spec's 8E1 on a serial
    port (7E1 with `--framing ascii`), 8N2 on a pseudo-terminal (such as `aiortu virtual-bus`
    makes; it keeps neither parity nor 7 data bits, so ASCII too), and 2 stop bits whenever the
    parity is N, as the spec says."""
    if getattr(args, "bytesize", None) is None:
        ascii_framing = getattr(args, "framing", "rtu") == "ascii"
        args.bytesize = 7 if ascii_framing and not is_pty(args.port) else 8
    if args.parity is None:
        args.parity = "N" if is_pty(args.port) else "E"
    if args.stopbits is None:
        args.stopbits = 2 if args.parity == "N" else 1


def is_pty(port: str) -> bool:
    """Whether `port` is the device path of a pseudo-terminal (links followed)."""
    try:
        device = os.stat(port).st_rdev if stat.S_ISCHR(os.stat(port).st_mode) else None
    except (OSError, ValueError):
        return False
    if device is None:
        return False
    # Linux numbers Unix98 pty slaves 136..143; elsewhere, go by the name.
    if os.major(device) in range(136, 144):
        return True
    name = os.path.realpath(port)
    return name.startswith(("/dev/pts/", "/dev/ttys", "/dev/pty"))

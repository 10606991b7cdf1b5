"""The options of the framings and secure transports: `--framing`, and the certificates of
`tls://` (`--certfile`, `--keyfile`, `--cafile`, and `--rules` for a server)."""

from __future__ import annotations

import argparse
from typing import Any

__all__ = ("add_transport_options", "misplaced_option", "transport_options")


def add_transport_options(parser: argparse.ArgumentParser, *, server: bool = False) -> None:
    """Add the options; `server` adds `--rules`, the role rules of a `tls://` listener."""
    group = parser.add_argument_group("framing and security")
    group.add_argument(
        "--framing",
        choices=("rtu", "ascii"),
        default="rtu",
        help="the serial framing on a device path or rtu+tcp:// (rtu; ascii+tcp:// is ascii)",
    )
    whose = "the server's" if server else "this client's"
    group.add_argument("--certfile", metavar="PEM", help=f"tls://: {whose} certificate")
    group.add_argument("--keyfile", metavar="PEM", help=f"tls://: {whose} private key")
    trusted = "clients" if server else "servers"
    group.add_argument("--cafile", metavar="PEM", help=f"tls://: the CAs of the trusted {trusted}")
    if server:
        group.add_argument(
            "--rules", metavar="FILE.toml", help="tls://: what each client role may do"
        )


_TLS_OPTIONS = ("certfile", "keyfile", "cafile", "rules")

_ASCII_SCHEMES = ("", "rtu+tcp", "ascii+tcp")
"""Where `--framing ascii` applies: a serial device path (no scheme) and the serial framings
over TCP; Modbus TCP, UDP and TLS carry MBAP frames."""


def misplaced_option(args: argparse.Namespace) -> str | None:
    """Why an option of the group does not go with the port `args.port`, in one sentence;
    None when they all do. (Given to the library, such an option would be a `TypeError`.)"""
    scheme, separator, _ = args.port.partition("://")
    scheme = scheme.lower() if separator else ""
    if scheme != "tls":
        given = [f"--{name}" for name in _TLS_OPTIONS if getattr(args, name, None) is not None]
        if given:
            return f"{given[0]} is for a tls:// port (Modbus/TCP Security), not {args.port}"
    if args.framing == "ascii" and scheme not in _ASCII_SCHEMES:
        return (
            f"--framing ascii is for a serial device path or rtu+tcp://, not {args.port}, "
            "whose frames are Modbus TCP's"
        )
    return None


def transport_options(args: argparse.Namespace) -> dict[str, Any]:
    """The keyword arguments of `open_master` or `serve` that the options ask for."""
    options: dict[str, Any] = {}
    if args.framing == "ascii":
        options["framing"] = "ascii"
    for name in _TLS_OPTIONS:
        value = getattr(args, name, None)
        if value is not None:
            options[name] = value
    return options

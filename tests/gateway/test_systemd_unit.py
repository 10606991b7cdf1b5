"""The systemd template unit in examples/ starts `aiortu gateway` with arguments it accepts."""

from __future__ import annotations

import configparser
import shlex
from pathlib import Path

from aiortu.cli import build_parser

UNIT_FILE = Path(__file__).parents[2] / "examples" / "aiortu-gateway@.service"


def _unit() -> configparser.ConfigParser:
    unit = configparser.ConfigParser(strict=False, interpolation=None)
    unit.optionxform = str  # type: ignore[assignment,method-assign]
    unit.read_string(UNIT_FILE.read_text())
    return unit


def test_the_unit_runs_the_gateway_on_its_instance_with_arguments_the_cli_takes() -> None:
    service = _unit()["Service"]
    name, _, default = shlex.split(service["Environment"])[0].partition("=")
    command = service["ExecStart"].replace(f"${name}", default).replace("%i", "ttyUSB0")
    program, *argv = shlex.split(command)
    assert program.endswith("/aiortu")
    args = build_parser("gateway").parse_args(argv)
    assert args.port == "/dev/ttyUSB0"
    assert args.listen == ["tcp://0.0.0.0:1502", "unix:/run/aiortu-ttyUSB0/gateway.sock"]
    # Bad arguments (exit 2) are not worth a restart.
    assert service["RestartPreventExitStatus"] == "2"
    assert service["RuntimeDirectory"] == "aiortu-%i"

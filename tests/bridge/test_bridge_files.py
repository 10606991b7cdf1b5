"""The shipped bridge files: the example configurations load, the systemd unit runs the
command with arguments it accepts."""

from __future__ import annotations

import configparser
import shlex
from pathlib import Path

from aiortu.bridge import load_config
from aiortu.cli import build_parser

EXAMPLES = Path(__file__).parents[2] / "examples"


def test_the_example_configurations_load() -> None:
    site = load_config(EXAMPLES / "bridge" / "bridge.toml")
    assert [d.name for d in site.devices()] == ["grid-meter", "inverter", "heat-pump"]
    assert site.broker.url == "mqtt://127.0.0.1:1883"
    assert site.lines[1].port == "tcp://10.0.0.20:1502"
    demo = load_config(EXAMPLES / "bridge" / "demo.toml")
    assert {line.port for line in demo.lines} == {"virtual"}


def test_the_unit_runs_the_bridge_on_its_instance_configuration() -> None:
    unit = configparser.ConfigParser(strict=False, interpolation=None)
    unit.read_string((EXAMPLES / "aiortu-bridge@.service").read_text())
    service = unit["Service"]
    program, *argv = shlex.split(service["ExecStart"].replace("%i", "site-1"))
    assert program.endswith("/aiortu")
    args = build_parser("bridge").parse_args(argv)
    assert args.config == "/etc/aiortu/bridge-site-1.toml"
    assert service["RestartPreventExitStatus"] == "2"

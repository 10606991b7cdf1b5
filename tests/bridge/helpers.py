"""Bridge configurations for the tests: the heat pump example on a virtual line."""

from __future__ import annotations

from pathlib import Path

from aiortu.bridge import BridgeConfig, parse_config

ROOT = Path(__file__).parents[2]
HEAT_PUMP = ROOT / "examples" / "profiles" / "heat-pump.toml"


def config(url: str, *, layout: str = "home-assistant", units: tuple[int, ...] = (1, 2),
           extra: str = "", node: str = "test", device: str = "") -> BridgeConfig:  # fmt: skip
    devices = "".join(
        f'[[line.device]]\nname = "hp-{unit}"\nunit = {unit}\nprofile = "{HEAT_PUMP}"\n{device}\n'
        for unit in units
    )
    text = (
        f'[broker]\nurl = "{url}"\nkeepalive = 5\n'
        f'[topics]\nlayout = "{layout}"\nnode = "{node}"\n{extra}\n'
        f'[[line]]\nport = "virtual"\ntimeout = 0.2\n{devices}'
    )
    return parse_config(text, "test.toml")

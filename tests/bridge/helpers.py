"""Bridge configurations for the tests: the heat pump example on a virtual line."""

from __future__ import annotations

import functools
import tempfile
from pathlib import Path

from aiortu.bridge import BridgeConfig, parse_config

ROOT = Path(__file__).parents[2]
HEAT_PUMP = ROOT / "examples" / "profiles" / "heat-pump.toml"
FAST_POLL = 0.25
"""How often `fast_heat_pump` polls its points of the default poll class, in seconds (the
example's every second)."""
_PROFILES = tempfile.TemporaryDirectory(prefix="aiortu-profiles-")


@functools.cache
def fast_heat_pump() -> Path:
    """The heat pump example with the points of the default poll class (`normal`: the power,
    the temperature, the mode...) polled every `FAST_POLL` seconds: for the tests that wait
    for a number of polls."""
    text = HEAT_PUMP.read_text()
    assert "\n[poll]\n" in text, "the example's poll classes moved"
    assert "\nnormal =" not in text, "the example's poll classes moved"
    path = Path(_PROFILES.name) / "heat-pump-fast.toml"
    path.write_text(text.replace("\n[poll]\n", f"\n[poll]\nnormal = {FAST_POLL}\n"))
    return path


def config(url: str, *, layout: str = "home-assistant", units: tuple[int, ...] = (1, 2),
           extra: str = "", node: str = "test", device: str = "",
           profile: Path = HEAT_PUMP) -> BridgeConfig:  # fmt: skip
    devices = "".join(
        f'[[line.device]]\nname = "hp-{unit}"\nunit = {unit}\nprofile = "{profile}"\n{device}\n'
        for unit in units
    )
    text = (
        f'[broker]\nurl = "{url}"\nkeepalive = 5\n'
        f'[topics]\nlayout = "{layout}"\nnode = "{node}"\n{extra}\n'
        f'[[line]]\nport = "virtual"\ntimeout = 0.2\n{devices}'
    )
    return parse_config(text, "test.toml")

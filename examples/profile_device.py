"""Describe a device in a file, serve it, read it by name and write to it, without a register
number in the code.

The heat pump of examples/profiles/heat-pump.toml is simulated by a ProfileStore on an
in-memory line; a master reads its points as named values with their units and writes the
setpoint by name (a write outside the profile's limits is refused before it is sent)::

    python examples/profile_device.py
"""

from __future__ import annotations

from pathlib import Path

import anyio

import aiortu
from aiortu.core.model import parse_profile
from aiortu.testing import VirtualBus

SETTINGS = aiortu.LineSettings(19200, parity="E")
PROFILE = Path(__file__).parent / "profiles" / "heat-pump.toml"


async def main() -> None:
    # parse_profile names the file in messages as given; load_profile(PROFILE) gives its path.
    profile = parse_profile(PROFILE.read_text(encoding="utf-8"), PROFILE.name)
    bus = VirtualBus(2, settings=SETTINGS)
    async with (
        aiortu.Slave(bus.endpoints[1], {7: aiortu.ProfileStore(profile)}, SETTINGS),
        aiortu.Master(bus.endpoints[0], SETTINGS, timeout=0.5) as master,
    ):
        heat_pump = aiortu.Device(master, 7, profile)
        print(f"{len(profile.points)} points in {len(heat_pump.plan().reads)} reads")
        for name, reading in (await heat_pump.read()).items():
            print(f"{name:17} {reading.value} {reading.unit_of_measurement}".rstrip())
        await heat_pump.write("setpoint", 48.5)
        print(f"setpoint now {await heat_pump.read_point('setpoint')}")
        try:
            await heat_pump.write("setpoint", 70)
        except aiortu.InvalidValue as error:
            print(f"refused: {error}")


if __name__ == "__main__":
    anyio.run(main)

"""Poll several simulated devices on one virtual RS-485 line with aiortu.Poller.

Runs on its own: three devices (units 1, 2 and 3) are simulated by an aiortu.Slave with
a MemoryStore each, on an in-memory bus paced at 19200 baud; unit 4 is configured in the
poller but absent from the line, to show that a dead device does not stall the cycle.
Prints every sample of three cycles, then the cycle times and each unit's health::

    python examples/poll_several_devices.py
"""

from __future__ import annotations

import anyio

import aiortu
from aiortu.core.model import Layout, encode_value
from aiortu.testing import VirtualBus

SETTINGS = aiortu.LineSettings(19200, parity="E")


def meter(voltage: float, current: float, energy: int) -> aiortu.MemoryStore:
    """An energy meter: floats in input registers (word-swapped), a counter in holding."""
    registers = [
        *encode_value(voltage, "float32", Layout.CDAB),
        *encode_value(current, "float32", Layout.CDAB),
    ]
    return aiortu.MemoryStore(
        input_registers={0: registers},
        holding_registers={100: list(encode_value(energy, "uint32"))},
        coils={0: [1, 0, 1, 1]},
    )


async def main() -> None:
    devices = {
        1: meter(230.5, 4.25, 123_456),
        2: meter(229.0, 0.5, 98_000),
        3: meter(231.25, 12.0, 7),
    }
    points = []
    for unit in (1, 2, 3, 4):
        points += [
            aiortu.Point.of(f"voltage{unit}", unit, "30001", "float32", layout="CDAB"),
            aiortu.Point.of(f"current{unit}", unit, "30003", "float32", layout="CDAB"),
            aiortu.Point.of(f"energy{unit}", unit, "40101", "uint32", scale=0.001),
            aiortu.Point.of(f"relay{unit}", unit, "00001"),
        ]
    bus = VirtualBus(2, settings=SETTINGS)
    async with (
        aiortu.Slave(bus.endpoints[1], devices, SETTINGS),
        # offline_after=1: one failed read marks a unit offline (the default is 3); the
        # timeout leaves a loaded machine time to answer for the units that are there.
        aiortu.Master(
            bus.endpoints[0], SETTINGS, timeout=1.0, retries=0, offline_after=1
        ) as master,
    ):
        poller = aiortu.Poller(master, points, interval=0.1, offline_probe_interval=2.0)
        print(f"{len(points)} points in {len(poller.reads)} reads")
        await anyio.sleep(0.01)
        with anyio.fail_after(10):
            async with poller:
                async for sample in poller:
                    if not sample.ok:
                        value = f"({sample.error})"
                    elif isinstance(sample.value, bool):
                        value = "on" if sample.value else "off"
                    else:
                        value = f"{sample.value:.3f}"
                    print(f"cycle {sample.cycle} unit {sample.unit} {sample.name:<10} {value}")
                    if sample.cycle == 2 and sample.name == points[-1].name:
                        break
        stats = poller.cycle_time
        assert stats.last is not None
        assert stats.mean is not None
        print(f"cycle time: last {stats.last * 1000:.1f} ms, mean {stats.mean * 1000:.1f} ms")
        for unit, health in poller.health().items():
            # online, suspect (a read failed lately) or offline (probed only)
            print(f"unit {unit}: {health.state.value}, {health.skipped} reads skipped")


if __name__ == "__main__":
    anyio.run(main)

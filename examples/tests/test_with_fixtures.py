"""A pytest-asyncio suite for your own Modbus code, on virtual lines, with a fault plan.

The aiortu pytest plugin (installed with aiortu) provides the ``virtual_bus``,
``virtual_pair`` and ``pty_bus`` fixtures. Here the code under test is
``read_temperature``, a small function an application might have; the tests run it
against a simulated device on an in-memory bus, first on a clean line and then on a
noisy one, where every result must still be right or a clear aiortu error.

Run it with::

    pytest examples/tests/test_with_fixtures.py
"""

from __future__ import annotations

import pytest

import aiortu
from aiortu.testing import FaultPlan

SETTINGS = aiortu.LineSettings(19200, parity="E")


async def read_temperature(master: aiortu.Master, unit: int) -> float:
    """The application code under test: a temperature in tenths of a degree at 30001."""
    (raw,) = await master.read_input_registers(unit, 0, 1)
    return raw / 10


def thermometer(tenths: int) -> aiortu.MemoryStore:
    return aiortu.MemoryStore(input_registers={0: [tenths]})


@pytest.mark.asyncio
async def test_reads_the_temperature(virtual_bus) -> None:  # type: ignore[no-untyped-def]
    bus = virtual_bus(2, settings=SETTINGS)
    async with (
        aiortu.Slave(bus[1], {5: thermometer(215)}, SETTINGS),
        aiortu.Master(bus[0], SETTINGS, timeout=0.5) as master,
    ):
        assert await read_temperature(master, 5) == 21.5


@pytest.mark.asyncio
async def test_a_missing_device_times_out(virtual_bus) -> None:  # type: ignore[no-untyped-def]
    bus = virtual_bus(2, settings=SETTINGS)
    async with (
        aiortu.Slave(bus[1], {5: thermometer(215)}, SETTINGS),
        aiortu.Master(bus[0], SETTINGS, timeout=0.1, retries=0) as master,
    ):
        with pytest.raises(aiortu.ResponseTimeout):
            await read_temperature(master, 6)


@pytest.mark.asyncio
async def test_a_noisy_line_gives_right_values_or_clear_errors(virtual_bus) -> None:  # type: ignore[no-untyped-def]
    # One bit in a thousand flipped, reproducibly (the same seed, the same faults).
    noise = FaultPlan(bit_error_rate=1e-3, seed=7)
    bus = virtual_bus(2, settings=SETTINGS, faults=noise)
    outcomes = {"right": 0, "error": 0}
    async with (
        aiortu.Slave(bus[1], {5: thermometer(215)}, SETTINGS),
        aiortu.Master(bus[0], SETTINGS, timeout=0.2, retries=2) as master,
    ):
        for _ in range(40):
            try:
                value = await read_temperature(master, 5)
            except aiortu.ModbusError:
                outcomes["error"] += 1
            else:
                assert value == 21.5  # never a wrong value
                outcomes["right"] += 1
    assert outcomes["right"] > 30

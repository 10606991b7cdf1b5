"""A profile served by a ProfileStore and read, written and polled by name through a master."""

from __future__ import annotations

import math
import random
from collections.abc import AsyncIterator
from contextlib import asynccontextmanager
from pathlib import Path

import anyio
import pytest

import aiortu
from aiortu.core.model import PointType, load_profile, parse_profile
from aiortu.errors import ExceptionResponse, InvalidValue, ResponseTimeout
from aiortu.testing import VirtualBus

SETTINGS = aiortu.LineSettings(115200)
PROFILES = Path(__file__).parents[2] / "src/aiortu/core/model/profiles"

HOLEY = """
[device]
manufacturer = "ACME"
model = "Holey"

[defaults]
max_gap = 10

[[hole]]
start = 4
count = 1

[[point]]
name = "a"
address = 0
value = 1

[[point]]
name = "b"
address = 6
value = 2

[[point]]
name = "c"
address = 12
type = "i16"
scale_factor = "c_sf"
value = -1.5

[[point]]
name = "c_sf"
address = 13
type = "i16"
value = -1

[[point]]
name = "limit"
address = 14
type = "u16"
access = "rw"
scale = 0.5
min = 0
max = 100
value = 10

[[point]]
name = "mode"
address = 15
type = "enum"
access = "rw"
values = { 0 = "off", 1 = "auto", 2 = "manual" }
value = "auto"

[[point]]
name = "relay"
table = "coils"
address = 3
access = "rw"
"""


@asynccontextmanager
async def served(stores: dict[int, aiortu.ProfileStore]) -> AsyncIterator[aiortu.Master]:
    bus = VirtualBus(2, settings=SETTINGS)
    async with (
        aiortu.Slave(bus.endpoints[1], stores, SETTINGS),
        aiortu.Master(bus.endpoints[0], SETTINGS, timeout=0.2, retries=0) as master,
    ):
        yield master


async def test_reads_values_by_name_with_units_and_scale_factors() -> None:
    profile = parse_profile(HOLEY, "holey.toml")
    async with served({5: aiortu.ProfileStore(profile)}) as master:
        device = aiortu.Device(master, 5, profile)
        readings = await device.read()
        assert list(readings) == [p.name for p in profile.points]
        assert all(r.ok for r in readings.values())
        assert readings["a"].value == 1
        assert readings["c"].value == pytest.approx(-1.5)
        assert readings["c"].raw == -15
        assert readings["mode"].value == "auto"
        assert readings["relay"].value is False
        assert await device.read_point("c") == pytest.approx(-1.5)


async def test_a_hole_the_profile_does_not_know_costs_refusals_in_the_first_read_only() -> None:
    # The served profile has the hole; the polled one does not know it.
    served_profile = parse_profile(HOLEY, "holey.toml")
    blind = parse_profile(HOLEY.replace("[[hole]]\nstart = 4\ncount = 1\n", ""), "blind.toml")
    refusals: list[int] = []
    async with served({5: aiortu.ProfileStore(served_profile)}) as master:
        device = aiortu.Device(master, 5, blind)
        plan = device.plan()
        before = len(plan.reads)
        first = await device.read()
        assert all(r.ok for r in first.values())
        assert plan.splits >= 1
        assert len(plan.reads) == before + plan.splits
        refusals.append(plan.splits)
        second = await device.read()
        assert {n: r.value for n, r in second.items()} == {n: r.value for n, r in first.items()}
        assert plan.splits == refusals[0]


async def test_writes_by_name_are_checked_scaled_and_stored() -> None:
    profile = parse_profile(HOLEY, "holey.toml")
    store = aiortu.ProfileStore(profile)
    async with served({5: store}) as master:
        device = aiortu.Device(master, 5, profile)
        await device.write("limit", 42.5)
        assert store.get("holding_registers", 14) == [85]
        assert await device.read_point("limit") == 42.5
        await device.write("mode", "manual")
        assert store.value("mode") == "manual"
        await device.write("relay", True)
        assert store.value("relay") is True
        with pytest.raises(InvalidValue, match=r"holey\.toml: point limit: value 101 is outside"):
            await device.write("limit", 101)
        with pytest.raises(InvalidValue, match=r"holey\.toml: point a: is read-only"):
            await device.write("a", 3)
        with pytest.raises(InvalidValue, match=r"point mode: value 'fast' is not one of"):
            await device.write("mode", "fast")
        with pytest.raises(InvalidValue, match=r"holey\.toml: no point named 'nope'"):
            await device.write("nope", 1)
        assert store.value("limit") == 42.5


async def test_a_silent_unit_costs_one_timeout_and_reports_every_point() -> None:
    profile = parse_profile(HOLEY, "holey.toml")
    async with served({5: aiortu.ProfileStore(profile)}) as master:
        device = aiortu.Device(master, 9, profile)
        start = anyio.current_time()
        readings = await device.read()
        assert anyio.current_time() - start < 0.2 * 2
        assert all(isinstance(r.error, ResponseTimeout) for r in readings.values())
        assert all(r.value is None for r in readings.values())


async def test_a_single_refused_point_gets_the_exception() -> None:
    profile = parse_profile(HOLEY, "holey.toml")
    extra = HOLEY + '\n[[point]]\nname = "ghost"\naddress = 200\n'
    async with served({5: aiortu.ProfileStore(profile)}) as master:
        device = aiortu.Device(master, 5, parse_profile(extra, "extra.toml"))
        readings = await device.read()
        assert isinstance(readings["ghost"].error, ExceptionResponse)
        assert readings["a"].value == 1
        with pytest.raises(ExceptionResponse):
            await device.read_point("ghost")


@pytest.mark.parametrize("seed", [1, 2, 3])
async def test_the_shipped_meter_served_and_polled(seed: int) -> None:
    profile = load_profile(PROFILES / "eastron-sdm630.toml")
    store = aiortu.ProfileStore(profile)
    rng = random.Random(seed)
    expected = {}
    for point in profile.points:
        if point.type is PointType.F32 and not point.writable:
            value = rng.uniform(-1000, 1000)
            store.set_value(point.name, value)
            expected[point.name] = value
    async with served({1: store}) as master:
        device = aiortu.Device(master, 1, profile)
        readings = {}
        for poll_class in profile.poll_classes:
            readings |= await device.read(poll_class)
        assert len(device.plan("normal").reads) <= 4  # 3 of input registers, 1 of settings
        assert len(device.plan("energy").reads) <= 2
        for name, value in expected.items():
            assert math.isclose(readings[name].value, value, rel_tol=1e-6), f"seed {seed} {name}"
        assert readings["l1_voltage"].unit_of_measurement == "V"
        assert readings["l1_voltage"].unit == 1


async def test_the_profile_poller_delivers_every_class() -> None:
    profile = parse_profile(HOLEY.replace("[defaults]", "[poll]\nfast = 0.05\n\n[defaults]"), "p")
    profile = parse_profile(
        HOLEY.replace('name = "a"\naddress = 0', 'name = "a"\naddress = 0\npoll = "fast"').replace(
            "[defaults]", "[poll]\nfast = 0.05\n\n[defaults]"
        ),
        "p.toml",
    )
    async with served({5: aiortu.ProfileStore(profile), 6: aiortu.ProfileStore(profile)}) as m:
        devices = [aiortu.Device(m, 5, profile), aiortu.Device(m, 6, profile)]
        seen: list[aiortu.Reading] = []
        poller = aiortu.ProfilePoller(devices, on_reading=seen.append)
        readings = await poller.poll_once()
        assert len(readings) == 2 * len(profile.points)
        assert seen == readings
        with anyio.fail_after(5):
            await poller.run(cycles=3)
        fast = [r for r in seen if r.name == "a"]
        assert len(fast) >= 2 + 3 * 2


async def test_on_read_gets_each_read_whole_and_max_pending_0_streams_nothing() -> None:
    profile = parse_profile(
        HOLEY.replace('name = "a"\naddress = 0', 'name = "a"\naddress = 0\npoll = "fast"').replace(
            "[defaults]", "[poll]\nfast = 0.05\n\n[defaults]"
        ),
        "p.toml",
    )
    async with served({5: aiortu.ProfileStore(profile), 6: aiortu.ProfileStore(profile)}) as m:
        devices = [aiortu.Device(m, 5, profile), aiortu.Device(m, 6, profile)]
        reads: list[tuple[aiortu.Device, dict[str, aiortu.Reading]]] = []
        seen: list[aiortu.Reading] = []

        async def on_read(device: aiortu.Device, readings: dict[str, aiortu.Reading]) -> None:
            reads.append((device, dict(readings)))

        poller = aiortu.ProfilePoller(devices, on_read=on_read, on_reading=seen.append,
                                      max_pending=0)  # fmt: skip
        readings = await poller.poll_once()
        # One read per device and poll class, each whole, in the order of the readings.
        assert [r for _, read in reads for r in read.values()] == readings == seen
        assert [(d.unit, sorted(read)) for d, read in reads] == [
            (5, ["a"]), (6, ["a"]),
            (5, sorted(p.name for p in profile.points if p.name != "a")),
            (6, sorted(p.name for p in profile.points if p.name != "a")),
        ]  # fmt: skip
        assert all(r.unit == d.unit for d, read in reads for r in read.values())
        # Nothing waits for `async for`: it ends with the run, and nothing was dropped.
        with anyio.fail_after(5):
            await poller.run(cycles=2)
            assert [r async for r in poller] == []
        assert poller.dropped == 0
    with pytest.raises(InvalidValue, match="max_pending"):
        aiortu.ProfilePoller(devices, max_pending=-1)


async def test_units_match_the_profiles_that_identify_them() -> None:
    pump = load_profile(Path(__file__).parents[2] / "examples/profiles/heat-pump.toml")
    meter = load_profile(PROFILES / "eastron-sdm630.toml")  # it says nothing to match by
    other = parse_profile(
        HOLEY + '\n[device.identify]\nobjects = { vendor_name = "acme" }\n'
        'probe = [{ point = "a", equals = [9] }]\n',
        "other.toml",
    )
    stores = {
        7: aiortu.ProfileStore(pump),
        8: aiortu.ProfileStore(other),
        9: aiortu.ProfileStore(parse_profile(HOLEY, "holey.toml")),
    }
    stores[8].set_value("a", 9)
    async with served(stores) as master:
        found = {
            unit: [
                (m.profile.source, m.by)
                for m in await aiortu.master.match_profiles(master, unit, [pump, meter, other])
            ]
            for unit in (7, 8, 9)
        }
        stores[8].set_value("a", 1)  # the probe no longer holds
        again = await aiortu.master.match_profiles(master, 8, [pump, meter, other])
    assert found[7] == [(pump.source, ("device identification", "probes"))]
    assert found[8] == [("other.toml", ("device identification", "probes"))]
    assert found[9] == []  # the objects match, the probe does not
    assert again == []


def test_readings_made_for_polls_are_the_readings_the_class_makes() -> None:
    """The poll's cheaper construction of a frozen `Reading` against the class's own."""
    from aiortu.master._device import _reading  # the shortcut itself

    rng = random.Random(23)
    profile = parse_profile(HOLEY, "holey.toml")
    for point in profile.points:
        error = rng.choice([None, ResponseTimeout("no reply")])
        args = (rng.randrange(248), point, rng.choice([None, 1.5, 7, "x"]), rng.randrange(9), error)
        made, expected = _reading(*args), aiortu.Reading(*args)
        assert made == expected, f"seed 23, {point.name}"
        assert (made.name, made.ok) == (point.name, error is None)
        with pytest.raises(AttributeError):
            made.value = 0  # type: ignore[misc]

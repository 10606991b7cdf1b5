"""SunSpec: a device laid out from SunSpec's model definitions, served from a profile, walked
by aiortu and read by pysunspec2's own client (in its own venv, over Modbus TCP on loopback)."""

from __future__ import annotations

import json
import math
import socket
import subprocess
from collections.abc import AsyncIterator
from contextlib import asynccontextmanager
from pathlib import Path

import anyio
import pytest

import aiortu
from aiortu.core.model import SunSpecModels, Table, load_profile, model_length, sunspec_layout
from aiortu.errors import ConfigError
from aiortu.testing import VirtualBus
from tests.peers.venvs import PYSUNSPEC2, peer_python, sunspec_models

pytestmark = [pytest.mark.interop, pytest.mark.timeout(600)]

CLIENT = Path(__file__).parents[1] / "peers" / "sunspec_client.py"
SHIPPED = Path(__file__).parents[2] / "src/aiortu/core/model/profiles"
VALUES = {
    "m1.Mn": "aiortu",
    "m1.Md": "Simulated inverter",
    "m1.SN": "SIM-0001",
    "m103.A": 12.34,
    "m103.A_SF": -2,
    "m103.PhVphA": 230.1,
    "m103.V_SF": -1,
    "m103.W": 15000,
    "m103.W_SF": 1,
    "m103.Hz": 50.0,
    "m103.Hz_SF": -2,
    "m103.WH": 987654,
    "m103.WH_SF": 0,
    "m103.St": 4,
    "m160.DCA_SF": -1,
    "m160.module.1.DCA": 5.2,
    "m160.module.2.DCA": 4.8,
}


@pytest.fixture(scope="session")
def sunspec_python() -> Path:
    return peer_python(PYSUNSPEC2, "sunspec2")


@pytest.fixture(scope="session")
def models(sunspec_python: Path) -> SunSpecModels:
    return SunSpecModels.locate(sunspec_models(sunspec_python))


def inverter(models: SunSpecModels, base: int = 40000) -> aiortu.ProfileStore:
    profile = sunspec_layout(models, [1, 103, 160], base=base, repeats=2, values=VALUES)
    return aiortu.ProfileStore(profile)


@asynccontextmanager
async def line(stores: dict[int, aiortu.MemoryStore]) -> AsyncIterator[aiortu.Master]:
    bus = VirtualBus(2)
    async with (
        aiortu.Slave(bus.endpoints[1], stores),
        aiortu.Master(bus.endpoints[0], timeout=0.5, retries=0) as master,
    ):
        yield master


@pytest.mark.parametrize("base", [40000, 50000, 0])
async def test_the_walk_describes_the_device(models: SunSpecModels, base: int) -> None:
    async with line({3: inverter(models, base)}) as master:
        found = await aiortu.walk_sunspec(master, 3, models=models)
        assert found is not None
        assert found.base == base
        assert [(m.id, m.address) for m in found.models] == [
            (1, base + 2),
            (103, base + 70),
            (160, base + 122),
        ]
        assert found.skipped == ()
        assert (found.profile.device.manufacturer, found.profile.device.model) == (
            "aiortu",
            "Simulated inverter",
        )
        readings = await aiortu.Device(master, 3, found.profile).read()
    assert readings["m103.A"].value == pytest.approx(12.34)
    assert readings["m103.PhVphA"].value == pytest.approx(230.1)
    assert readings["m103.W"].value == pytest.approx(15000)
    assert readings["m103.Hz"].value == pytest.approx(50.0)
    assert readings["m103.St"].value == "MPPT"
    assert readings["m103.WH"].value == 987654
    assert readings["m103.VA"].value is None  # 0x8000: not implemented
    assert readings["m160.module.2.DCA"].value == pytest.approx(4.8)
    assert readings["m1.SN"].value == "SIM-0001"
    assert readings["m103.W"].unit_of_measurement == "W"


async def test_an_unknown_model_is_skipped_and_the_walk_goes_on(models: SunSpecModels) -> None:
    first = aiortu.ProfileStore(sunspec_layout(models, [1, 103], values=VALUES))
    head = first.get(Table.HOLDING_REGISTERS, 40000, 2 + 68 + 52)
    unknown = [64999, 4, 1, 2, 3, 4]
    base = 40000 + len(head) + len(unknown) - 2
    second = aiortu.ProfileStore(sunspec_layout(models, [160], base=base, repeats=2, values=VALUES))
    tail = second.get(
        Table.HOLDING_REGISTERS, base + 2, 2 + model_length(models.definition(160) or {}, 2) + 2
    )
    store = aiortu.MemoryStore(holding_registers={40000: [*head, *unknown, *tail]})
    async with line({3: store}) as master:
        found = await aiortu.walk_sunspec(master, 3, models=models)
        assert found is not None
        assert [m.id for m in found.models] == [1, 103, 160]
        assert [(m.id, m.address, m.length) for m in found.skipped] == [(64999, 40122, 4)]
        assert found.warnings == (
            "model 64999 at 40122 (4 registers) skipped: the SunSpec model definitions do "
            "not know it",
        )
        readings = await aiortu.Device(master, 3, found.profile).read()
    assert readings["m160.module.1.DCA"].value == pytest.approx(5.2)


async def test_no_marker_is_no_sunspec_device(models: SunSpecModels) -> None:
    plain = aiortu.MemoryStore(holding_registers={0: [1, 2, 3]})
    async with line({3: plain}) as master:
        assert await aiortu.walk_sunspec(master, 3, models=models) is None


def test_missing_definitions_say_how_to_get_them(tmp_path: Path) -> None:
    with pytest.raises(
        ConfigError, match=r"install pysunspec2 \(pip install 'aiortu\[sunspec\]'\)"
    ):
        SunSpecModels.locate(tmp_path)


def free_port() -> int:
    with socket.socket() as probe:
        probe.bind(("127.0.0.1", 0))
        return int(probe.getsockname()[1])


async def run_client(python: Path, port: int, *extra: str) -> dict[str, dict[str, object]]:
    result = await anyio.run_process(
        [str(python), str(CLIENT), str(port), "7", *extra], check=False
    )
    assert result.returncode == 0, result.stderr.decode()
    models: dict[str, dict[str, object]] = json.loads(result.stdout)["models"]
    return models


def same(ours: object, theirs: object) -> bool:
    if isinstance(ours, float) or isinstance(theirs, float):
        return (
            theirs is not None
            and ours is not None
            and math.isclose(
                float(ours),
                float(theirs),
                rel_tol=1e-6,
                abs_tol=1e-9,  # type: ignore[arg-type]
            )
        )
    return ours == theirs or (isinstance(ours, int) and str(ours) == str(theirs))


async def test_pysunspec2_reads_the_device_aiortu_serves(
    models: SunSpecModels, sunspec_python: Path
) -> None:
    store = inverter(models)
    port = free_port()
    async with aiortu.serve(f"tcp://127.0.0.1:{port}", {7: store}):
        theirs = await run_client(sunspec_python, port)
        async with aiortu.open_master(f"tcp://127.0.0.1:{port}", timeout=2.0) as master:
            found = await aiortu.walk_sunspec(master, 7, models=models)
            assert found is not None
            readings = await aiortu.Device(master, 7, found.profile).read()
    assert sorted(theirs) == ["1", "103", "160"]
    compared = 0
    for model_id, points in theirs.items():
        for name, value in points.items():
            if name.startswith("Pad"):
                continue
            reading = readings[f"m{model_id}.{name}"]
            ours = reading.value
            if reading.point.type.value in ("enum", "bitfield") and ours is not None:
                ours = reading.raw  # pysunspec2 gives enums and bitfields as numbers
            assert same(ours, value), (model_id, name, ours, value)
            compared += 1
    assert compared == sum(len(p) for p in theirs.values()) - 1  # all but model 1's pad
    assert theirs["103"]["W"] == 15000
    assert theirs["1"]["Mn"] == "aiortu"


async def test_pysunspec2_writes_a_point_aiortu_serves(
    models: SunSpecModels, sunspec_python: Path
) -> None:
    store = inverter(models)
    port = free_port()
    async with aiortu.serve(f"tcp://127.0.0.1:{port}", {7: store}):
        await run_client(sunspec_python, port, "1", "DA", "42")
    assert store.value("m1.DA") == 42


async def test_the_shipped_sunspec_inverter_walks_to_its_own_points(
    models: SunSpecModels,
) -> None:
    shipped = load_profile(SHIPPED / "sunspec-inverter.toml")
    async with line({3: aiortu.ProfileStore(shipped)}) as master:
        found = await aiortu.walk_sunspec(master, 3, models=models)
        assert found is not None
        walked = await aiortu.Device(master, 3, found.profile).read()
        direct = await aiortu.Device(master, 3, shipped).read()
    assert {n: r.value for n, r in walked.items()} == {
        n: r.value for n, r in direct.items() if not n.startswith("sunspec.")
    } | {"sunspec.marker": 0x53756E53}


def test_the_peer_is_pysunspec2_itself(sunspec_python: Path) -> None:
    version = subprocess.run(
        [str(sunspec_python), "-m", "pip", "show", "pysunspec2"],
        capture_output=True,
        text=True,
        check=True,
    ).stdout
    assert "Name: pysunspec2" in version

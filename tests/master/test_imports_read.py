"""Imported profiles read the values their sources mean: a simulated device is read through
the imported profile by aiortu and, independently, by pymodbus's client decoding each register
as the Home Assistant entity or the evcc register says (pymodbus's own conversions, the swaps
and scales of the source file), over Modbus TCP on loopback."""

from __future__ import annotations

import math
import random
import socket
from pathlib import Path
from typing import Any

import pytest
import yaml
from pymodbus.client import AsyncModbusTcpClient

import aiortu
from aiortu.core.model import (
    PointType,
    Profile,
    Table,
    profile_from_evcc,
    profiles_from_home_assistant,
)

pytestmark = [pytest.mark.interop, pytest.mark.timeout(60)]

EXAMPLES = Path(__file__).parents[2] / "examples" / "imports"
TYPES = AsyncModbusTcpClient.DATATYPE
COUNTS = {
    "int16": 1,
    "uint16": 1,
    "int32": 2,
    "uint32": 2,
    "float32": 2,
    "int64": 4,
    "uint64": 4,
    "float64": 4,
}


def free_port() -> int:
    with socket.socket() as probe:
        probe.bind(("127.0.0.1", 0))
        return int(probe.getsockname()[1])


def randomised(profile: Profile, rng: random.Random) -> aiortu.ProfileStore:
    """The profile's device with every point at random raw contents."""
    store = aiortu.ProfileStore(profile)
    for point in profile.points:
        if point.table.is_bit:
            store.set(point.table, point.address, [rng.randrange(2)])
        elif point.type is PointType.STRING:
            text = "".join(rng.choice("ABCXYZ0123.") for _ in range(2 * point.size))
            store.set_value(point.name, text)
        elif point.type is PointType.ENUM:
            store.set(point.table, point.address, [rng.choice(list(point.values))])
        else:
            registers = [rng.randrange(0x10000) for _ in range(point.size)]
            if point.type in (PointType.F32, PointType.F64):
                store.set_value(point.name, rng.uniform(-1e4, 1e4))  # no NaN to compare
                continue
            store.set(point.table, point.address, registers)
    return store


async def registers(
    client: AsyncModbusTcpClient, unit: int, table: str, address: int, count: int
) -> list[int]:
    read = client.read_input_registers if table == "input" else client.read_holding_registers
    reply = await read(address, count=count, device_id=unit)
    assert not reply.isError(), reply
    return list(reply.registers)


def home_assistant_value(entity: dict[str, Any], raw: list[int]) -> object:
    """What Home Assistant makes of `raw`: its swaps, pymodbus's conversion, scale, offset."""
    swap = entity.get("swap", "none")
    if swap in ("byte", "word_byte"):
        raw = [((r & 0xFF) << 8) | (r >> 8) for r in raw]
    if swap in ("word", "word_byte"):
        raw = raw[::-1]
    data_type = entity.get("data_type", "int16")
    value = AsyncModbusTcpClient.convert_from_registers(raw, getattr(TYPES, data_type.upper()))
    if data_type == "string":
        return str(value).rstrip("\x00 ")
    return value * entity.get("scale", 1) + entity.get("offset", 0)


def close(ours: object, theirs: object) -> bool:
    if isinstance(ours, float) or isinstance(theirs, float):
        return math.isclose(float(ours), float(theirs), rel_tol=1e-6, abs_tol=1e-6)  # type: ignore[arg-type]
    return ours == theirs


@pytest.mark.parametrize("seed", [1, 2, 3])
async def test_home_assistant_sensors_read_the_same_both_ways(seed: int) -> None:
    document = yaml.safe_load((EXAMPLES / "home-assistant-modbus.yaml").read_text())
    profiles = profiles_from_home_assistant(document, "configuration.yaml")
    rng = random.Random(seed)
    stores = {unit: randomised(profile, rng) for (_, unit), profile in profiles.items()}
    port = free_port()
    async with aiortu.serve(f"tcp://127.0.0.1:{port}", stores):
        async with aiortu.open_master(f"tcp://127.0.0.1:{port}", timeout=2.0) as master:
            ours = {
                unit: await aiortu.Device(master, unit, profile).read()
                for (_, unit), profile in profiles.items()
            }
        client = AsyncModbusTcpClient("127.0.0.1", port=port)
        await client.connect()
        compared = 0
        try:
            hub = document["modbus"][0]
            for entity in hub["sensors"]:
                count = entity.get("count") or COUNTS[entity.get("data_type", "int16")]
                raw = await registers(
                    client,
                    entity["slave"],
                    entity.get("input_type", "holding"),
                    entity["address"],
                    count,
                )
                theirs = home_assistant_value(entity, raw)
                name = entity["name"].lower().replace(" ", "_")
                reading = ours[entity["slave"]][name]
                assert close(reading.value, theirs), (seed, name, reading.value, theirs)
                compared += 1
            for entity in hub["binary_sensors"]:
                reply = await client.read_discrete_inputs(
                    entity["address"], count=1, device_id=entity["slave"]
                )
                name = entity["name"].lower().replace(" ", "_")
                assert ours[entity["slave"]][name].value is reply.bits[0], (seed, name)
                compared += 1
        finally:
            client.close()
    assert compared == 10


@pytest.mark.parametrize("seed", [1, 2])
async def test_an_evcc_meter_reads_the_same_both_ways(seed: int) -> None:
    template = yaml.safe_load((EXAMPLES / "evcc-meter.yaml").read_text())
    profile = profile_from_evcc(template, yaml.safe_load, params={"usage": "grid"}).profile
    store = randomised(profile, random.Random(seed))
    rendered = yaml.safe_load(
        aiortu.core.model.render_evcc(template["render"], {"usage": "grid", "phases": "true"})
    )
    port = free_port()
    async with aiortu.serve(f"tcp://127.0.0.1:{port}", {1: store}):
        async with aiortu.open_master(f"tcp://127.0.0.1:{port}", timeout=2.0) as master:
            ours = await aiortu.Device(master, 1, profile).read()
        client = AsyncModbusTcpClient("127.0.0.1", port=port)
        await client.connect()
        try:
            for key, plugins in rendered.items():
                if key in ("type", "soc"):
                    continue
                listed = plugins if isinstance(plugins, list) else [plugins]
                for index, plugin in enumerate(listed):
                    register = plugin["register"]
                    decode = register["decode"]
                    swapped = decode.endswith("s")
                    kind = decode.removesuffix("s")
                    raw = await registers(
                        client, 1, register["type"], register["address"], COUNTS[kind]
                    )
                    value = AsyncModbusTcpClient.convert_from_registers(
                        raw, getattr(TYPES, kind.upper()), word_order="little" if swapped else "big"
                    )
                    theirs = value * plugin.get("scale", 1)
                    name = (
                        f"{key.removesuffix('s')}_l{index + 1}"
                        if isinstance(plugins, list)
                        else key
                    )
                    assert close(ours[name].value, theirs), (seed, name, ours[name].value, theirs)
        finally:
            client.close()
    assert store.profile.point("voltage_l1").table is Table.INPUT_REGISTERS

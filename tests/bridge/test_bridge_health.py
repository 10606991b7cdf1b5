"""Availability from the units' health: a unit that never answers turns offline on its own; a
line lost (its Modbus TCP server gone) turns its devices offline, and back online when it is
back; Sparkplug says the same with DDEATH and DBIRTH."""

from __future__ import annotations

import contextlib
from collections.abc import AsyncIterator

import anyio
import pytest

from aiortu.bridge import Bridge, parse_config
from aiortu.core.model import load_profile
from aiortu.slave import ModbusTcpServer, ProfileStore
from tests.bridge.helpers import HEAT_PUMP, fast_heat_pump
from tests.bridge.mosquitto import Mosquitto, Subscriber, free_port
from tests.bridge.test_bridge_broker import _of, _sparkplug, until

pytestmark = pytest.mark.timeout(60)


def _config(url: str, port: int, layout: str) -> str:
    devices = "".join(
        f'[[line.device]]\nname = "hp-{u}"\nunit = {u}\nprofile = "{fast_heat_pump()}"\n'
        for u in (1, 3)
    )
    return (
        f'[broker]\nurl = "{url}"\nkeepalive = 5\n[topics]\nlayout = "{layout}"\nnode = "t"\n'
        f'[[line]]\nport = "tcp://127.0.0.1:{port}"\ntimeout = 0.2\nretries = 0\n'
        f"offline_after = 2\nprobe_interval = 0.5\n{devices}"
    )


class _Devices:
    """Unit 1 served over Modbus TCP on `port`, unit 3 never answering; `stop` and `start`."""

    def __init__(self, port: int) -> None:
        self.port = port
        self.server = ModbusTcpServer(
            {1: ProfileStore(load_profile(HEAT_PUMP))}, answer_unknown_units=False
        )
        self.scope: anyio.CancelScope | None = None

    async def start(self, tasks: anyio.abc.TaskGroup) -> None:
        listener = await anyio.create_tcp_listener(local_host="127.0.0.1", local_port=self.port)
        self.scope = anyio.CancelScope()

        async def serve() -> None:
            with self.scope:  # type: ignore[union-attr]
                await self.server.serve(listener)

        tasks.start_soon(serve)

    def stop(self) -> None:
        assert self.scope is not None
        self.scope.cancel()


@contextlib.asynccontextmanager
async def _served() -> AsyncIterator[tuple[_Devices, anyio.abc.TaskGroup]]:
    async with anyio.create_task_group() as tasks:
        served = _Devices(free_port())
        await served.start(tasks)
        yield served, tasks
        tasks.cancel_scope.cancel()


async def test_unit_health_is_each_device_s_availability(mosquitto: Mosquitto) -> None:
    subscriber = Subscriber(mosquitto.port, ["aiortu/#"])
    try:
        async with (
            _served() as (served, tasks),
            Bridge(parse_config(_config(mosquitto.url, served.port, "home-assistant"))),
        ):
            # Availability starts offline; health says when the unit has been found silent.
            await until(lambda: subscriber.on("aiortu/hp-3/health")[-1:] == [b"offline"])
            assert subscriber.on("aiortu/hp-3/availability")[-1] == b"offline"
            assert subscriber.on("aiortu/hp-1/availability")[-1] == b"online"
            assert subscriber.on("aiortu/hp-1/power") == [b"1800.0"]
            served.stop()
            await until(lambda: subscriber.on("aiortu/hp-1/availability")[-1:] == [b"offline"])
            await served.start(tasks)
            await until(lambda: subscriber.on("aiortu/hp-1/availability")[-1:] == [b"online"], 20)
            assert subscriber.on("aiortu/hp-3/availability")[-1] == b"offline"
    finally:
        subscriber.close()


async def test_sparkplug_device_death_and_rebirth(mosquitto: Mosquitto) -> None:
    subscriber = Subscriber(mosquitto.port, ["spBv1.0/#"])
    node = "spBv1.0/aiortu/{}/t/hp-1"
    try:
        async with (
            _served() as (served, tasks),
            Bridge(parse_config(_config(mosquitto.url, served.port, "sparkplug"))),
        ):
            await until(lambda: _of(_sparkplug(subscriber), node.format("DBIRTH")))
            served.stop()
            await until(lambda: _of(_sparkplug(subscriber), node.format("DDEATH")))
            await served.start(tasks)
            await until(lambda: len(_of(_sparkplug(subscriber), node.format("DBIRTH"))) == 2, 20)
        messages = _sparkplug(subscriber)
        # The unit that never answered was never born, so never died.
        assert not [t for t, _ in messages if t.endswith("/hp-3")]
        seqs = [p.seq for t, p in messages if "/NDEATH/" not in t]
        assert seqs == list(range(len(seqs)))
    finally:
        subscriber.close()

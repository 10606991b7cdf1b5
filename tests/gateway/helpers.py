"""A virtual line with aiortu slaves, a master on it, and a gateway in front of the master.

Its clients connect over TCP on 127.0.0.1 (`client`), or over an in-memory stream straight to
the gateway's `serve_connection` (`memory_client`, with `line(listen=())`): no socket, so that
the test runs on a virtual clock (`tests/virtual_clock.py`)."""

from __future__ import annotations

import functools
from collections.abc import AsyncIterator, Mapping
from contextlib import AsyncExitStack, asynccontextmanager
from dataclasses import dataclass
from typing import Any

import anyio

from aiortu.core.serial import LineSettings
from aiortu.gateway import Gateway, Listen, gateway
from aiortu.master import Master
from aiortu.slave import MemoryStore, Slave
from aiortu.testing import VirtualBus, VirtualEndpoint, virtual_pair
from tests.slave.tcp_helpers import UNIT, TcpClient, device

__all__ = (
    "UNIT",
    "Line",
    "TcpClient",
    "client",
    "device",
    "line",
    "memory_client",
    "memory_stream",
)


@dataclass
class Line:
    bus: VirtualBus
    slave: Slave
    master: Master
    gateway: Gateway

    @property
    def messages(self) -> int:
        """Requests the slave saw on the line."""
        return self.slave.counters.server_message_count


@asynccontextmanager
async def line(
    units: Mapping[int, MemoryStore] | None = None,
    *,
    master_options: Mapping[str, Any] | None = None,
    listen: tuple[str | Listen, ...] = ("tcp://127.0.0.1:0",),
    **gateway_options: Any,
) -> AsyncIterator[Line]:
    """Unit 17 (`device()`) on a fast virtual line, and a gateway on 127.0.0.1, a free port."""
    bus = VirtualBus(2)
    slave = Slave(bus.endpoints[1], units or {UNIT: device()}, frame_gap=0.0, frame_silence=0.005)
    options: dict[str, Any] = {
        "frame_gap": 0, "timeout": 0.2, "retries": 0, "turnaround_delay": 0.005,
        "late_reply_guard": 0.005, "fail_fast_offline": True, "reconnect_fail_fast": True,
    }  # fmt: skip
    options.update(master_options or {})
    master = Master(bus.endpoints[0], LineSettings(1_000_000), **options)
    async with AsyncExitStack() as stack:
        await stack.enter_async_context(slave)
        await stack.enter_async_context(master)
        await anyio.sleep(0.02)  # both receivers past their first silence
        server = await stack.enter_async_context(gateway(master, listen, **gateway_options))
        yield Line(bus, slave, master, server)


@asynccontextmanager
async def client(server: Gateway) -> AsyncIterator[TcpClient]:
    stream = await anyio.connect_tcp("127.0.0.1", server.port)
    async with stream:
        yield TcpClient(stream)


@asynccontextmanager
async def memory_stream(server: Gateway, **serve_options: Any) -> AsyncIterator[VirtualEndpoint]:
    """A client's end of an in-memory stream whose far end `server` serves as it serves an
    accepted socket (`serve_options` are `serve_connection`'s: `rtu_framing=True`, ...)."""
    near, far = virtual_pair()
    async with anyio.create_task_group() as tasks:
        tasks.start_soon(functools.partial(server.serve_connection, far, **serve_options))
        async with near:
            yield near
        tasks.cancel_scope.cancel()


@asynccontextmanager
async def memory_client(server: Gateway) -> AsyncIterator[TcpClient]:
    """A Modbus TCP client of `server` over an in-memory stream (see `memory_stream`)."""
    async with memory_stream(server) as stream:
        yield TcpClient(stream)

"""Each layout's own list of its topics (what the configuration's length check reads) against
what the bridge does: run on a Modbus TCP line, against a scripted broker that records every
last will, subscription and PUBLISH, with commands on every point and the line lost at the
end, every topic the bridge uses is in the list and the list holds nothing it never uses."""

from __future__ import annotations

import contextlib
import struct
import time
from collections.abc import AsyncIterator
from dataclasses import dataclass, field

import anyio
import anyio.abc
import pytest

from aiortu.bridge import (
    Bridge,
    DataType,
    LayoutTopic,
    Metric,
    SparkplugPayload,
    encode_payload,
    parse_config,
)
from aiortu.bridge._layouts import make_layout
from aiortu.bridge._packets import (
    Packet,
    PacketReader,
    PacketType,
    Publish,
    puback_packet,
    publish_packet,
)
from aiortu.bridge._sparkplug import REBIRTH
from aiortu.bridge._state import device_states
from aiortu.core.model import load_profile
from aiortu.master import UnitState
from aiortu.slave import ModbusTcpServer, ProfileStore
from tests.bridge.helpers import HEAT_PUMP, fast_heat_pump
from tests.bridge.mosquitto import free_port
from tests.bridge.test_bridge_broker import until

pytestmark = pytest.mark.timeout(60)

_PAYLOADS = {"mode": b"cool", "setpoint": b"30", "pump": b"true"}
"""A value each writable point of the heat pump takes, as a plain payload (others: `1`)."""
_METRICS: dict[str, str | float] = {"mode": "cool", "setpoint": 30.0, "pump": True}
"""The same as Sparkplug metrics' values (others: `"1"`)."""
_NBIRTH = "spBv1.0/aiortu/NBIRTH/t"


def _matches(pattern: str, topic: str) -> bool:
    """Whether MQTT topic filter `pattern` (`+`, `#`) matches `topic`."""
    want, have = pattern.split("/"), topic.split("/")
    for n, level in enumerate(want):
        if level == "#":
            return True
        if n >= len(have) or level not in ("+", have[n]):
            return False
    return len(want) == len(have)


def _string(body: bytes, at: int) -> tuple[str, int]:
    """The MQTT string at `at` in `body`, and where what follows it starts."""
    (length,) = struct.unpack_from(">H", body, at)
    return body[at + 2 : at + 2 + length].decode(), at + 2 + length


@dataclass
class _Broker:
    """A scripted broker for one bridge: it records the topic of each CONNECT's last will,
    each SUBSCRIBE's filters and each PUBLISH's topic, answers what needs an answer, and
    delivers the commands it is given when a subscription matches, as a broker would."""

    wills: set[str] = field(default_factory=set)
    filters: set[str] = field(default_factory=set)
    published: list[str] = field(default_factory=list)
    stream: anyio.abc.ByteStream | None = None
    sending: anyio.Lock = field(default_factory=anyio.Lock)
    """One send at a time: the answers and the commands share the stream."""

    async def serve(self, stream: anyio.abc.ByteStream) -> None:
        self.stream = stream
        reader = PacketReader()
        with contextlib.suppress(anyio.EndOfStream, anyio.BrokenResourceError):
            while True:
                for packet in reader.feed(await stream.receive()):
                    await self._take(packet)

    async def send(self, data: bytes) -> None:
        assert self.stream is not None
        async with self.sending:
            await self.stream.send(data)

    async def _take(self, packet: Packet) -> None:
        body = packet.body
        if packet.type == PacketType.CONNECT:
            if body[7] & 0x04:  # the will flag: its topic follows the client id
                self.wills.add(_string(body, _string(body, 10)[1])[0])
            await self.send(bytes((0x20, 2, 0, 0)))
        elif packet.type == PacketType.SUBSCRIBE:
            at, granted = 2, b""
            while at < len(body):
                pattern, at = _string(body, at)
                self.filters.add(pattern)
                at, granted = at + 1, granted + b"\x01"
            await self.send(bytes((0x90, 2 + len(granted))) + body[:2] + granted)
        elif packet.type == PacketType.PUBLISH:
            publish = Publish.parse(packet)
            self.published.append(publish.topic)
            if publish.packet_id is not None:
                await self.send(puback_packet(publish.packet_id))
        elif packet.type == PacketType.PINGREQ:
            await self.send(bytes((0xD0, 0)))

    async def command(self, topic: str, payload: bytes) -> bool:
        """Deliver `payload` on `topic` if a subscription matches; whether it did."""
        if self.stream is None or not any(_matches(f, topic) for f in self.filters):
            return False
        await self.send(publish_packet(topic, payload))
        return True


@contextlib.asynccontextmanager
async def _line(port: int) -> AsyncIterator[anyio.CancelScope]:
    """Units 1 and 2 (the heat pump example) served over Modbus TCP on `port`, until the
    scope yielded is cancelled (the line lost)."""
    stores = {unit: ProfileStore(load_profile(HEAT_PUMP)) for unit in (1, 2)}
    server = ModbusTcpServer(stores, answer_unknown_units=False)
    listener = await anyio.create_tcp_listener(local_host="127.0.0.1", local_port=port)
    async with anyio.create_task_group() as tasks:
        scope = anyio.CancelScope()

        async def serve() -> None:
            with scope:
                await server.serve(listener)

        tasks.start_soon(serve)
        yield scope
        tasks.cancel_scope.cancel()


def _config(layout: str, broker: int, line: int) -> str:
    """hp-1 with every point (read-only and writable), hp-2 with read-only points only,
    published every poll (Sparkplug: DDATA without a write)."""
    profile = fast_heat_pump()
    return (
        f'[broker]\nurl = "mqtt://127.0.0.1:{broker}"\nkeepalive = 5\n'
        f'[topics]\nlayout = "{layout}"\nnode = "t"\n'
        f'[[line]]\nport = "tcp://127.0.0.1:{line}"\ntimeout = 0.2\nretries = 0\n'
        f"offline_after = 2\nprobe_interval = 0.5\n"
        f'[[line.device]]\nname = "hp-1"\nunit = 1\nprofile = "{profile}"\n'
        f'[[line.device]]\nname = "hp-2"\nunit = 2\nprofile = "{profile}"\n'
        f'points = ["power", "energy", "serial"]\npublish = "every"\n'
    )


def _commands(bridge: Bridge) -> list[tuple[str, bytes]]:
    """A command on every point of every device (a valid value for the writable ones); for
    Sparkplug a rebirth too."""
    names = [(state.name, point.name) for state in bridge.devices for point in state.points]
    if bridge.config.topics.layout != "sparkplug":
        return [(f"aiortu/{d}/{p}/set", _PAYLOADS.get(p, b"1")) for d, p in names]
    stamp = int(time.time() * 1000)
    rebirth = (Metric(REBIRTH, DataType.BOOLEAN, True),)
    commands = [("spBv1.0/aiortu/NCMD/t", encode_payload(SparkplugPayload(stamp, rebirth)))]
    for device, point in names:
        value = _METRICS.get(point, "1")
        kind = {str: DataType.STRING, float: DataType.DOUBLE, bool: DataType.BOOLEAN}
        metric = Metric(point, kind[type(value)], value)
        payload = encode_payload(SparkplugPayload(stamp, (metric,)))
        commands.append((f"spBv1.0/aiortu/DCMD/t/{device}", payload))
    return commands


async def _carried_out(bridge: Bridge, broker: _Broker, topic: str, payload: bytes) -> bool:
    """Send one command; whether the bridge did it (a write, or the births again) rather
    than refuse it (a read-only point) or never get it (no subscription matches)."""
    stats = bridge.stats
    before = (stats.writes, stats.write_errors, broker.published.count(_NBIRTH))
    if not await broker.command(topic, payload):
        return False

    def answered() -> bool:
        return (stats.writes, stats.write_errors, broker.published.count(_NBIRTH)) != before

    await until(answered, 5)
    return stats.writes > before[0] or broker.published.count(_NBIRTH) > before[2]


async def _run(layout: str) -> tuple[list[LayoutTopic], _Broker, set[str]]:
    """The layout's list, what the broker saw, and the command topics the bridge acted on."""
    broker, done = _Broker(), set[str]()
    listener = await anyio.create_tcp_listener(local_host="127.0.0.1", local_port=0)
    port = listener.extra(anyio.abc.SocketAttribute.local_port)
    line_port = free_port()
    async with anyio.create_task_group() as tasks, _line(line_port) as line:
        tasks.start_soon(listener.serve, broker.serve)
        config = parse_config(_config(layout, port, line_port), "test.toml")
        listed = make_layout(config.topics).every_topic(device_states(config))
        async with Bridge(config) as bridge:
            await until(lambda: all(s.complete for s in bridge.devices) and not bridge.outbox)
            await until(lambda: bool(broker.filters))
            for topic, payload in _commands(bridge):
                if await _carried_out(bridge, broker, topic, payload):
                    done.add(topic)
            line.cancel()
            await until(lambda: all(s.health is UnitState.OFFLINE for s in bridge.devices))
            expected = {t.topic for t in listed if not t.command}
            with contextlib.suppress(TimeoutError):  # what is missing is shown below
                await until(lambda: expected <= broker.wills | set(broker.published), 5)
        tasks.cancel_scope.cancel()
    return listed, broker, done


@pytest.mark.parametrize("layout", ["plain", "home-assistant", "sparkplug"])
async def test_every_topic_the_bridge_uses_is_in_its_layouts_list(layout: str) -> None:
    listed, broker, done = await _run(layout)
    sent = broker.wills | set(broker.published)
    publish = {t.topic for t in listed if not t.command}
    commands = {t.topic for t in listed if t.command}
    assert sent - publish == set(), "published, not listed"
    assert publish - sent == set(), "listed, never published"
    assert done - commands == set(), "a command carried out on a topic not listed"
    assert commands - done == set(), "listed, no command carried out on it"
    assert broker.filters
    for pattern in broker.filters:
        assert any(_matches(pattern, t) for t in commands), f"{pattern} covers no listed topic"
    for topic in commands:
        assert any(_matches(f, topic) for f in broker.filters), f"{topic} is not subscribed"

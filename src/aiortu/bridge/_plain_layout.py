"""The plain topic layout, with or without Home Assistant discovery.

Under the prefix (`aiortu` by default), for the bridge named NODE and each device DEVICE:

| topic | payload |
|---|---|
| `PREFIX/bridge/NODE/status` | `online`, or `offline` (the last will), retained |
| `PREFIX/bridge/NODE/dropped` | messages dropped while the broker was away, retained |
| `PREFIX/DEVICE/POINT` | the point's value (retained unless the layout says not) |
| `PREFIX/DEVICE/POINT/set` | a write of a writable point (the bridge subscribes) |
| `PREFIX/DEVICE/availability` | `online` or `offline`, from the unit's health, retained |
| `PREFIX/DEVICE/health` | `online`, `suspect` or `offline`, retained |
| `PREFIX/DEVICE/error` | a refused or failed write: JSON with the point, payload and reason |
"""

from __future__ import annotations

import json

from aiortu.bridge._config import TopicLayout
from aiortu.bridge._discovery import discovery_config
from aiortu.bridge._outbox import Message
from aiortu.bridge._packets import Publish
from aiortu.bridge._payloads import format_value
from aiortu.bridge._state import Command, DeviceState
from aiortu.bridge._topics import (
    COMMAND,
    LayoutTopic,
    bridge_topic,
    device_topic,
    discovery_object_id,
    discovery_topic,
    entity_component,
    point_topic,
)
from aiortu.core.model import ProfilePoint, Value
from aiortu.master import UnitState

__all__ = ("PlainLayout",)


class PlainLayout:
    """The plain layout of `topics` (see the module docstring); with `discovery`, Home
    Assistant's discovery configs too."""

    def __init__(self, topics: TopicLayout, *, discovery: bool) -> None:
        self.topics = topics
        self.discovery = discovery
        self.prefix = topics.prefix
        self.status_topic = bridge_topic(self.prefix, topics.node, "status")
        self.dropped_topic = bridge_topic(self.prefix, topics.node, "dropped")
        self._command_prefixes: dict[str, DeviceState] = {}
        self._states: dict[str, dict[str, tuple[str, ProfilePoint]]] = {}

    def will(self) -> Message | None:
        """The bridge's status `offline`, retained."""
        return Message(self.status_topic, b"offline", qos=1, retain=True)

    def subscriptions(self) -> list[str]:
        """The command topics of the devices with writable points."""
        return [point_topic(self.prefix, name, "+") + COMMAND for name in self._command_prefixes]

    def every_topic(self, devices: list[DeviceState]) -> list[LayoutTopic]:
        """The bridge's status and dropped count; each device's error topic if it has writable
        points (the others take no commands), its availability and health; each point's
        command topic if writable (first: the longer, which the length check names), its
        topic, and its discovery topic."""
        listed = [LayoutTopic(self.status_topic), LayoutTopic(self.dropped_topic)]
        for device in devices:
            name = device.name
            leaves = (["error"] if device.writable else []) + ["availability", "health"]
            listed += [LayoutTopic(device_topic(self.prefix, name, leaf), name) for leaf in leaves]
            for point in device.points:
                state = point_topic(self.prefix, name, point.name)
                if point.writable:
                    listed.append(LayoutTopic(state + COMMAND, name, point.name, command=True))
                listed.append(LayoutTopic(state, name, point.name))
                if self.discovery:
                    topic = discovery_topic(
                        self.topics.discovery_prefix, entity_component(point), self.topics.node,
                        discovery_object_id(name, point.name),
                    )  # fmt: skip
                    listed.append(LayoutTopic(topic, name, point.name))
        return listed

    def bind(self, devices: list[DeviceState]) -> None:
        """Learn the devices (before the first connection)."""
        self._command_prefixes = {d.name: d for d in devices if d.writable}
        # Made once: each point's state topic (the same string each poll, its hash kept for
        # the session's cache of encoded topics) and the point that formats its value.
        self._states = {
            d.name: {p.name: (point_topic(self.prefix, d.name, p.name), p) for p in d.points}
            for d in devices
        }

    def on_connect(self, devices: list[DeviceState], dropped: int, now: float) -> list[Message]:
        """Status, the dropped count, discovery, and each device's availability and values."""
        qos = self.topics.qos
        messages = [
            Message(self.status_topic, b"online", qos, True, now),
            Message(self.dropped_topic, str(dropped).encode(), qos, True, now),
        ]
        for device in devices:
            if self.discovery:
                messages += self._discovery(device, now)
            messages += self.health(device, now)
        return messages

    def _discovery(self, device: DeviceState, now: float) -> list[Message]:
        messages = []
        availability = device_topic(self.prefix, device.name, "availability")
        for point in device.points:
            state = point_topic(self.prefix, device.name, point.name)
            topic, payload = discovery_config(
                device, point, node=self.topics.node, qos=self.topics.qos,
                discovery_prefix=self.topics.discovery_prefix,
                topics={"state": state, "command": state + COMMAND,
                        "availability": availability, "status": self.status_topic},
            )  # fmt: skip
            messages.append(Message(topic, payload, self.topics.qos, True, now))
        return messages

    def values(self, device: DeviceState, changed: dict[str, Value], now: float) -> list[Message]:
        """One message per value, on the point's topic."""
        states = self._states[device.name]
        qos, retain = self.topics.qos, self.topics.retain
        messages = []
        for name, value in changed.items():
            topic, point = states[name]
            messages.append(Message(topic, format_value(point, value), qos, retain, now))
        return messages

    def health(self, device: DeviceState, now: float) -> list[Message]:
        """The device's availability and its three-state health."""
        available = b"offline" if device.health is UnitState.OFFLINE else b"online"
        availability = device_topic(self.prefix, device.name, "availability")
        health = device_topic(self.prefix, device.name, "health")
        qos = self.topics.qos
        return [
            Message(availability, available, qos, True, now),
            Message(health, device.health.value.encode(), qos, True, now),
        ]

    def command(self, publish: Publish, devices: list[DeviceState], now: float,
                ) -> tuple[list[Command], list[Message]]:  # fmt: skip
        """A write from `PREFIX/DEVICE/POINT/set`."""
        parts = publish.topic[len(self.prefix) + 1 :].split("/")
        if len(parts) != 3 or parts[2] != "set" or parts[0] not in self._command_prefixes:
            return [], []
        return [Command(parts[0], parts[1], publish.payload)], []

    def error(self, device: str, point: str, payload: bytes, reason: str, now: float) -> Message:
        """`PREFIX/DEVICE/error`, not retained."""
        body = {"point": point, "payload": payload.decode("utf-8", "replace"), "error": reason}
        return Message(device_topic(self.prefix, device, "error"), json.dumps(body).encode(),
                       self.topics.qos, False, now)  # fmt: skip

    def prepare(self, message: Message) -> bytes:
        """The payload as made."""
        return message.payload

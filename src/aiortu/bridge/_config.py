"""The bridge's configuration: its lines, the devices on each, the broker, the topic layout
and the buffer, as records (`_config_file` reads them from TOML and checks them).
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

from aiortu.bridge._broker import Broker
from aiortu.core.model import Profile

__all__ = (
    "LAYOUTS",
    "VIRTUAL_PORT",
    "BridgeConfig",
    "DeviceConfig",
    "LineConfig",
    "TopicLayout",
)

LAYOUTS = ("home-assistant", "plain", "sparkplug")
"""The topic layouts: plain topics, the same with Home Assistant discovery, Sparkplug B."""

VIRTUAL_PORT = "virtual"
"""The port of a simulated line: the devices answer from their profiles, in the bridge's
process, on a virtual line of `aiortu.testing` (demos, tests, a fleet on one machine)."""


@dataclass(frozen=True, slots=True)
class DeviceConfig:
    """One device on a line: its `name` (unique in the bridge: its topics), `unit`,
    `profile`, whether its points are published on change (`publish = "change"`) or every
    poll (`"every"`), the points published every poll whatever that says (`every_poll`),
    and the points published (`points`; None: all)."""

    name: str
    unit: int
    profile: Profile
    publish: str = "change"
    every_poll: frozenset[str] = frozenset()
    points: tuple[str, ...] | None = None


@dataclass(frozen=True, slots=True)
class LineConfig:
    """One line: its `port` (a serial device, `tcp://`, `rtu+tcp://`, a gateway's listen URL,
    or [`VIRTUAL_PORT`][aiortu.bridge.VIRTUAL_PORT]), the master's `options` (`baudrate`,
    `timeout`, `offline_after`, ...), and its `devices`."""

    port: str
    devices: tuple[DeviceConfig, ...]
    options: Mapping[str, Any] = field(default_factory=dict)


@dataclass(frozen=True, slots=True)
class TopicLayout:
    """Where the bridge publishes: the `layout` (one of [`LAYOUTS`][aiortu.bridge.LAYOUTS]),
    the `prefix` of the plain topics, Home Assistant's `discovery_prefix`, `retain` for the
    state topics, the `qos` of everything but Sparkplug's (QoS 0 by its specification), the
    bridge's `node` name (its status topic, its Sparkplug edge node id) and Sparkplug's
    `group`."""

    layout: str = "home-assistant"
    prefix: str = "aiortu"
    discovery_prefix: str = "homeassistant"
    retain: bool = True
    qos: int = 1
    node: str = "bridge"
    group: str = "aiortu"


@dataclass(frozen=True, slots=True)
class BridgeConfig:
    """A whole bridge: `broker`, `topics`, `lines`, and the outbox's bound
    (`max_messages`, `max_bytes`) while the broker is away."""

    broker: Broker
    lines: tuple[LineConfig, ...]
    topics: TopicLayout = field(default_factory=TopicLayout)
    max_messages: int = 100_000
    max_bytes: int = 64 * 1024 * 1024

    def devices(self) -> list[DeviceConfig]:
        """Every device of every line."""
        return [device for line in self.lines for device in line.devices]

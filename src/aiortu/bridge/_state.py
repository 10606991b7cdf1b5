"""What the bridge knows of each device, and what a topic layout turns into messages.

A [`DeviceState`][aiortu.bridge.DeviceState] holds a device's last published values and its
health; a layout ([`Layout`][aiortu.bridge.Layout]: plain topics with or without Home
Assistant discovery, or Sparkplug B) makes the messages for values, health changes,
connections and commands. The bridge decides what to publish and when; the layout only how.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Protocol

from aiortu.bridge._config import BridgeConfig, DeviceConfig
from aiortu.bridge._outbox import Message
from aiortu.bridge._packets import Publish
from aiortu.bridge._topics import LayoutTopic
from aiortu.core.model import ProfilePoint, Value
from aiortu.master import UnitState

__all__ = ("Command", "DeviceState", "Layout", "device_states")


@dataclass(slots=True)
class DeviceState:
    """A device as the bridge sees it: its `config`, the `points` it publishes, the `values`
    last published by name, its `health` (the master's view of its unit), and the points
    `seen`."""

    config: DeviceConfig
    points: tuple[ProfilePoint, ...]
    values: dict[str, Value] = field(default_factory=dict)
    health: UnitState = UnitState.ONLINE
    seen: set[str] = field(default_factory=set)
    """The points read at least once (with or without a value)."""
    published: frozenset[str] = field(init=False)
    """The names of `points`."""

    def __post_init__(self) -> None:
        self.published = frozenset(p.name for p in self.points)

    @property
    def complete(self) -> bool:
        """Whether every published point has been read once (each poll class polled)."""
        return len(self.seen) >= len(self.points)

    @property
    def name(self) -> str:
        """The device's name: its topics."""
        return self.config.name

    @property
    def writable(self) -> tuple[ProfilePoint, ...]:
        """The published points a command may write."""
        return tuple(p for p in self.points if p.writable)


def device_states(config: BridgeConfig) -> list[DeviceState]:
    """Each device of `config` before its first read, with the points it publishes: its
    profile's, or those its `points` names."""
    return [
        DeviceState(d, tuple(p for p in d.profile.points
                             if d.points is None or p.name in d.points))
        for d in config.devices()
    ]  # fmt: skip


@dataclass(frozen=True, slots=True)
class Command:
    """A write asked over MQTT: `point` of `device` from `payload` (text), or from a
    `value` already typed (a Sparkplug metric's)."""

    device: str
    point: str
    payload: bytes
    value: object = None
    typed: bool = False


class Layout(Protocol):
    """How a topic layout speaks (see the module docstring); every method returns the
    messages to publish, in order."""

    def bind(self, devices: list[DeviceState]) -> None:
        """Learn the devices (before the first connection)."""

    def will(self) -> Message | None:
        """The last will of the next connection."""

    def subscriptions(self) -> list[str]:
        """The topic filters of the commands."""

    def every_topic(self, devices: list[DeviceState]) -> list[LayoutTopic]:
        """Every topic this layout publishes on (its last will's too) or takes commands from,
        as [`LayoutTopic`][aiortu.bridge.LayoutTopic]s, for `devices`: the one list of them (the
        configuration checks their lengths)."""

    def on_connect(self, devices: list[DeviceState], dropped: int, now: float) -> list[Message]:
        """What to publish first on a new connection: the bridge's and the devices'
        availability, discovery or births, and the count of messages `dropped` so far."""

    def values(self, device: DeviceState, changed: dict[str, Value], now: float) -> list[Message]:
        """The `changed` values of `device` (and those published every poll)."""

    def health(self, device: DeviceState, now: float) -> list[Message]:
        """`device`'s health changed to `device.health`."""

    def command(self, publish: Publish, devices: list[DeviceState], now: float,
                ) -> tuple[list[Command], list[Message]]:  # fmt: skip
        """The writes `publish` asks for, and what to publish at once (a Sparkplug rebirth)."""

    def error(self, device: str, point: str, payload: bytes, reason: str, now: float) -> Message:
        """A refused or failed write, with its reason."""

    def prepare(self, message: Message) -> bytes:
        """The payload of `message` as it is sent now."""

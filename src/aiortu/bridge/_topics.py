"""The bridge's topic names, each made by one function from the configuration's names: the
layouts publish and subscribe on them, and each lists those it uses as
[`LayoutTopic`][aiortu.bridge.LayoutTopic]s, which the configuration is checked with against
MQTT's limit on a topic's length before anything is opened.

| function | topic |
|---|---|
| `bridge_topic` | `PREFIX/bridge/NODE/LEAF` (`status`, the last will; `dropped`) |
| `device_topic` | `PREFIX/DEVICE/LEAF` (`availability`, `health`, `error`) |
| `point_topic` | `PREFIX/DEVICE/POINT`, and with `/set` its command topic |
| `discovery_topic` | `DISCOVERY_PREFIX/COMPONENT/NODE/OBJECT_ID/config` (Home Assistant) |
| `sparkplug_topic` | `spBv1.0/GROUP/TYPE/NODE[/DEVICE]` |
"""

from __future__ import annotations

import re
from dataclasses import dataclass
from typing import Final

from aiortu.core.model import PointType, ProfilePoint

__all__ = (
    "COMMAND",
    "SPARKPLUG_NAMESPACE",
    "LayoutTopic",
    "bridge_topic",
    "device_topic",
    "discovery_object_id",
    "discovery_topic",
    "entity_component",
    "point_topic",
    "sparkplug_topic",
)

SPARKPLUG_NAMESPACE: Final = "spBv1.0"
"""The first level of every Sparkplug B topic."""

COMMAND: Final = "/set"
"""What follows a point's topic in its command topic."""


@dataclass(frozen=True, slots=True)
class LayoutTopic:
    """A topic a layout uses: it publishes on it, or (`command`) takes commands from it (a
    write of a writable point, a Sparkplug rebirth); the `device` and `point` it belongs to
    (empty: the bridge's own, or the device's own)."""

    topic: str
    device: str = ""
    point: str = ""
    command: bool = False


def bridge_topic(prefix: str, node: str, leaf: str) -> str:
    """The bridge's own topic `leaf` (`status`, `dropped`)."""
    return f"{prefix}/bridge/{node}/{leaf}"


def device_topic(prefix: str, device: str, leaf: str) -> str:
    """A device's topic `leaf` (`availability`, `health`, `error`)."""
    return f"{prefix}/{device}/{leaf}"


def point_topic(prefix: str, device: str, point: str) -> str:
    """The topic of a point's value (its command topic: this and `COMMAND`)."""
    return f"{prefix}/{device}/{point}"


def entity_component(point: ProfilePoint) -> str:
    """The Home Assistant entity platform of `point`."""
    if point.type is PointType.BOOL:
        return "switch" if point.writable else "binary_sensor"
    if point.writable and point.type is PointType.ENUM:
        return "select"
    if point.writable and point.type.is_number:
        return "number"
    return "sensor"


def discovery_object_id(device: str, point: str) -> str:
    """A point's Home Assistant object id: letters, digits and underscores (SunSpec names
    have dots)."""
    return re.sub(r"[^A-Za-z0-9_]", "_", f"{device}_{point}")


def discovery_topic(discovery_prefix: str, component: str, node: str, object_id: str) -> str:
    """The topic of a point's Home Assistant discovery config, by its `component`
    (`entity_component`) and `object_id` (`discovery_object_id`), which its config uses too."""
    return f"{discovery_prefix}/{component}/{node}/{object_id}/config"


def sparkplug_topic(group: str, kind: str, node: str, device: str | None = None) -> str:
    """A Sparkplug B topic of message type `kind` (`NBIRTH`, `DDATA`, ...)."""
    tail = f"/{device}" if device is not None else ""
    return f"{SPARKPLUG_NAMESPACE}/{group}/{kind}/{node}{tail}"

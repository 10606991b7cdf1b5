"""Home Assistant's MQTT discovery: one retained config per point, under the discovery
prefix, that makes it an entity of its device.

A point becomes a `sensor` (numbers, texts, flags; enums with their options), a
`binary_sensor` (read-only bits), a `number` (writable numbers, with the profile's limits),
a `select` (writable enums) or a `switch` (writable bits). Its config names the state topic,
the command topic when writable, the unit, the `device_class` and `state_class` from the
point's `meta`, and two availability topics that must both say `online`: the bridge's (its
last will says `offline`) and the device's (from its unit's health). The device block
(identifiers, manufacturer, model) groups a device's entities in Home Assistant.
"""

from __future__ import annotations

import json

from aiortu.bridge._state import DeviceState
from aiortu.bridge._topics import discovery_object_id, discovery_topic, entity_component
from aiortu.core.model import PointType, ProfilePoint

__all__ = ("discovery_config",)


def discovery_config(
    device: DeviceState, point: ProfilePoint, *, topics: dict[str, str], node: str,
    discovery_prefix: str, qos: int,
) -> tuple[str, bytes]:  # fmt: skip
    """The discovery topic and payload of `point` of `device`; `topics` holds its `state`,
    `command`, `availability` and the bridge's `status` topic."""
    component = entity_component(point)
    info = device.config.profile.device
    object_id = discovery_object_id(device.name, point.name)
    config: dict[str, object] = {
        "name": point.description or point.name.replace("_", " "),
        "unique_id": f"aiortu_{object_id}",
        "object_id": object_id,
        "state_topic": topics["state"],
        "availability": [{"topic": topics["status"]}, {"topic": topics["availability"]}],
        "availability_mode": "all",
        "qos": qos,
        "device": {
            "identifiers": [f"aiortu_{device.name}"],
            "name": device.name,
            "manufacturer": info.manufacturer,
            "model": info.model,
        },
    }
    if point.unit:
        config["unit_of_measurement"] = point.unit
    for key in ("device_class", "state_class", "icon", "entity_category"):
        if key in point.meta:
            config[key] = point.meta[key]
    if point.type is PointType.BOOL:
        config |= {"payload_on": "true", "payload_off": "false"}
        if component == "switch":
            config |= {"state_on": "true", "state_off": "false"}
    if point.type is PointType.ENUM:
        config["options"] = list(point.values.values())
        if component == "sensor":
            config.setdefault("device_class", "enum")
    if point.writable:
        config["command_topic"] = topics["command"]
    if component == "number":
        # Home Assistant's own defaults (1..100) would refuse most values.
        config["min"] = point.minimum if point.minimum is not None else -1e9
        config["max"] = point.maximum if point.maximum is not None else 1e9
        config["step"] = point.scale if point.scale else (1 if point.type.is_integer else 0.001)
        config["mode"] = "box"
    topic = discovery_topic(discovery_prefix, component, node, object_id)
    return topic, json.dumps(config, ensure_ascii=False).encode()

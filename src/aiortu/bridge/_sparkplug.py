"""The Sparkplug B layout: the bridge is an edge node, each device a Sparkplug device.

Topics are `spBv1.0/GROUP/TYPE/NODE[/DEVICE]`. On each connection the node's last will is
an NDEATH carrying `bdSeq` (one more each connection, 0..255), then NBIRTH (the same
`bdSeq`, the `Node Control/Rebirth` metric, the bridge's dropped count) and a DBIRTH for each
device that answers, with every metric, its datatype and value. Values that change go out as
DDATA; a unit the master marks offline gets a DDEATH, and a DBIRTH when it answers again
(a device is born with its first values, not before).
Every message after NBIRTH (sequence 0) carries the next sequence number, 0..255, stamped
when it is sent; DDATA queued while the broker was away is marked historical. An NCMD
`Node Control/Rebirth` = true publishes the births again; a DCMD writes its metrics.
Sparkplug's messages go at QoS 0 and are not retained, as the specification says; the will
at QoS 1.
"""

from __future__ import annotations

import math
import time

from aiortu.bridge._config import TopicLayout
from aiortu.bridge._outbox import Message
from aiortu.bridge._packets import Publish
from aiortu.bridge._protobuf import (
    DataType,
    Metric,
    SparkplugPayload,
    decode_payload,
    encode_payload,
)
from aiortu.bridge._state import Command, DeviceState
from aiortu.bridge._topics import LayoutTopic, device_topic, sparkplug_topic
from aiortu.core.model import PointType, ProfilePoint, Value
from aiortu.master import UnitState

__all__ = ("REBIRTH", "SparkplugLayout", "metric_datatype")

REBIRTH = "Node Control/Rebirth"
"""The node metric whose `true` in an NCMD asks for the births again."""
DROPPED = "Bridge/Dropped"
"""The node metric counting the messages dropped while the broker was away."""

_TYPES = {
    PointType.BOOL: DataType.BOOLEAN, PointType.U16: DataType.UINT16,
    PointType.I16: DataType.INT16, PointType.U32: DataType.UINT32, PointType.I32: DataType.INT32,
    PointType.U64: DataType.UINT64, PointType.I64: DataType.INT64, PointType.F32: DataType.FLOAT,
    PointType.F64: DataType.DOUBLE,
}  # fmt: skip


def metric_datatype(point: ProfilePoint) -> DataType:
    """The Sparkplug datatype of `point`'s value: a scaled integer is a Double, an enum or a
    text a String, a bitfield the String of its flags joined by commas."""
    if (
        point.type.is_integer
        and point.type.is_number
        and (point.scale is not None or point.offset is not None or point.scale_factor is not None)
    ):
        return DataType.DOUBLE
    return _TYPES.get(point.type, DataType.STRING)


def _metric_value(point: ProfilePoint, value: Value) -> bool | int | float | str | None:
    if isinstance(value, tuple):
        return ",".join(value)
    if isinstance(value, float) and not math.isfinite(value):
        return None
    return value


def _millis(now: float) -> int:
    return int(now * 1000)


class SparkplugLayout:
    """The Sparkplug B layout of `topics` (see the module docstring)."""

    def __init__(self, topics: TopicLayout) -> None:
        self.topics = topics
        self.group, self.node = topics.group, topics.node
        self.bd_seq = -1
        self.seq = 0
        self._born_at = -math.inf
        self._devices: dict[str, DeviceState] = {}
        self._wall = time.time
        self._dropped = 0
        self._born: set[str] = set()

    def _topic(self, kind: str, device: str | None = None) -> str:
        return sparkplug_topic(self.group, kind, self.node, device)

    def bind(self, devices: list[DeviceState]) -> None:
        """Learn the devices (before the first connection)."""
        self._devices = {device.name: device for device in devices}

    def will(self) -> Message | None:
        """NDEATH with the next bdSeq."""
        self.bd_seq = (self.bd_seq + 1) % 256
        payload = SparkplugPayload(
            _millis(self._wall()), (Metric("bdSeq", DataType.UINT64, self.bd_seq),)
        )
        return Message(self._topic("NDEATH"), encode_payload(payload), qos=1, retain=False)

    def subscriptions(self) -> list[str]:
        """NCMD of the node, DCMD of its devices."""
        return [self._topic("NCMD"), self._topic("DCMD", "+")]

    def every_topic(self, devices: list[DeviceState]) -> list[LayoutTopic]:
        """The node's NBIRTH, NDEATH (its last will) and NCMD; each device's error topic,
        DBIRTH, DDEATH, DDATA, and its DCMD if it has writable points (a DCMD to the others
        can only be refused); a point is a metric in the payload, not a topic."""
        listed = [LayoutTopic(self._topic("NBIRTH")), LayoutTopic(self._topic("NDEATH")),
                  LayoutTopic(self._topic("NCMD"), command=True)]  # fmt: skip
        for device in devices:
            name = device.name
            listed.append(LayoutTopic(self._error_topic(name), name))
            listed += [LayoutTopic(self._topic(kind, name), name)
                       for kind in ("DBIRTH", "DDEATH", "DDATA")]  # fmt: skip
            if device.writable:
                listed.append(LayoutTopic(self._topic("DCMD", name), name, command=True))
        return listed

    def on_connect(self, devices: list[DeviceState], dropped: int, now: float) -> list[Message]:
        """NBIRTH, then a DBIRTH per device that answers."""
        self._born_at, self._dropped = now, dropped
        self._born.clear()
        return self.births(devices, dropped, now)

    def births(self, devices: list[DeviceState], dropped: int, now: float) -> list[Message]:
        """NBIRTH and the devices' DBIRTHs."""
        stamp = _millis(self._wall())
        node_metrics = (
            Metric("bdSeq", DataType.UINT64, self.bd_seq, stamp),
            Metric(REBIRTH, DataType.BOOLEAN, False, stamp),
            Metric(DROPPED, DataType.UINT64, dropped, stamp),
        )
        messages = [Message(self._topic("NBIRTH"), b"", 0, False, now,
                            SparkplugPayload(stamp, node_metrics))]  # fmt: skip
        for device in devices:
            # A device not read yet is born with its first values.
            if device.health is not UnitState.OFFLINE and device.complete:
                messages.append(self._dbirth(device, now))
        return messages

    def _dbirth(self, device: DeviceState, now: float) -> Message:
        self._born.add(device.name)
        stamp = _millis(self._wall())
        metrics = tuple(
            Metric(p.name, metric_datatype(p), _metric_value(p, device.values.get(p.name)), stamp)
            for p in device.points
        )
        return Message(self._topic("DBIRTH", device.name), b"", 0, False, now,
                       SparkplugPayload(stamp, metrics))  # fmt: skip

    def values(self, device: DeviceState, changed: dict[str, Value], now: float) -> list[Message]:
        """One DDATA with the changed metrics; a DBIRTH with every metric for a device not
        born in this session yet."""
        if device.name not in self._born:
            return [self._dbirth(device, now)] if device.complete else []
        if not changed:
            return []
        stamp = _millis(self._wall())
        point = device.config.profile.point
        metrics = tuple(
            Metric(name, metric_datatype(point(name)), _metric_value(point(name), value), stamp)
            for name, value in changed.items()
        )
        return [Message(self._topic("DDATA", device.name), b"", 0, False, now,
                        SparkplugPayload(stamp, metrics))]  # fmt: skip

    def health(self, device: DeviceState, now: float) -> list[Message]:
        """DDEATH when the unit goes offline; it is born again with its next values."""
        if device.health is UnitState.OFFLINE and device.name in self._born:
            self._born.discard(device.name)
            payload = SparkplugPayload(_millis(self._wall()), ())
            return [Message(self._topic("DDEATH", device.name), b"", 0, False, now, payload)]
        return []

    def command(self, publish: Publish, devices: list[DeviceState], now: float,
                ) -> tuple[list[Command], list[Message]]:  # fmt: skip
        """A rebirth from NCMD; writes from DCMD."""
        try:
            payload = decode_payload(publish.payload)
        except ValueError:
            return [], []
        if publish.topic == self._topic("NCMD"):
            if any(m.name == REBIRTH and m.value is True for m in payload.metrics):
                return [], self.births(devices, self._dropped, now)
            return [], []
        device = publish.topic.rsplit("/", 1)[-1]
        if publish.topic != self._topic("DCMD", device) or device not in self._devices:
            return [], []
        return [Command(device, m.name, repr(m.value).encode(), m.value, True)
                for m in payload.metrics], []  # fmt: skip

    def error(self, device: str, point: str, payload: bytes, reason: str, now: float) -> Message:
        """Sparkplug has no error message: the plain layout's error topic."""
        import json

        body = {"point": point, "payload": payload.decode("utf-8", "replace"), "error": reason}
        return Message(self._error_topic(device), json.dumps(body).encode(), self.topics.qos,
                       False, now)  # fmt: skip

    def _error_topic(self, device: str) -> str:
        return device_topic(self.topics.prefix, device, "error")

    def prepare(self, message: Message) -> bytes:
        """The payload with this session's next sequence number (NBIRTH: 0), DDATA queued
        before this connection's births marked historical."""
        payload = message.metrics
        if not isinstance(payload, SparkplugPayload):
            return message.payload
        if message.topic == self._topic("NBIRTH"):
            self.seq = 0
        else:
            self.seq = (self.seq + 1) % 256
        metrics = payload.metrics
        if message.created < self._born_at and "/DDATA/" in message.topic:
            metrics = tuple(
                Metric(m.name, m.datatype, m.value, m.timestamp, m.alias, True) for m in metrics
            )
        return encode_payload(SparkplugPayload(payload.timestamp, metrics, self.seq))

"""MQTT 3.1.1 packets, sans-IO: the few a bridge sends and receives, built and parsed.

The bridge speaks MQTT 3.1.1 (OASIS standard, 2014), which every broker in use accepts:
CONNECT with a will, user name and password; PUBLISH at QoS 0 and 1 with its PUBACK;
SUBSCRIBE and its SUBACK; PINGREQ and PINGRESP; DISCONNECT. A QoS 2 message from the broker
is refused (the bridge subscribes at QoS 1 at most, so none comes).
"""

from __future__ import annotations

import enum
import struct
from collections.abc import Callable, Iterable
from dataclasses import dataclass
from typing import Protocol, TypeVar

__all__ = (
    "MAX_STRING_BYTES",
    "PUBACK_SIZE",
    "ConnectRefused",
    "Outgoing",
    "Packet",
    "PacketReader",
    "PacketType",
    "Publish",
    "PublishWriter",
    "connect_packet",
    "disconnect_packet",
    "pingreq_packet",
    "puback_packet",
    "publish_packet",
    "subscribe_packet",
)

_MAX_REMAINING = 268_435_455
"""The largest remaining length four bytes can say (MQTT 3.1.1, 2.2.3)."""
MAX_STRING_BYTES = 65_535
"""The most bytes of an MQTT 3.1.1 string (1.5.3: a two-byte length, then UTF-8): a topic, a
client id, a user name; a password's binary data has the same two-byte length (3.1.3.5)."""


class PacketType(enum.IntEnum):
    """The control packet types used (the high nibble of the first byte)."""

    CONNECT = 1
    CONNACK = 2
    PUBLISH = 3
    PUBACK = 4
    SUBSCRIBE = 8
    SUBACK = 9
    PINGREQ = 12
    PINGRESP = 13
    DISCONNECT = 14


CONNACK_REASONS = {
    1: "the broker does not accept MQTT 3.1.1",
    2: "the broker refused the client id",
    3: "the broker is unavailable",
    4: "the broker refused the user name or password",
    5: "the broker says the client is not authorised",
}
"""What each refusing CONNACK return code means."""


class ConnectRefused(Exception):
    """The broker answered CONNECT with a refusal; `code` is its return code."""

    def __init__(self, code: int) -> None:
        super().__init__(CONNACK_REASONS.get(code, f"the broker refused the connection ({code})"))
        self.code = code


@dataclass(slots=True)
class Packet:
    """A received packet: its `type`, the flags of its first byte and its `body`."""

    type: int
    flags: int
    body: bytes


@dataclass(frozen=True, slots=True)
class Publish:
    """A received PUBLISH: `topic`, `payload`, `qos`, `retain` and (QoS 1) `packet_id`."""

    topic: str
    payload: bytes
    qos: int
    retain: bool
    packet_id: int | None

    @classmethod
    def parse(cls, packet: Packet) -> Publish:
        """The PUBLISH in `packet`."""
        qos = (packet.flags >> 1) & 3
        (length,) = struct.unpack_from(">H", packet.body)
        topic = packet.body[2 : 2 + length].decode()
        at = 2 + length
        packet_id = None
        if qos:
            (packet_id,) = struct.unpack_from(">H", packet.body, at)
            at += 2
        return cls(topic, packet.body[at:], qos, bool(packet.flags & 1), packet_id)


_PUBACK_FIRST = bytes((PacketType.PUBACK << 4,))
_PUBACK_LENGTH = b"\x02"
PUBACK_SIZE = 4
"""The bytes of a PUBACK (MQTT 3.1.1, 3.4): what the broker sends for each QoS 1 PUBLISH."""

_SHORT = struct.Struct(">H").pack
"""A two-byte big-endian integer (lengths and packet ids)."""


def _length(n: int) -> bytes:
    if n > _MAX_REMAINING:
        raise ValueError(f"an MQTT packet holds at most {_MAX_REMAINING} bytes, not {n}")
    out = bytearray()
    while True:
        n, digit = divmod(n, 128)
        out.append(digit | (0x80 if n else 0))
        if not n:
            return bytes(out)


def _text(value: str | bytes) -> bytes:
    data = value.encode() if isinstance(value, str) else value
    return struct.pack(">H", len(data)) + data


def _packet(first: int, body: bytes) -> bytes:
    return bytes((first,)) + _length(len(body)) + body


def connect_packet(
    client_id: str,
    *,
    keepalive: int,
    username: str | None = None,
    password: str | None = None,
    will: tuple[str, bytes, int, bool] | None = None,
    clean_session: bool = True,
) -> bytes:
    """CONNECT: `will` is `(topic, payload, qos, retain)`."""
    flags = 0x02 if clean_session else 0
    payload = _text(client_id)
    if will is not None:
        topic, message, qos, retain = will
        flags |= 0x04 | (qos << 3) | (0x20 if retain else 0)
        payload += _text(topic) + _text(message)
    if username is not None:
        flags |= 0x80
        payload += _text(username)
    if password is not None:
        flags |= 0x40
        payload += _text(password)
    header = _text("MQTT") + bytes((4, flags)) + struct.pack(">H", keepalive)
    return _packet(PacketType.CONNECT << 4, header + payload)


def publish_packet(
    topic: str, payload: bytes, *, qos: int = 0, retain: bool = False, packet_id: int = 0,
    dup: bool = False,
) -> bytes:  # fmt: skip
    """PUBLISH of `payload` on `topic` (`packet_id` for QoS 1)."""
    writer = PublishWriter(max_topics=0)
    writer.add(topic, payload, qos, retain, packet_id, dup=dup)
    return writer.joined()


def _topic_field(topic: str) -> bytes:
    name = topic.encode()
    if len(name) > MAX_STRING_BYTES:
        raise ValueError(f"an MQTT topic holds at most {MAX_STRING_BYTES} bytes, not {len(name)}")
    return _SHORT(len(name)) + name


_HEADS = [[bytes((0x30 | flags, size)) for size in range(0x80)] for flags in range(4)]
"""The fixed header of a PUBLISH at QoS 0 or 1 whose remaining length is under 128 (a
bridge's values, as a rule), by its flags (QoS << 1 | retain), then by that length."""


class Outgoing(Protocol):
    """A message as [`PublishWriter.add_all`][aiortu.bridge._packets.PublishWriter.add_all]
    reads it: a `payload` on a `topic` at `qos`, `retain`ed or not; one whose `metrics` is
    set has its payload made when it is written."""

    @property
    def topic(self) -> str: ...
    @property
    def payload(self) -> bytes: ...
    @property
    def qos(self) -> int: ...
    @property
    def retain(self) -> bool: ...
    @property
    def metrics(self) -> object: ...


_Message = TypeVar("_Message", bound=Outgoing)


class PublishWriter:
    """PUBLISH packets as [`publish_packet`][aiortu.bridge._packets.publish_packet] makes
    them, added by the batch and joined once, each topic encoded once: a publisher sends the
    same topics again and again. Up to `max_topics` encodings are kept (a bridge's topics are
    set by its configuration)."""

    def __init__(self, max_topics: int = 100_000) -> None:
        self.max_topics = max_topics
        self._topics: dict[str, bytes] = {}
        self._parts: list[bytes] = []

    def add(
        self, topic: str, payload: bytes, qos: int, retain: bool, packet_id: int, *,
        dup: bool = False,
    ) -> None:  # fmt: skip
        """Add the PUBLISH of `payload` on `topic` (`packet_id` for QoS 1) to the packets
        that [`joined`][aiortu.bridge._packets.PublishWriter.joined] returns; raises
        ValueError, adding nothing, for a topic or packet too long for MQTT."""
        field = self._field(topic)
        size = len(field) + len(payload) + (2 if qos else 0)
        head = bytes((0x30 | (0x08 if dup else 0) | qos << 1 | retain,)) + _length(size)
        if qos:
            self._parts += (head, field, _SHORT(packet_id), payload)
        else:
            self._parts += (head, field, payload)

    def add_all(
        self, messages: Iterable[_Message], packet_ids: Iterable[int],
        prepare: Callable[[_Message], bytes],
    ) -> None:  # fmt: skip
        """`add` each of `messages` with its id of `packet_ids` (0 at QoS 0), its payload
        made by `prepare` if it carries `metrics`: a poll's values in one loop, each fixed
        header under 128 bytes from a table. A message that `add` refuses raises its
        ValueError, and the messages before it stay added."""
        topics, extend = self._topics, self._parts.extend
        for message, packet_id in zip(messages, packet_ids, strict=True):
            topic = message.topic
            field = topics.get(topic) or self._field(topic)
            payload = message.payload if message.metrics is None else prepare(message)
            qos = message.qos
            size = len(field) + len(payload)
            if qos == 1 and size < 0x7E:
                extend((_HEADS[2 | message.retain][size + 2], field, _SHORT(packet_id), payload))
            elif qos == 0 and size < 0x80:
                extend((_HEADS[message.retain][size], field, payload))
            else:  # a long packet, or QoS 2
                self.add(topic, payload, qos, message.retain, packet_id)

    def _field(self, topic: str) -> bytes:
        """The topic's field, encoded once (and kept while under `max_topics`)."""
        field = self._topics.get(topic)
        if field is None:
            field = _topic_field(topic)
            if len(self._topics) < self.max_topics:
                self._topics[topic] = field
        return field

    def joined(self) -> bytes:
        """The packets added since the last call, in order, in one piece."""
        parts, self._parts = self._parts, []
        return b"".join(parts)


def puback_packet(packet_id: int) -> bytes:
    """PUBACK of a received QoS 1 PUBLISH."""
    return _packet(PacketType.PUBACK << 4, struct.pack(">H", packet_id))


def subscribe_packet(packet_id: int, topics: list[tuple[str, int]]) -> bytes:
    """SUBSCRIBE to `topics`, each `(filter, qos)`."""
    body = struct.pack(">H", packet_id)
    for topic, qos in topics:
        body += _text(topic) + bytes((qos,))
    return _packet(PacketType.SUBSCRIBE << 4 | 0x02, body)


def pingreq_packet() -> bytes:
    """PINGREQ."""
    return bytes((PacketType.PINGREQ << 4, 0))


def disconnect_packet() -> bytes:
    """DISCONNECT."""
    return bytes((PacketType.DISCONNECT << 4, 0))


class PacketReader:
    """Splits received bytes into packets: `feed` bytes, get the whole packets they end."""

    def __init__(self) -> None:
        self._buffer = bytearray()

    @property
    def pending(self) -> int:
        """The bytes held of a packet not yet whole."""
        return len(self._buffer)

    def acknowledgements(self, data: bytes) -> tuple[int, ...] | None:
        """The packet ids of `data` if it is whole PUBACKs and nothing else, and no part of a
        packet waits: the bulk of what a publisher receives, read without a packet each.
        Else None, and nothing is read: `feed` it `data`."""
        count, rest = divmod(len(data), 4)
        if (rest or not count or self._buffer or data[0::4] != _PUBACK_FIRST * count
                or data[1::4] != _PUBACK_LENGTH * count):  # fmt: skip
            return None
        return struct.unpack(">" + "2xH" * count, data)

    def feed(self, data: bytes) -> list[Packet]:
        """The packets completed by `data`; raises ValueError for a malformed length."""
        buffer = self._buffer
        buffer += data
        packets: list[Packet] = []
        start, size = 0, len(buffer)
        while size - start >= 2:
            body, length = start + 2, buffer[start + 1]
            if length & 0x80:  # a length of more than one byte (a short one is the rule)
                found = _long_length(buffer, start)
                if found is None:
                    break
                body, length = found
            end = body + length
            if end > size:
                break
            first = buffer[start]
            packets.append(Packet(first >> 4, first & 0x0F, bytes(buffer[body:end])))
            start = end
        del buffer[:start]
        return packets


def _long_length(buffer: bytearray, start: int) -> tuple[int, int] | None:
    """Where the body of the packet at `start` begins and its length, or None while the
    length is incomplete; ValueError for a length of more than four bytes."""
    length = shift = 0
    at = start + 1
    while at < len(buffer):
        byte = buffer[at]
        length |= (byte & 0x7F) << shift
        at += 1
        if not byte & 0x80:
            return at, length
        shift += 7
        if shift > 21:
            raise ValueError("a malformed MQTT remaining length")
    return None

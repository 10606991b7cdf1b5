"""The bridge's codecs without a broker: MQTT packets, Sparkplug payloads (read back by
pysparkplug), the outbox's bound, and the payloads of values and commands."""

from __future__ import annotations

import itertools
import math

import pytest
from hypothesis import given
from hypothesis import strategies as st
from pysparkplug import Topic

from aiortu.bridge import (
    Broker,
    BrokerSession,
    CommandError,
    DataType,
    Message,
    Metric,
    Outbox,
    SessionHooks,
    SparkplugPayload,
    decode_payload,
    encode_payload,
    format_value,
    parse_command,
)
from aiortu.bridge._packets import (
    PacketReader,
    Publish,
    PublishWriter,
    puback_packet,
    publish_packet,
)
from aiortu.core.model import load_profile
from tests.bridge.helpers import HEAT_PUMP

PROFILE = load_profile(HEAT_PUMP)

_RANGES = {
    DataType.INT16: (-(2**15), 2**15 - 1), DataType.INT32: (-(2**31), 2**31 - 1),
    DataType.INT64: (-(2**63), 2**63 - 1), DataType.UINT16: (0, 2**16 - 1),
    DataType.UINT32: (0, 2**32 - 1), DataType.UINT64: (0, 2**64 - 1),
}  # fmt: skip


@st.composite
def metrics(draw: st.DrawFn) -> Metric:
    datatype = draw(st.sampled_from(list(DataType)))
    value: bool | int | float | str | None
    if draw(st.booleans()) and draw(st.booleans()):
        value = None
    elif datatype in _RANGES:
        value = draw(st.integers(*_RANGES[datatype]))
    elif datatype is DataType.BOOLEAN:
        value = draw(st.booleans())
    elif datatype is DataType.STRING:
        value = draw(st.text())
    elif datatype is DataType.FLOAT:
        value = draw(st.floats(width=32, allow_nan=False))
    else:
        value = draw(st.floats(allow_nan=False))
    name = draw(st.text(min_size=1, max_size=20))
    return Metric(name, datatype, value, draw(st.none() | st.integers(0, 2**63)))


@given(st.lists(metrics(), max_size=5), st.integers(0, 2**63), st.none() | st.integers(0, 255))
def test_sparkplug_payloads_round_trip_and_pysparkplug_reads_them(
    metric_list: list[Metric], timestamp: int, seq: int | None
) -> None:
    payload = SparkplugPayload(timestamp, tuple(metric_list), seq)
    data = encode_payload(payload)
    assert decode_payload(data) == payload
    if seq is None:
        return
    theirs = Topic.from_str("spBv1.0/g/DDATA/n/d").message_type.payload.decode(data)
    assert theirs.seq == seq
    assert theirs.timestamp == timestamp
    for mine, other in zip(metric_list, theirs.metrics, strict=True):
        assert (other.name, int(other.datatype)) == (mine.name, int(mine.datatype))
        if mine.value is None:
            assert other.is_null
        else:
            assert other.value == mine.value


def test_a_truncated_payload_is_refused() -> None:
    data = encode_payload(SparkplugPayload(1, (Metric("power", DataType.FLOAT, 1.5),), 3))
    for cut in (data[:-1], data[:12], data + b"\x0a"):
        with pytest.raises(ValueError, match=r"Sparkplug B payload|truncated"):
            decode_payload(cut)


@given(st.lists(st.tuples(st.text(max_size=30), st.binary(max_size=300), st.integers(0, 1),
                          st.booleans()), max_size=8), st.integers(1, 50))  # fmt: skip
def test_publish_packets_split_at_any_point_read_back(
    messages: list[tuple[str, bytes, int, bool]], chunk: int
) -> None:
    stream = b"".join(
        publish_packet(topic, payload, qos=qos, retain=retain, packet_id=n + 1)
        for n, (topic, payload, qos, retain) in enumerate(messages)
    )
    reader = PacketReader()
    packets = [
        p for at in range(0, len(stream), chunk) for p in reader.feed(stream[at : at + chunk])
    ]
    got = [Publish.parse(p) for p in packets]
    assert [(p.topic, p.payload, p.qos, p.retain) for p in got] == messages
    assert [p.packet_id for p in got] == [n + 1 if m[2] else None for n, m in enumerate(messages)]


def _spec_publish(topic: str, payload: bytes, qos: int, retain: bool, packet_id: int,
                  dup: bool) -> bytes:  # fmt: skip
    """A PUBLISH as MQTT 3.1.1 (3.3) lays it out, written out plainly for the tests."""
    name = topic.encode()
    body = len(name).to_bytes(2, "big") + name
    if qos:
        body += packet_id.to_bytes(2, "big")
    body += payload
    length, size = bytearray(), len(body)
    while True:  # 2.2.3: seven bits a byte, the top bit says more follow
        size, digit = divmod(size, 128)
        length.append(digit | (0x80 if size else 0))
        if not size:
            break
    return bytes((0x30 | dup << 3 | qos << 1 | retain,)) + bytes(length) + body


@given(
    st.lists(st.tuples(st.sampled_from(["a", "b/c", "t" * 120, "u" * 300]),
                       st.sampled_from([0, 1, *range(120, 129), 200, 16_400]),
                       st.integers(0, 2), st.booleans(), st.integers(1, 65535), st.booleans(),
                       st.booleans()),
             max_size=12),
)  # fmt: skip
def test_a_writer_s_batch_is_each_packet_as_the_spec_lays_it_out(
    packets: list[tuple[str, int, int, bool, int, bool, bool]],
) -> None:
    # The remaining lengths around 128 (a topic field of 3 or 5 bytes, a packet id of 2) take
    # the fixed headers' table, or the general path past it; a message with metrics gets the
    # payload `prepare` makes.
    writer = PublishWriter()
    made: dict[int, bytes] = {}  # the payloads prepare makes, by message

    def prepare(message: Message) -> bytes:
        assert message.metrics is not None
        return made[id(message)]

    general: list[str] = []  # the topics of packets laid out by `add`, not from the table
    add = writer.add
    writer.add = lambda topic, *rest, **options: (general.append(topic),  # type: ignore[method-assign]
                                                 add(topic, *rest, **options))[1]  # fmt: skip
    for _ in range(2):  # each topic encoded afresh, then from the writer's cache
        wanted, messages, ids = [], [], []
        general.clear()
        for topic, size, qos, retain, packet_id, dup, later in packets:
            payload = bytes(range(256)) * (size // 256) + bytes(size % 256)
            message = Message(topic, b"" if later else payload, qos, retain,
                              metrics=object() if later else None)  # fmt: skip
            made[id(message)] = payload
            messages.append(message)
            ids.append(packet_id if qos else 0)
            wanted.append(_spec_publish(topic, payload, qos, retain, ids[-1], False))
            assert publish_packet(topic, payload, qos=qos, retain=retain, packet_id=packet_id,
                                  dup=dup) == _spec_publish(topic, payload, qos, retain,
                                                            packet_id, dup)  # fmt: skip
        writer.add_all(messages, ids, prepare)
        assert writer.joined() == b"".join(wanted)
        assert general == [m.topic for m, w in zip(messages, wanted, strict=True)
                           if m.qos == 2 or w[1] & 0x80]  # fmt: skip
        assert writer.joined() == b""


def test_a_writer_keeps_at_most_max_topics_encodings() -> None:
    writer = PublishWriter(max_topics=1)
    for topic in ("a", "b", "a"):
        writer.add(topic, b"1", 0, False, 0)
    assert list(writer._topics) == ["a"]
    assert writer.joined() == b"".join(publish_packet(t, b"1") for t in ("a", "b", "a"))


def test_packet_ids_skip_those_still_in_flight_when_they_wrap() -> None:
    hooks = SessionHooks(will=lambda: None, subscriptions=list, on_connect=list,
                         on_publish=lambda publish: None)  # fmt: skip
    session = BrokerSession(Broker("127.0.0.1", 1883), Outbox(), hooks)
    waiting = Message("t", b"")
    session._inflight = {1: waiting, 2: waiting, 65535: waiting}
    session._next_id = 65533
    sent = [Message("t", b"%d" % n, qos=n % 2) for n in range(1, 6)]
    assert session._number(sent) == [65534, 0, 3, 0, 4]
    assert list(session._inflight) == [1, 2, 65535, 65534, 3, 4]


@given(st.lists(st.binary(max_size=40), max_size=60), st.integers(1, 20), st.integers(20, 400))
def test_the_outbox_keeps_the_newest_within_its_bound(
    payloads: list[bytes], max_messages: int, max_bytes: int
) -> None:
    outbox = Outbox(max_messages, max_bytes)
    for payload in payloads:
        outbox.put(Message("t", payload))
        assert len(outbox) <= max_messages
        assert outbox.bytes <= max_bytes or len(outbox) == 1
    kept = outbox.take(len(outbox))
    assert [m.payload for m in kept] == payloads[len(payloads) - len(kept) :]
    assert outbox.dropped + len(kept) == len(payloads)


def test_messages_put_back_go_first_in_their_order() -> None:
    outbox = Outbox()
    for n in range(4):
        outbox.put(Message("t", bytes([n])))
    first = outbox.take(2)
    outbox.put(Message("t", b"\x09"))
    outbox.put_back(first)
    assert [m.payload for m in outbox.take(10)] == [b"\x00", b"\x01", b"\x02", b"\x03", b"\x09"]


@pytest.mark.parametrize(
    ("point", "value", "payload"),
    [
        ("power", 230.10000610351562, b"230.1"),
        ("power", 1800.0, b"1800.0"),
        ("power", math.nan, b"null"),
        ("setpoint", 45.1, b"45.1"),
        ("model_code", 7, b"7"),
        ("mode", "heat", b"heat"),
        ("alarms", ("high_pressure", "sensor_fault"), b'["high_pressure", "sensor_fault"]'),
        ("pump", True, b"true"),
        ("serial", None, b"null"),
    ],
)
def test_values_as_payloads(point: str, value: object, payload: bytes) -> None:
    assert format_value(PROFILE.point(point), value) == payload  # type: ignore[arg-type]


@pytest.mark.parametrize(
    ("point", "payload", "value"),
    [
        ("setpoint", b"50.5", 50.5),
        ("setpoint", b" 50 ", 50),
        ("pump", b"ON", True),
        ("pump", b"false", False),
        ("pump", b"0", False),
        ("mode", b"cool", "cool"),
        ("mode", b'"cool"', "cool"),
        ("alarms", b'["low_pressure"]', ("low_pressure",)),
    ],
)
def test_command_payloads(point: str, payload: bytes, value: object) -> None:
    assert parse_command(PROFILE.point(point), payload) == value


@pytest.mark.parametrize(
    ("point", "payload", "reason"),
    [
        ("setpoint", b"", "the payload is empty"),
        ("setpoint", b"warm", "'warm' is not a number"),
        ("setpoint", b"true", "'true' is not a number"),
        ("pump", b"maybe", "'maybe' is not a boolean (true/false, on/off, 1/0)"),
        ("alarms", b"low_pressure", "'low_pressure' is not a JSON list of flag names"),
        ("setpoint", b"\xff\xfe", "the payload is not UTF-8 text"),
    ],
)
def test_bad_command_payloads_say_why(point: str, payload: bytes, reason: str) -> None:
    with pytest.raises(CommandError) as caught:
        parse_command(PROFILE.point(point), payload)
    assert str(caught.value) == reason


_LOOKALIKE = publish_packet("t", puback_packet(7) * 3, qos=1, packet_id=9)
"""A PUBLISH whose payload looks like PUBACKs: cut at its payload, it must not be read as them."""


@st.composite
def received(draw: st.DrawFn) -> bytes:
    """What a broker sends a publisher: PUBACKs mostly, now and then something else."""
    return draw(st.one_of(
        st.integers(1, 65535).map(puback_packet),
        st.integers(1, 65535).map(puback_packet),
        st.just(bytes((0xD0, 0))),  # PINGRESP
        st.just(bytes((0x90, 3, 0, 1, 1))),  # SUBACK
        st.just(_LOOKALIKE),
        st.binary(max_size=200).map(lambda payload: publish_packet("a/b", payload)),
    ))  # fmt: skip


@given(st.lists(received(), max_size=30), st.lists(st.integers(0, 400), max_size=12))
def test_acknowledgements_read_as_every_packet_is_read(
    packets: list[bytes], cuts: list[int]
) -> None:
    """The PUBACK shortcut against the general reader: the same packets, in the same order,
    whatever the chunks."""
    stream = b"".join(packets)
    bounds = [0, *sorted(c for c in cuts if c < len(stream)), len(stream)]
    chunks = [stream[a:b] for a, b in itertools.pairwise(bounds) if b > a]
    shortcut, general = PacketReader(), PacketReader()
    got: list[tuple[int, int, bytes]] = []
    expected: list[tuple[int, int, bytes]] = []
    for chunk in chunks:
        ids = shortcut.acknowledgements(chunk)
        if ids is None:
            got += [(p.type, p.flags, p.body) for p in shortcut.feed(chunk)]
        else:
            got += [(4, 0, packet_id.to_bytes(2, "big")) for packet_id in ids]
        expected += [(p.type, p.flags, p.body) for p in general.feed(chunk)]
    assert got == expected
    assert len(got) == len(packets)


def test_the_acknowledgement_shortcut_takes_whole_pubacks_only() -> None:
    reader = PacketReader()
    assert reader.acknowledgements(puback_packet(1) + puback_packet(0x1234)) == (1, 0x1234)
    assert reader.acknowledgements(puback_packet(1)[:3]) is None
    assert reader.acknowledgements(b"") is None
    assert reader.acknowledgements(bytes((0x41, 2, 0, 1))) is None  # flags a PUBACK has not
    assert reader.acknowledgements(bytes((0x40, 3, 0, 1))) is None
    assert reader.acknowledgements(bytes((0xD0, 0, 0xD0, 0))) is None  # two PINGRESPs
    assert reader.feed(_LOOKALIKE[:7]) == []
    # Part of a packet waits: what follows is its rest, whatever it looks like.
    assert reader.acknowledgements(puback_packet(7)) is None


def test_long_remaining_lengths_and_a_malformed_one() -> None:
    payload = bytes(range(256)) * 80  # 20,480 bytes: a remaining length of three bytes
    packet = publish_packet("big", payload, qos=1, packet_id=3)
    assert packet[1:4] == bytes((0x87, 0xA0, 0x01))  # 20,487 = 7 + 32 * 128 + 1 * 16,384
    reader = PacketReader()
    assert reader.feed(packet[:2]) == reader.feed(packet[2:3]) == []
    (got,) = reader.feed(packet[3:])
    assert Publish.parse(got) == Publish("big", payload, 1, False, 3)
    with pytest.raises(ValueError, match="malformed MQTT remaining length"):
        PacketReader().feed(bytes((0x30, 0xFF, 0xFF, 0xFF, 0xFF, 0x01)))
    with pytest.raises(ValueError, match="at most 65535 bytes"):
        publish_packet("t" * 65536, b"")


@given(
    st.lists(st.lists(st.binary(max_size=40), max_size=12), max_size=8),
    st.integers(1, 20), st.integers(20, 400), st.integers(1, 8),
)  # fmt: skip
def test_a_batch_put_leaves_what_putting_one_by_one_leaves(
    batches: list[list[bytes]], max_messages: int, max_bytes: int, step: int
) -> None:
    batched, single = Outbox(max_messages, max_bytes), Outbox(max_messages, max_bytes)
    for batch in batches:
        batched.put_all([Message("t", p) for p in batch])
        for payload in batch:
            single.put(Message("t", payload))
        assert (len(batched), batched.bytes, batched.dropped, batched.accepted) == (
            len(single), single.bytes, single.dropped, single.accepted)  # fmt: skip
    kept = [m.payload for m in single.take(len(single))]
    taken: list[bytes] = []
    while batched:
        taken += [m.payload for m in batched.take(step)]
        assert batched.bytes == sum(len("t") + len(p) for p in kept[len(taken) :])
    assert taken == kept
    assert batched.bytes == 0

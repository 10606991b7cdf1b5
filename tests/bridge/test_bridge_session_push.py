"""The broker session's two paths: on asyncio the connection is pushed (read in the event
loop's callback, written from the call that fills the outbox), elsewhere a task reads anyio's
stream and another sends. A differential test runs one seeded scenario against a scripted
broker on asyncio's general path, on its pushed path and on trio, and compares every packet
each connection received; then what only the pushed path does: it stops writing while the
broker reads nothing (the messages wait in the bounded outbox), it leaves a connection whose
bytes are not MQTT, and a bug in a hook is raised, not taken for a lost connection."""

from __future__ import annotations

import contextlib
import os
import random
import socket
import struct
from collections.abc import Awaitable, Callable
from dataclasses import dataclass, field
from types import SimpleNamespace

import anyio
import anyio.abc
import pytest

import aiortu.bridge._session as session_module
from aiortu.bridge import Broker, BrokerSession, Message, Outbox, SessionHooks, _session_push
from aiortu.bridge._packets import (
    Packet,
    PacketReader,
    PacketType,
    Publish,
    puback_packet,
    publish_packet,
)
from aiortu.bridge._session_push import open_pushed, push_session

pytestmark = pytest.mark.timeout(60)

CONNACK = bytes((0x20, 2, 0, 0))
SUBACK = bytes((0x90, 3, 0, 1, 1))
WINDOW = 4
TOPICS = ["a", "plant/line-1/meter/f00", "t" * 150]  # the last makes a long header


@dataclass
class Scenario:
    """One seeded run: what goes in the outbox, and how the broker acknowledges it."""

    seed: int
    rng: random.Random = field(init=False)
    first: list[Message] = field(default_factory=list)
    batch: list[Message] = field(default_factory=list)
    full: list[Message] = field(default_factory=list)
    last: list[Message] = field(default_factory=list)

    def __post_init__(self) -> None:
        self.rng = random.Random(self.seed)
        self.first = [self.message(qos) for qos in (1, 0, 1)]
        self.batch = [self.message() for _ in range(WINDOW)]
        self.full = [self.message(1) for _ in range(3 * WINDOW)]
        self.last = [self.message(1) for _ in range(2)]

    def message(self, qos: int | None = None) -> Message:
        rng = self.rng
        size = rng.choice([0, 1, 5, 100, 300])
        metrics = object() if rng.random() < 0.2 else None  # a payload made when sent
        return Message(rng.choice(TOPICS), rng.randbytes(size),
                       qos=rng.choice([0, 1]) if qos is None else qos,
                       retain=rng.random() < 0.5, metrics=metrics)  # fmt: skip

    def chunks(self, packets: list[Packet]) -> list[bytes]:
        """The PUBACKs of `packets`' QoS 1 PUBLISHes, shuffled, in chunks of 1 to 4."""
        acks = [puback_packet(p.packet_id) for p in map(Publish.parse, packets)
                if p.packet_id is not None]  # fmt: skip
        self.rng.shuffle(acks)
        out = []
        while acks:
            take = self.rng.randint(1, 4)
            out.append(b"".join(acks[:take]))
            del acks[:take]
        return out


class Broker1:
    """A scripted broker: each step waits for the packets it expects, so the packets each
    connection receives do not depend on timing."""

    def __init__(self, scenario: Scenario, outbox: Outbox) -> None:
        self.scenario = scenario
        self.outbox = outbox
        self.connections: list[list[Packet]] = []
        self.done = anyio.Event()

    async def serve(self, stream: anyio.abc.ByteStream) -> None:
        reader = PacketReader()
        got: list[Packet] = []
        self.connections.append(got)

        async def expect(count: int) -> list[Packet]:
            start = len(got)
            while len(got) - start < count:
                got.extend(reader.feed(await stream.receive()))
            assert len(got) - start == count, got[start:]
            return got[start:]

        (connect,) = await expect(1)
        assert connect.type == PacketType.CONNECT
        await stream.send(CONNACK)
        s = self.scenario
        if len(self.connections) == 1:
            await self._first_connection(stream, expect)
            return
        # SUBSCRIBE, the first messages, then the two left unacknowledged, in order.
        packets = await expect(1 + len(s.first) + len(s.last))
        for chunk in s.chunks(packets[1:]):
            await stream.send(chunk)
        self.done.set()
        await anyio.sleep_forever()

    async def _first_connection(
        self, stream: anyio.abc.ByteStream, expect: Callable[[int], Awaitable[list[Packet]]]
    ) -> None:
        s = self.scenario
        packets = await expect(1 + len(s.first))  # SUBSCRIBE, then what on_connect made
        await stream.send(SUBACK)
        for chunk in s.chunks(packets[1:]):
            await stream.send(chunk)
        self.outbox.put_all(s.batch)  # within the window, whatever it holds
        for chunk in s.chunks(await expect(len(s.batch))):
            await stream.send(chunk)
        # A command: its PUBACK, then what its hook puts in the outbox.
        await stream.send(publish_packet("cmd/x/set", b"7", qos=1, packet_id=77))
        ack, reply = await expect(2)
        assert ack.type == PacketType.PUBACK
        assert ack.body == b"\x00\x4d"
        assert Publish.parse(reply).payload == b"ack 7"
        for chunk in s.chunks([reply]):
            await stream.send(chunk)
        # More than the window: each acknowledgement lets one more go.
        self.outbox.put_all(s.full)
        waiting = list(await expect(WINDOW))
        for _ in range(len(s.full) - WINDOW):
            await stream.send(s.chunks([waiting.pop(0)])[0])
            waiting += await expect(1)
        for chunk in s.chunks(waiting):
            await stream.send(chunk)
        # Two never acknowledged: sent again first on the next connection.
        self.outbox.put_all(s.last)
        await expect(len(s.last))
        await stream.aclose()


async def _run(scenario: Scenario) -> list[list[Packet]]:
    outbox = Outbox()
    sent = 0

    def prepare(message: Message) -> bytes:
        nonlocal sent
        sent += 1
        return message.payload + bytes((sent % 256,))  # as Sparkplug stamps its seq

    def on_publish(publish: Publish) -> None:
        outbox.put(Message("reply", b"ack " + publish.payload, qos=1))

    broker = Broker1(scenario, outbox)
    listener = await anyio.create_tcp_listener(local_host="127.0.0.1", local_port=0)
    port = listener.extra(anyio.abc.SocketAttribute.local_port)
    hooks = SessionHooks(
        will=lambda: Message("will", b"gone", qos=1, retain=True),
        subscriptions=lambda: ["cmd/+/set"],
        on_connect=lambda: list(scenario.first),
        on_publish=on_publish,
        prepare=prepare,
    )
    session = BrokerSession(Broker("127.0.0.1", port, keepalive=60), outbox, hooks,
                            window=WINDOW, reconnect_delay=(0.01, 0.01))  # fmt: skip
    async with anyio.create_task_group() as tasks:
        tasks.start_soon(listener.serve, broker.serve)
        tasks.start_soon(session.run)
        with anyio.fail_after(20):
            await broker.done.wait()
            while session.delivered < _expected_deliveries(scenario):  # noqa: ASYNC110 - bounded
                await anyio.sleep(0.01)
        tasks.cancel_scope.cancel()
    assert session.connections == 2
    assert len(outbox) == 0
    assert not session._inflight
    return broker.connections


def _expected_deliveries(s: Scenario) -> int:
    """Every message of the scenario, the command's reply, and `first` twice."""
    return 2 * len(s.first) + len(s.batch) + 1 + len(s.full) + len(s.last)


@pytest.mark.parametrize("seed", [1, 2, 3, 4])
def test_both_paths_and_trio_send_the_same_packets(
    seed: int, monkeypatch: pytest.MonkeyPatch
) -> None:
    runs = {}
    for name, backend, pushed in [
        ("asyncio, general", "asyncio", False),
        ("asyncio, pushed", "asyncio", True),
        ("trio", "trio", None),
    ]:
        if pushed is not None:
            monkeypatch.setattr(session_module, "push_session", lambda pushed=pushed: pushed)
        else:
            monkeypatch.undo()
        runs[name] = anyio.run(_run, Scenario(seed), backend=backend)
    general = runs.pop("asyncio, general")
    for name, connections in runs.items():
        assert connections == general, f"seed {seed}: {name} differs from the general path"
    # And the general path did what the scenario says: the messages in order, the two
    # unacknowledged ones first again on the second connection.
    scenario = Scenario(seed)
    first, second = general
    publishes = [p for p in first if p.type == PacketType.PUBLISH]
    wanted = [*scenario.first, *scenario.batch, Message("reply", b"ack 7"), *scenario.full,
              *scenario.last]  # fmt: skip
    assert [p.topic for p in map(Publish.parse, publishes)] == [m.topic for m in wanted]
    again = [Publish.parse(p) for p in second if p.type == PacketType.PUBLISH]
    assert [p.topic for p in again] == [m.topic for m in [*scenario.first, *scenario.last]]


def test_the_predicate_picks_the_pushed_path_on_asyncio_only() -> None:
    async def check() -> bool:
        return push_session()

    assert anyio.run(check, backend="asyncio") is True
    assert anyio.run(check, backend="trio") is False


async def _connected(
    serve: Callable[[anyio.abc.ByteStream], Awaitable[None]], outbox: Outbox, **hooks: object
) -> tuple[BrokerSession, anyio.abc.Listener[anyio.abc.SocketStream]]:
    listener = await anyio.create_tcp_listener(local_host="127.0.0.1", local_port=0)
    port = listener.extra(anyio.abc.SocketAttribute.local_port)
    options: dict[str, object] = {
        "will": lambda: None, "subscriptions": list, "on_connect": list,
        "on_publish": lambda publish: None, **hooks,
    }  # fmt: skip
    session = BrokerSession(Broker("127.0.0.1", port, keepalive=60), outbox,
                            SessionHooks(**options), reconnect_delay=(0.01, 0.01))  # type: ignore[arg-type]  # fmt: skip
    return session, listener


async def _connect(stream: anyio.abc.ByteStream, then: bytes = b"") -> PacketReader:
    """The scripted broker's side of a connection: the CONNECT read and answered (with
    `then` after the CONNACK); the reader goes on with what follows."""
    reader = PacketReader()
    while not reader.feed(await stream.receive()):  # CONNECT
        pass
    await stream.send(CONNACK + then)
    return reader


async def test_a_broker_that_reads_nothing_leaves_the_messages_in_the_outbox() -> None:
    """The pushed path writes only while the transport's buffer is below its high-water
    mark: what the broker does not read waits in the outbox (bounded), not in memory the
    bound does not see; once the broker reads again, everything arrives in order."""
    reading = anyio.Event()
    received: list[bytes] = []
    count, size = 20_000, 1000

    async def broker(stream: anyio.abc.ByteStream) -> None:
        reader = await _connect(stream)
        await reading.wait()
        while len(received) < count:
            packets = reader.feed(await stream.receive())
            received.extend(Publish.parse(p).payload[:5] for p in packets)

    outbox = Outbox(max_messages=count, max_bytes=count * 2 * size)
    session, listener = await _connected(broker, outbox)
    async with anyio.create_task_group() as tasks:
        tasks.start_soon(listener.serve, broker)
        tasks.start_soon(session.run)
        with anyio.fail_after(20):
            while not session.connected:  # noqa: ASYNC110 - a bounded wait
                await anyio.sleep(0.01)
            for start in range(0, count, 1000):
                outbox.put_all([Message("t", b"%05d" % n + bytes(size - 5), qos=0)
                                for n in range(start, start + 1000)])  # fmt: skip
            left = -1
            while len(outbox) != left:  # until the kernel's buffers and the transport's are full
                left = len(outbox)
                await anyio.sleep(0.2)
            link = session._stream
            assert isinstance(link, session_module.PushedLink)
            assert link.transport is not None
            # 20 MB put; the loopback's buffers take a few, the transport at most one batch
            # past its high-water mark, the outbox the rest.
            assert left > count // 4
            assert link.transport.get_write_buffer_size() <= 64 * 1024 + 256 * size
            reading.set()
            while len(received) < count:  # noqa: ASYNC110 - a bounded wait
                await anyio.sleep(0.05)
        tasks.cancel_scope.cancel()
    assert received == [b"%05d" % n for n in range(count)]
    assert outbox.dropped == 0
    assert session.delivered == count


@pytest.mark.parametrize("pushed", [True, False], ids=["pushed", "general"])
async def test_bytes_that_are_not_mqtt_end_the_connection(
    pushed: bool, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.setattr(session_module, "push_session", lambda: pushed)

    async def broker(stream: anyio.abc.ByteStream) -> None:
        reader = await _connect(stream)
        while not reader.feed(await stream.receive()):  # the PUBLISH after connecting
            pass
        await stream.send(bytes((0x30, 0xFF, 0xFF, 0xFF, 0xFF, 0x7F)))  # a 5-byte length
        await anyio.sleep_forever()

    session, listener = await _connected(
        broker, Outbox(), on_connect=lambda: [Message("up", b"1", qos=0)]
    )
    async with anyio.create_task_group() as tasks:
        tasks.start_soon(listener.serve, broker)
        tasks.start_soon(session.run)
        with anyio.fail_after(10):
            while session.connections < 2:  # noqa: ASYNC110 - a bounded wait
                await anyio.sleep(0.01)
        tasks.cancel_scope.cancel()
    assert session.last_error == "a malformed MQTT remaining length"


def _leaves(error: BaseException) -> list[BaseException]:
    if isinstance(error, BaseExceptionGroup):
        return [leaf for inner in error.exceptions for leaf in _leaves(inner)]
    return [error]


@pytest.mark.parametrize("pushed", [True, False], ids=["pushed", "general"])
async def test_a_bug_in_a_hook_is_raised_not_taken_for_a_lost_connection(
    pushed: bool, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.setattr(session_module, "push_session", lambda: pushed)

    async def broker(stream: anyio.abc.ByteStream) -> None:
        await _connect(stream, then=publish_packet("cmd", b"1", qos=1, packet_id=5))
        await anyio.sleep_forever()

    def on_publish(publish: Publish) -> None:
        raise RuntimeError("a bug in the hook")

    session, listener = await _connected(broker, Outbox(), on_publish=on_publish)
    with pytest.raises(BaseException) as raised:  # noqa: PT011, PT012 - checked below
        async with anyio.create_task_group() as tasks:
            tasks.start_soon(listener.serve, broker)
            with anyio.fail_after(10):
                await session.run()
    assert [type(e) for e in _leaves(raised.value)] == [RuntimeError]
    assert session.connections == 1


async def _until(check: Callable[[], bool], seconds: float = 10) -> None:
    with anyio.fail_after(seconds):
        while not check():  # noqa: ASYNC110 - a bounded wait
            await anyio.sleep(0.01)


async def test_a_poll_s_acknowledgements_wake_nothing_and_the_next_write_reads_them(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """The broker acknowledges 40 messages one by one; where the kernel takes a receive mark
    the pushed session is not woken for them at all: the next write of the outbox reads them
    first, in one piece, in the turn of the loop that fills it (elsewhere each chunk is read
    as it comes). Nothing is read that way while nothing is in flight (QoS 0)."""
    count = 40
    acknowledged = anyio.Event()

    async def broker(stream: anyio.abc.ByteStream) -> None:
        reader = await _connect(stream)
        ids: list[int] = []
        while len(ids) < count:
            publishes = map(Publish.parse, reader.feed(await stream.receive()))
            ids += [p.packet_id for p in publishes if p.packet_id is not None]
        for packet_id in ids:
            await stream.send(puback_packet(packet_id))
            await anyio.sleep(0.002)
        acknowledged.set()
        await anyio.sleep_forever()

    outbox = Outbox()
    session, listener = await _connected(broker, outbox)
    reads: list[bytes] = []
    pushed = session._pushed
    session._pushed = lambda data: (reads.append(data), pushed(data))[1]  # type: ignore[method-assign]
    collected: list[bytes | None] = []

    def read(fd: int, size: int) -> bytes:  # the link's own read, seen (None: it waited)
        collected.append(None)
        collected[-1] = data = os.read(fd, size)
        return data

    monkeypatch.setattr(_session_push, "os", SimpleNamespace(read=read))
    async with anyio.create_task_group() as tasks:
        tasks.start_soon(listener.serve, broker)
        tasks.start_soon(session.run)
        await _until(lambda: session.connected)
        outbox.put_all([Message("t", b"qos 0", qos=0) for _ in range(3)])
        assert collected == []  # nothing in flight: nothing owed, nothing to read
        outbox.put_all([Message("t", b"%d" % n, qos=1) for n in range(count)])
        with anyio.fail_after(10):
            await acknowledged.wait()
        await anyio.sleep(0.05)
        acks = b"".join(puback_packet(n) for n in range(1, count + 1))
        if _marks():
            assert reads == []  # no wake for them
            assert len(session._inflight) == count
            outbox.put(Message("t", b"next", qos=1))
            assert reads == [acks]  # read first, at once
            assert collected == [acks]
            assert len(session._inflight) == 1
        else:
            assert b"".join(reads) == acks
        await _until(lambda: session.delivered == count + 3)
        tasks.cancel_scope.cancel()


async def test_collect_reads_below_the_mark_without_waiting_and_ends_the_link_on_a_reset() -> None:
    """`PushedLink.collect` reads only what waits below a mark above one byte, hands it on as
    the loop's callback would, never waits, and a reset of the connection ends the link with
    it (not raised into the caller)."""
    server = socket.create_server(("127.0.0.1", 0))
    with server:
        link = await open_pushed("127.0.0.1", server.getsockname()[1], None)
        peer, _ = server.accept()
        with peer:
            peer.sendall(b"12345678")
            await anyio.sleep(0.05)  # the mark is one byte: the loop's callback reads them
            assert link._kept == [b"12345678"]
            link.collect()  # a mark of one byte: nothing read
            assert link._kept == [b"12345678"]
            link.expect(9)
            peer.sendall(b"abcdefgh")
            await anyio.sleep(0.05)
            if not _marks():
                assert link._kept == [b"12345678", b"abcdefgh"]
                return
            assert link._kept == [b"12345678"]  # below the mark: no wake
            link.collect()
            assert link._kept == [b"12345678", b"abcdefgh"]  # handed on as the callback does
            link.collect()  # nothing waits: no wait, nothing handed on
            assert link._kept == [b"12345678", b"abcdefgh"]
            peer.setsockopt(socket.SOL_SOCKET, socket.SO_LINGER, struct.pack("ii", 1, 0))
        link.collect()  # the reset, read before the loop's callback
        with pytest.raises(ConnectionResetError):
            await link.ended()


async def _take_publishes(stream: anyio.abc.ByteStream, count: int) -> list[Packet]:
    """The broker's side of a connection: its CONNECT answered, then `count` packets taken."""
    reader = await _connect(stream)
    got: list[Packet] = []
    while len(got) < count:
        got += reader.feed(await stream.receive())
    return got


async def test_bytes_that_are_not_mqtt_below_the_mark_end_the_connection_not_the_poll() -> None:
    """What the next fill of the outbox reads below the mark is taken as the read callback
    takes it: bytes that are not MQTT end the connection (the session connects again), and
    the caller that filled the outbox (a poll) goes on."""
    count = 10

    async def broker(stream: anyio.abc.ByteStream) -> None:
        await _take_publishes(stream, count)
        await stream.send(bytes((0x30, 0xFF, 0xFF, 0xFF, 0xFF, 0x7F)))  # below the mark of 41
        await anyio.sleep_forever()

    outbox = Outbox()
    session, listener = await _connected(broker, outbox)
    async with anyio.create_task_group() as tasks:
        tasks.start_soon(listener.serve, broker)
        tasks.start_soon(session.run)
        await _until(lambda: session.connected)
        outbox.put_all([Message("t", b"%d" % n, qos=1) for n in range(count)])
        await anyio.sleep(0.1)
        if _marks():
            assert session.connections == 1  # below the mark: not read yet
        outbox.put(Message("t", b"next", qos=1))  # reads them, and does not raise
        await _until(lambda: session.connections == 2)
        tasks.cancel_scope.cancel()
    assert session.last_error == "a malformed MQTT remaining length"


def _marks() -> bool:
    return _session_push._MARKS


@pytest.mark.parametrize("seed", range(6))
async def test_acknowledgements_and_commands_cut_anywhere_never_wait_for_more(seed: int) -> None:
    """Whatever the broker sends in whatever pieces (PUBACKs and commands, a packet cut
    between two reads), the session never waits for bytes the broker does not owe."""
    rng = random.Random(seed)
    count = rng.randint(1, 6)
    commands = rng.randint(0, 3)

    async def broker(stream: anyio.abc.ByteStream) -> None:
        got = await _take_publishes(stream, count)
        pieces = [puback_packet(Publish.parse(p).packet_id or 0) for p in got]
        pieces += [publish_packet("c", b"", qos=1, packet_id=100 + n) for n in range(commands)]
        rng.shuffle(pieces)
        data = b"".join(pieces)
        cuts = sorted(rng.sample(range(1, len(data)), min(3, len(data) - 1)))
        for start, end in zip([0, *cuts], [*cuts, len(data)], strict=True):
            await stream.send(data[start:end])
            await anyio.sleep(0.01)
        await anyio.sleep_forever()

    outbox = Outbox()
    heard: list[Publish] = []
    session, listener = await _connected(broker, outbox, on_publish=heard.append)
    async with anyio.create_task_group() as tasks:
        tasks.start_soon(listener.serve, broker)
        tasks.start_soon(session.run)
        await _until(lambda: session.connected)
        outbox.put_all([Message("t", b"%d" % n, qos=1) for n in range(count)])
        await _until(lambda: session.delivered == count and len(heard) == commands, 5)
        tasks.cancel_scope.cancel()
    assert not session._inflight, f"seed {seed}"


async def test_a_broker_that_holds_its_acknowledgements_is_still_heard_by_the_keep_alive() -> None:
    """Messages in flight that the broker never acknowledges do not silence it: after each
    PINGREQ the session is woken by any byte, so the PINGRESPs keep the connection."""

    async def broker(stream: anyio.abc.ByteStream) -> None:
        reader = await _connect(stream)
        with contextlib.suppress(anyio.EndOfStream):
            while True:
                for packet in reader.feed(await stream.receive()):
                    if packet.type == PacketType.PINGREQ:
                        await stream.send(bytes((0xD0, 0)))  # PINGRESP, never a PUBACK

    outbox = Outbox()
    listener = await anyio.create_tcp_listener(local_host="127.0.0.1", local_port=0)
    port = listener.extra(anyio.abc.SocketAttribute.local_port)
    hooks = SessionHooks(will=lambda: None, subscriptions=list, on_connect=list,
                         on_publish=lambda publish: None)  # fmt: skip
    session = BrokerSession(Broker("127.0.0.1", port, keepalive=1), outbox, hooks,
                            reconnect_delay=(0.05, 0.05))  # fmt: skip
    async with anyio.create_task_group() as tasks:
        tasks.start_soon(listener.serve, broker)
        tasks.start_soon(session.run)
        await _until(lambda: session.connected)
        outbox.put_all([Message("t", b"%d" % n, qos=1) for n in range(5)])
        await anyio.sleep(2.2)  # two keep-alives
        tasks.cancel_scope.cancel()
    assert session.connections == 1
    assert session.last_error is None
    assert len(outbox) == 5  # never acknowledged: back in the outbox for the next connection

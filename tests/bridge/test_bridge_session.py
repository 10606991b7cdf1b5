"""The broker session against a scripted broker: messages in flight when a connection drops
are sent again first, in order, on the next one; commands are acknowledged and handed on."""

from __future__ import annotations

import contextlib

import anyio
import anyio.abc
import pytest

from aiortu.bridge import Broker, BrokerSession, Message, Outbox, SessionHooks
from aiortu.bridge._packets import (
    Packet,
    PacketReader,
    PacketType,
    Publish,
    publish_packet,
)

pytestmark = pytest.mark.timeout(30)

CONNACK = bytes((0x20, 2, 0, 0))


async def _packets(stream: anyio.abc.ByteStream, reader: PacketReader, count: int) -> list[Packet]:
    got: list[Packet] = []
    while len(got) < count:
        got += reader.feed(await stream.receive())
    return got


async def test_unacknowledged_messages_go_again_first_and_in_order() -> None:
    outbox = Outbox()
    received: list[Publish] = []
    seen: list[list[bytes]] = []
    commands: list[Publish] = []
    done = anyio.Event()

    async def broker(stream: anyio.abc.ByteStream) -> None:
        reader = PacketReader()
        (connect,) = await _packets(stream, reader, 1)
        assert connect.type == PacketType.CONNECT
        await stream.send(CONNACK)
        connection = len(seen)
        seen.append([])
        if connection == 0:
            # Take five messages, acknowledge none, hang up.
            for packet in await _packets(stream, reader, 5):
                seen[0].append(Publish.parse(packet).payload)
            await stream.aclose()
            return
        await stream.send(publish_packet("cmd/x/set", b"1", qos=1, packet_id=77))
        while len(received) < 8:
            for packet in await _packets(stream, reader, 1):
                if packet.type == PacketType.PUBACK:
                    assert packet.body == b"\x00\x4d"  # our command, id 77
                    continue
                publish = Publish.parse(packet)
                received.append(publish)
                seen[1].append(publish.payload)
                await stream.send(bytes((0x40, 2)) + publish.packet_id.to_bytes(2, "big"))
        done.set()

    listener = await anyio.create_tcp_listener(local_host="127.0.0.1", local_port=0)
    port = listener.extra(anyio.abc.SocketAttribute.local_port)
    hooks = SessionHooks(
        will=lambda: None, subscriptions=list, on_connect=list,
        on_publish=commands.append,
    )  # fmt: skip
    session = BrokerSession(Broker("127.0.0.1", port, keepalive=5), outbox, hooks,
                            reconnect_delay=(0.05, 0.05))  # fmt: skip
    async with anyio.create_task_group() as tasks:
        tasks.start_soon(listener.serve, broker)
        for n in range(5):
            outbox.put(Message("t", bytes([n]), qos=1))
        tasks.start_soon(session.run)
        with anyio.fail_after(10):
            while not seen or len(seen[0]) < 5:  # noqa: ASYNC110 - a bounded wait
                await anyio.sleep(0.01)
            for n in range(5, 8):
                outbox.put(Message("t", bytes([n]), qos=1))
            await done.wait()
        tasks.cancel_scope.cancel()
    assert seen[0] == [bytes([n]) for n in range(5)]
    assert [p.payload for p in received] == [bytes([n]) for n in range(8)]
    assert session.delivered == 8
    assert session.connections == 2
    assert [(c.topic, c.payload) for c in commands] == [("cmd/x/set", b"1")]


async def _session_against(answer_pings: bool, seconds: float) -> BrokerSession:
    """A session with a keep-alive of 1 s, `seconds` against a broker that accepts each
    connection and then answers PINGREQs, or says nothing more."""

    async def broker(stream: anyio.abc.ByteStream) -> None:
        reader = PacketReader()
        await _packets(stream, reader, 1)  # CONNECT
        await stream.send(CONNACK)
        # Until the session hangs up (the end of the stream), or the test is over.
        with anyio.move_on_after(seconds + 1), contextlib.suppress(anyio.EndOfStream):
            while True:
                for packet in await _packets(stream, reader, 1):
                    if packet.type == PacketType.PINGREQ and answer_pings:
                        await stream.send(bytes((0xD0, 0)))  # PINGRESP

    listener = await anyio.create_tcp_listener(local_host="127.0.0.1", local_port=0)
    port = listener.extra(anyio.abc.SocketAttribute.local_port)
    hooks = SessionHooks(will=lambda: None, subscriptions=list, on_connect=list,
                         on_publish=lambda publish: None)  # fmt: skip
    session = BrokerSession(Broker("127.0.0.1", port, keepalive=1), Outbox(), hooks,
                            reconnect_delay=(0.05, 0.05))  # fmt: skip
    async with anyio.create_task_group() as tasks:
        tasks.start_soon(listener.serve, broker)
        tasks.start_soon(session.run)
        await anyio.sleep(seconds)
        tasks.cancel_scope.cancel()
    return session


async def test_a_silent_broker_is_left_within_one_and_a_half_keep_alives() -> None:
    session = await _session_against(answer_pings=False, seconds=2.2)
    # Silent for a keep-alive (two pings unanswered) ends each connection: at 1 s and 2 s,
    # and never before a keep-alive (a fourth connection would start before 2.2 s).
    assert 2 <= session.connections <= 3
    assert session.last_error == "the broker said nothing in 1 s"


async def test_a_broker_that_answers_pings_keeps_the_connection() -> None:
    session = await _session_against(answer_pings=True, seconds=2.2)  # two keep-alives
    assert session.connections == 1
    assert session.last_error is None

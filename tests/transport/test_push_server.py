"""Server connections on asyncio's transports: which listeners get them, back-pressure from
the first byte, reads bounded by `max_bytes`, the end of a connection, and the tap offered
only while the task waits with nothing unread."""

from __future__ import annotations

import socket
from pathlib import Path

import anyio
import anyio.abc
import pytest

from aiortu.transport import (
    ConnectionLimit,
    PushServerStream,
    listen_tcp,
    push_listener,
    pushed_listener,
    serve_listener,
)
from tests.tcp_flood import kernel_buffers
from tests.transport.test_listen import _stream_until_blocked

pytestmark = pytest.mark.timeout(30)


async def test_anyio_tcp_listeners_on_asyncio_are_pushed(tmp_path: Path) -> None:
    listener = await listen_tcp("127.0.0.1", 0)
    async with listener:
        assert push_listener(listener)
    unix = await anyio.create_unix_listener(tmp_path / "socket")
    async with unix:
        assert not push_listener(unix)


def test_trio_keeps_anyio_streams() -> None:
    async def scenario() -> bool:
        listener = await listen_tcp("127.0.0.1", 0)
        async with listener:
            return push_listener(listener)

    assert anyio.run(scenario, backend="trio") is False


async def test_a_send_on_a_connection_never_set_up_says_it_is_closed() -> None:
    sock = socket.socket()
    stream = PushServerStream(sock)  # accepted, but its transport never made
    try:
        with anyio.fail_after(5), pytest.raises(anyio.ClosedResourceError):
            await stream.send(b"\x00")
    finally:
        sock.close()


async def test_a_client_streaming_before_the_first_read_is_held_back() -> None:
    """As anyio's streams in test_listen.py: nothing is read before the first receive()."""
    limit = ConnectionLimit("test server", 4)
    received = anyio.Event()

    async def slow(stream: anyio.abc.ByteStream) -> None:
        assert isinstance(stream, PushServerStream)
        await anyio.sleep(0.3)  # the client streams before the first receive()
        assert len(await stream.receive(10)) == 10
        received.set()
        await anyio.sleep_forever()

    listener = await listen_tcp("127.0.0.1", 0)
    port = listener.extra(anyio.abc.SocketAttribute.local_port)
    bound = kernel_buffers() + (1 << 20)
    async with anyio.create_task_group() as tasks:
        tasks.start_soon(serve_listener, pushed_listener(listener), slow, limit)
        sent = await anyio.to_thread.run_sync(_stream_until_blocked, port, bound + (8 << 20))
        await received.wait()
        tasks.cancel_scope.cancel()
    assert sent <= bound, f"{sent} bytes accepted, more than the {bound} the kernel can hold"


async def test_reads_the_tap_and_the_end() -> None:
    """`receive(n)` returns at most n bytes; the tap sees a chunk only while a receive()
    waits with nothing unread (bytes sent meanwhile wait in the socket), and a chunk it
    declines is read as any other; the client's close ends the stream."""
    limit = ConnectionLimit("test server", 4)
    offered: list[bytes] = []
    seen: list[bytes] = []
    ended = anyio.Event()

    def tap(chunk: bytes) -> bool:
        offered.append(chunk)
        return chunk == b"mine"

    async def serve(stream: anyio.abc.ByteStream) -> None:
        assert isinstance(stream, PushServerStream)
        stream.tap = tap
        try:
            while True:
                seen.append(await stream.receive(4))
                await anyio.sleep(0.05)  # busy: what comes meanwhile is not offered
        except anyio.EndOfStream:
            ended.set()

    listener = await listen_tcp("127.0.0.1", 0)
    port = listener.extra(anyio.abc.SocketAttribute.local_port)
    async with anyio.create_task_group() as tasks:
        tasks.start_soon(serve_listener, pushed_listener(listener), serve, limit)
        with socket.create_connection(("127.0.0.1", port)) as client:
            client.sendall(b"mine")  # taken by the tap
            await anyio.sleep(0.2)
            client.sendall(b"0123456789")  # declined: read 4 bytes at a time
            await anyio.sleep(0.01)
            client.sendall(b"mine")  # the task busy: left in the socket until it waits again
            await anyio.sleep(0.3)
            client.sendall(b"late")  # offered again, declined
            await anyio.sleep(0.2)
        with anyio.fail_after(5):
            await ended.wait()
        tasks.cancel_scope.cancel()
    assert offered == [b"mine", b"0123456789", b"mine", b"late"]
    assert b"".join(seen) == b"0123456789late"
    assert all(len(chunk) <= 4 for chunk in seen)


async def test_the_tap_is_offered_a_chunk_only_while_it_may_answer() -> None:
    """The read callback's conditions one by one, on a connected pair: a receive() waiting,
    nothing unread, the client reading its replies."""
    ours, theirs = socket.socketpair()
    offered: list[bytes] = []
    stream = PushServerStream(ours)
    await stream.connect()
    stream.tap = lambda chunk: offered.append(chunk) is None
    with theirs:
        stream.data(b"early")  # no receive() waiting: kept
        assert offered == []
        assert await stream.receive() == b"early"
        async with anyio.create_task_group() as tasks:

            async def read() -> None:
                assert await stream.receive() == b"kept"

            tasks.start_soon(read)
            await anyio.sleep(0.01)  # the task waits
            assert stream.transport is not None
            stream.transport.get_protocol().pause_writing()  # the client reads nothing
            stream.data(b"kept")
            assert offered == []
        stream.transport.get_protocol().resume_writing()

        async def read_both() -> None:
            assert await stream.receive() == b"unreadmore"

        async with anyio.create_task_group() as tasks:
            tasks.start_soon(read_both)
            await anyio.sleep(0.01)
            stream._kept += b"unread"  # bytes not read yet
            stream.data(b"more")
            assert offered == []
        async with anyio.create_task_group() as tasks:
            tasks.start_soon(stream.receive)
            await anyio.sleep(0.01)
            stream.data(b"mine")
            assert offered == [b"mine"]
            stream.data(b"again")
            assert offered == [b"mine", b"again"]
            tasks.cancel_scope.cancel()
        await stream.aclose()

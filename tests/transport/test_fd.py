"""FileDescriptorStream over pty pairs and pipes."""

from __future__ import annotations

import os

import anyio
import pytest

from aiortu.testing import make_raw
from aiortu.transport import FileDescriptorStream

pytestmark = pytest.mark.timeout(10)


@pytest.fixture
def pty_streams():
    master, slave = os.openpty()
    make_raw(slave)
    return FileDescriptorStream(master), FileDescriptorStream(slave)


async def test_bytes_cross_both_ways(pty_streams):
    master, slave = pty_streams
    async with master, slave:
        await master.send(b"\x11\x03\x00\x6b\x00\x03\x76\x87")
        assert await slave.receive() == b"\x11\x03\x00\x6b\x00\x03\x76\x87"
        await slave.send(bytes(range(256)))
        received = b""
        while len(received) < 256:
            received += await master.receive()
        assert received == bytes(range(256))


async def test_large_write_waits_for_room(pty_streams):
    master, slave = pty_streams
    payload = os.urandom(200_000)
    received = bytearray()

    async def reader() -> None:
        while len(received) < len(payload):
            received.extend(await slave.receive())

    async with master, slave, anyio.create_task_group() as tg:
        tg.start_soon(reader)
        await master.send(payload)
    assert bytes(received) == payload


async def test_other_side_closed_is_end_of_stream():
    master, slave = os.openpty()
    stream = FileDescriptorStream(master)
    os.close(slave)
    with pytest.raises(anyio.EndOfStream):
        await stream.receive()
    await stream.aclose()


async def test_write_to_closed_pipe_is_broken():
    read_end, write_end = os.pipe()
    os.close(read_end)
    stream = FileDescriptorStream(write_end)
    with pytest.raises(anyio.BrokenResourceError):
        await stream.send(b"x")
    await stream.aclose()


async def test_use_after_close(pty_streams):
    master, slave = pty_streams
    await master.aclose()
    await master.aclose()
    with pytest.raises(anyio.ClosedResourceError):
        await master.receive()
    with pytest.raises(anyio.ClosedResourceError):
        await master.send(b"x")
    await slave.aclose()


async def test_close_wakes_a_waiting_receiver(pty_streams):
    master, slave = pty_streams
    outcome: list[type[BaseException]] = []

    async def waiter() -> None:
        try:
            await slave.receive()
        except anyio.ClosedResourceError as exc:
            outcome.append(type(exc))

    async with anyio.create_task_group() as tg:
        tg.start_soon(waiter)
        await anyio.wait_all_tasks_blocked()
        await slave.aclose()
    assert outcome == [anyio.ClosedResourceError]
    await master.aclose()


async def test_send_eof_is_not_supported(pty_streams):
    master, slave = pty_streams
    with pytest.raises(NotImplementedError):
        await master.send_eof()
    await master.aclose()
    await slave.aclose()


async def test_borrowed_descriptor_stays_open():
    read_end, write_end = os.pipe()
    stream = FileDescriptorStream(write_end, owns_fd=False)
    await stream.send(b"abc")
    await stream.aclose()
    assert stream.closed
    os.write(write_end, b"d")
    assert os.read(read_end, 10) == b"abcd"
    os.close(read_end)
    os.close(write_end)

"""The push extension: which streams are push streams, and how the link uses one."""

from __future__ import annotations

import os
from collections.abc import Callable

import anyio
import anyio.abc
import pytest
from anyio.streams.stapled import StapledByteStream

from aiortu.core.rtu import FrameReceived, Role
from aiortu.core.serial import LineSettings
from aiortu.line import Link
from aiortu.transport import FileDescriptorStream, PushStream, SerialStream, open_serial
from tests.transport.ptys import LINE, open_pty

FAST = LineSettings(115200)
REQUEST = bytes.fromhex("1103006b00037687")


class _Pipe(anyio.abc.ByteStream):
    """One end of an in-memory line: what it sends goes to *sent*."""

    def __init__(self) -> None:
        self.sent: list[bytes] = []
        self.incoming, self._incoming_reader = anyio.create_memory_object_stream[bytes](16)

    async def receive(self, max_bytes: int = 65536) -> bytes:
        try:
            return await self._incoming_reader.receive()
        except anyio.EndOfStream:
            raise anyio.EndOfStream from None

    async def send(self, item: bytes) -> None:
        self.sent.append(item)

    async def send_eof(self) -> None:
        pass

    async def aclose(self) -> None:
        self.incoming.close()
        self._incoming_reader.close()


class _SendsAtOnce(_Pipe):
    """Has ``send_nowait`` only: half of the extension, so not a push stream."""

    def __init__(self) -> None:
        super().__init__()
        self.sent_at_once: list[bytes] = []

    def send_nowait(self, item: bytes) -> bool:
        self.sent_at_once.append(item)
        return True


class _Pushes(_SendsAtOnce):
    """Both methods: a push stream, with no base class for it."""

    def __init__(self) -> None:
        super().__init__()
        self.receiver: Callable[[bytes], None] | None = None
        self.receivers_set: list[object] = []

    def set_receiver(
        self,
        receiver: Callable[[bytes], None] | None,
        on_lost: Callable[[], None] | None = None,
    ) -> None:
        self.receiver = receiver
        self.receivers_set.append(receiver)


async def test_the_serial_port_is_a_push_stream_and_other_transports_are_not() -> None:
    with open_pty() as pty:
        async with await open_serial(pty.path, LINE) as stream:
            assert isinstance(stream, SerialStream)
            assert isinstance(stream, PushStream)
    master, slave = os.openpty()
    os.close(slave)
    assert not isinstance(FileDescriptorStream(master), PushStream)
    os.close(master)
    assert not isinstance(StapledByteStream(_Pipe(), _Pipe()), PushStream)  # type: ignore[arg-type]
    assert not isinstance(_SendsAtOnce(), PushStream)
    assert isinstance(_Pushes(), PushStream)


async def test_a_stream_with_half_of_the_extension_is_written_through_send() -> None:
    stream = _SendsAtOnce()
    async with Link(stream, FAST, frame_gap=0) as link:
        await link.send(REQUEST)
        assert link.send_now(REQUEST) is None
    assert stream.sent == [REQUEST]
    assert stream.sent_at_once == []


async def test_a_push_stream_feeds_the_link_from_its_receiver_under_asyncio() -> None:
    stream = _Pushes()
    async with Link(stream, FAST, role=Role.SLAVE, units={0x11}, frame_gap=0) as link:
        await anyio.sleep(0.03)  # the reader starts, and sets its receiver
        assert stream.receiver is not None
        assert link.loop is not None
        stream.receiver(REQUEST)
        with anyio.fail_after(2):
            event = await link.receive()
        assert isinstance(event, FrameReceived)
        assert event.frame == REQUEST
        assert link.send_now(REQUEST) is not None
    assert stream.sent_at_once == [REQUEST]
    assert stream.receivers_set[-1] is None  # the reader gave the stream its bytes back


@pytest.mark.parametrize("backend", ["asyncio", "trio"])
def test_under_any_backend_a_push_stream_can_be_read_with_receive(backend: str) -> None:
    async def scenario() -> None:
        stream = _Pushes()
        async with Link(stream, FAST, role=Role.SLAVE, units={0x11}, frame_gap=0) as link:
            await anyio.sleep(0.03)
            if stream.receiver is None:  # trio: no call_at timers, so the link reads
                assert link.loop is None
                await stream.incoming.send(REQUEST)
            else:
                stream.receiver(REQUEST)
            with anyio.fail_after(2):
                event = await link.receive()
            assert isinstance(event, FrameReceived)
            assert event.frame == REQUEST
        assert (stream.receivers_set == []) is (backend == "trio")

    anyio.run(scenario, backend=backend)

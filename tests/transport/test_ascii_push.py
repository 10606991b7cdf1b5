"""Modbus ASCII pushed: which streams take the push path, the shortcuts of the master and the
slave over it, its inter-character timer, 08/03 and a failing callback. The push and the
general paths are compared on random exchanges in test_ascii_push_differential.py."""

from __future__ import annotations

import asyncio
import contextlib
from typing import Any

import anyio
import pytest

import aiortu
from aiortu.core.ascii import AsciiDiscardReason, encode_ascii_frame
from aiortu.core.pdu import RawPDU
from aiortu.core.serial import LineSettings
from aiortu.master import _fast_path
from aiortu.testing import PtyBus, VirtualBus, virtual_pair
from aiortu.transport import (
    AsciiStream,
    PushAsciiStream,
    PushStream,
    ascii_stream,
    open_stream,
    pushes_ascii,
)
from aiortu.transport import _ascii_push as push_module
from tests.virtual_clock import VirtualTimeLoop

pytestmark = pytest.mark.timeout(60)

PTY_LINE: dict[str, Any] = {"bytesize": 8, "parity": "N", "stopbits": 2}
READ = encode_ascii_frame(1, bytes.fromhex("03 0000 0001"))


async def test_ascii_is_pushed_on_a_serial_port_and_on_a_pushing_line_only() -> None:
    async with PtyBus(ports=2) as bus:
        stream = await open_stream(bus.paths[0], LineSettings(19200, **PTY_LINE), framing="ascii")
        async with stream:
            assert type(stream) is PushAsciiStream
            assert isinstance(stream, PushStream)
    pushing, _ = virtual_pair()
    paced, _ = virtual_pair(chunk_size=1)  # a bus that holds bytes on the wire: no push
    assert pushes_ascii(pushing)
    assert type(ascii_stream(pushing)) is PushAsciiStream
    assert not pushes_ascii(paced)
    assert type(ascii_stream(paced)) is AsciiStream
    assert not isinstance(ascii_stream(paced), PushStream)


def test_without_a_running_asyncio_loop_nothing_is_pushed() -> None:
    pushing, _ = virtual_pair()
    assert not pushes_ascii(pushing)
    assert type(ascii_stream(pushing)) is AsciiStream


async def test_the_master_and_the_slave_take_their_shortcuts_over_ascii(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    replies = 0
    on_reply = _fast_path.FastPath.on_reply

    def counted(self: _fast_path.FastPath, frame: bytes, end: float) -> None:
        nonlocal replies
        replies += 1
        on_reply(self, frame, end)

    monkeypatch.setattr(_fast_path.FastPath, "on_reply", counted)
    store = aiortu.MemoryStore(holding_registers={0: list(range(10))})
    async with (
        PtyBus(ports=2) as bus,
        aiortu.serve(bus.paths[1], {17: store}, framing="ascii", **PTY_LINE) as slave,
        aiortu.open_master(bus.paths[0], framing="ascii", timeout=2.0, **PTY_LINE) as master,
    ):
        for count in range(1, 11):
            assert await master.read_holding_registers(17, 0, count) == list(range(count))
        await master.write_register(17, 3, 33)
        assert await master.read_holding_registers(17, 3, 1) == [33]
        assert isinstance(slave.link.stream, PushAsciiStream)
        # Every read took the master's fast path; every request was answered at once.
        assert replies == 11
        assert slave._at_once.answered == 12
        assert slave.link.stream.frames_received == 12
        assert master.link.stream.frames_received == 12


async def test_a_stalled_frame_is_dropped_by_the_timer_at_its_deadline() -> None:
    left, right = virtual_pair()
    stream = ascii_stream(right, timeout=0.1)
    assert isinstance(stream, PushAsciiStream)
    frames: list[bytes] = []
    lost: list[bool] = []
    async with left, stream:
        stream.set_receiver(frames.append, lambda: lost.append(True))
        await left.send(READ[:6])
        await anyio.sleep(0.02)
        assert stream.discarded[AsciiDiscardReason.TIMEOUT] == 0
        with anyio.fail_after(2):
            while not stream.discarded[AsciiDiscardReason.TIMEOUT]:  # noqa: ASYNC110
                await anyio.sleep(0.01)  # no more bytes come: the timer drops the frame
        await left.send(READ[6:] + READ[:3])
        await anyio.sleep(0.02)
        assert frames == []
        await left.send(READ[3:])  # the second frame, in two chunks
        with anyio.fail_after(2):
            while not frames:  # noqa: ASYNC110
                await anyio.sleep(0.01)
        assert lost == []
    assert frames == [bytes.fromhex("01 03 0000 0001 840A")]
    assert stream.discarded == {AsciiDiscardReason.TIMEOUT: 1, AsciiDiscardReason.NOISE: 1}
    assert stream.frames_received == 1
    assert lost == [True]  # the endpoint was closed while the receiver was set


async def test_frames_kept_before_the_receiver_is_set_go_to_it_first() -> None:
    left, right = virtual_pair()
    stream = ascii_stream(right)
    async with left, stream:
        await left.send(READ + READ)
        with anyio.fail_after(2):
            first = await stream.receive()  # the general path: both frames decoded
        frames: list[bytes] = []
        stream.set_receiver(frames.append)
        assert frames == [first]  # the second one, handed over at once
        await left.send(READ)
        with anyio.fail_after(2):
            while len(frames) < 2:  # noqa: ASYNC110
                await anyio.sleep(0.01)
        stream.set_receiver(None)
        await left.send(READ)
        with anyio.fail_after(2):
            assert await stream.receive() == first  # kept for receive() again
    assert stream.frames_received == 4


async def test_change_ascii_input_delimiter_is_honoured_at_both_ends_when_pushed() -> None:
    bus = VirtualBus(2)
    master_end, slave_end = bus.endpoints
    slave_stream = ascii_stream(slave_end)
    master_stream = ascii_stream(master_end)
    assert isinstance(slave_stream, PushAsciiStream)
    assert isinstance(master_stream, PushAsciiStream)
    store = aiortu.MemoryStore(holding_registers={0: [1, 2, 3]})
    async with (
        aiortu.Slave(slave_stream, {17: store}),
        aiortu.Master(master_stream, timeout=1.0, retries=0) as master,
    ):
        assert await master.diagnostics(17, 0x03, b"!\x00") is not None
        assert await master.diagnostics(17, 0x03, b"!\x00") is not None
        assert await master.read_holding_registers(17, 0, 2) == [1, 2]
    sent = [(entry.sender, entry.data) for entry in bus.trace]
    change = bytes.fromhex("08 0003 2100")
    assert sent == [
        (0, encode_ascii_frame(17, change)),
        (1, encode_ascii_frame(17, change)),
        # The same request again: the device now waits for '!'; its replies still end with LF.
        (0, encode_ascii_frame(17, change, delimiter=ord("!"))),
        (1, encode_ascii_frame(17, change)),
        (0, encode_ascii_frame(17, bytes.fromhex("03 0000 0002"), delimiter=ord("!"))),
        (1, encode_ascii_frame(17, bytes.fromhex("03 04 0001 0002"))),
    ]
    assert slave_stream.receiver.delimiter == ord("!")
    assert master_stream.send_delimiters == {17: ord("!")}


async def test_a_failing_callback_ends_the_reader_with_its_error() -> None:
    left, right = virtual_pair()
    stream = ascii_stream(right)
    assert isinstance(stream, PushAsciiStream)
    lost = asyncio.Event()
    bug = RuntimeError("a bug in the consumer")

    def consumer(frame: bytes) -> None:
        raise bug

    async with left, stream:
        stream.set_receiver(consumer, lost.set)
        await left.send(READ)
        with anyio.fail_after(2):
            await lost.wait()
        with pytest.raises(RuntimeError) as caught:
            await stream.receive()
        assert caught.value is bug


@pytest.mark.parametrize("push", [True, False])
async def test_a_short_0803_reply_changes_no_delimiter(push: bool) -> None:
    left, right = virtual_pair()
    stream = ascii_stream(right) if push else AsciiStream(right)
    async with left, stream:
        # 08/03 with no data byte (malformed; the master refuses it), then a full one.
        await left.send(encode_ascii_frame(17, bytes.fromhex("08 0003")))
        with anyio.fail_after(2):
            assert (await stream.receive())[:4] == bytes.fromhex("11 08 0003")
        assert stream.send_delimiters == {}
        await left.send(encode_ascii_frame(17, bytes.fromhex("08 0003 2100")))
        with anyio.fail_after(2):
            await stream.receive()
        assert stream.send_delimiters == {17: ord("!")}


async def test_frames_after_the_receiver_stops_are_kept_for_receive() -> None:
    left, right = virtual_pair()
    stream = ascii_stream(right)
    taken: list[bytes] = []

    def take_one(frame: bytes) -> None:
        taken.append(frame)
        stream.set_receiver(None)  # as a link's reader does when it stops

    async with left, stream:
        stream.set_receiver(take_one)
        await left.send(READ + encode_ascii_frame(2, bytes.fromhex("03 0000 0001")))
        with anyio.fail_after(2):
            second = await stream.receive()  # the second frame of the chunk was kept
    assert [frame[0] for frame in taken] == [1]
    assert second[0] == 2
    assert stream.frames_received == 2


@pytest.mark.parametrize("push", [True, False])
def test_two_frames_in_one_read_are_two_frames(push: bool, monkeypatch: pytest.MonkeyPatch) -> None:
    """One read of the port holds another unit's reply and then the unit's own, of a function
    code whose length the first bytes do not tell: the link takes each as a frame of its own
    (a stream of whole frames has no character time to join them by), skips the first and
    answers with the second, on a virtual clock."""
    if not push:
        monkeypatch.setattr(push_module, "pushes_ascii", lambda stream: False)
    other = encode_ascii_frame(5, bytes.fromhex("41 0102"))
    own = encode_ascii_frame(1, bytes.fromhex("41 0304"))

    async def scenario() -> None:
        port, device = virtual_pair()
        stream = ascii_stream(port)
        assert isinstance(stream, PushAsciiStream) is push

        async def answer() -> None:
            with contextlib.suppress(anyio.EndOfStream):
                while await device.receive():
                    await device.send(other + own)

        async with anyio.create_task_group() as group:
            group.start_soon(answer)
            async with aiortu.Master(stream, LineSettings(19200), timeout=0.5) as master:
                for _ in range(3):
                    assert await master.execute(1, RawPDU(0x41, b"\x09")) == RawPDU(
                        0x41, b"\x03\x04"
                    )
                stats = master.unit_stats(1)
                assert (stats.successes, stats.skipped_frames, stats.failures) == (3, 3, 0)
                assert not master.link.discarded
            group.cancel_scope.cancel()

    anyio.run(scenario, backend="asyncio", backend_options={"loop_factory": VirtualTimeLoop})

"""The serial port's push path: bytes from the read callback, and a Link that uses it."""

from __future__ import annotations

import anyio
import pytest

import aiortu
from aiortu.core.rtu import DiscardReason, FrameDiscarded, FrameReceived, Role, crc16
from aiortu.errors import ConnectionLost, ResponseTimeout
from aiortu.line import Link, ReplyTap
from aiortu.master import Master
from aiortu.transport import open_serial
from tests.transport.ptys import LINE, open_pty, read_master

REPLY = bytes.fromhex("1103060ae10000000000")  # unit 17, FC 03, 3 registers, no CRC yet


def _with_crc(body: bytes) -> bytes:
    crc = crc16(body)
    return body + bytes((crc & 0xFF, crc >> 8))


async def test_receiver_gets_kept_bytes_then_pushed_ones() -> None:
    with open_pty() as pty:
        stream = await open_serial(pty.path, LINE)
        pty.write(b"\x01\x02")
        await anyio.sleep(0.05)  # kept for receive(): no receiver yet
        got: list[bytes] = []
        second = anyio.Event()

        def take(data: bytes) -> None:
            got.append(data)
            if len(got) == 2:
                second.set()

        stream.set_receiver(take)
        assert got == [b"\x01\x02"]
        pty.write(b"\x03")
        with anyio.fail_after(2):
            await second.wait()
        assert got[1] == b"\x03"
        stream.set_receiver(None)
        pty.write(b"\x04")
        with anyio.fail_after(2):
            assert await stream.receive() == b"\x04"
        await stream.aclose()


async def test_on_lost_is_called_at_hangup_and_receive_then_breaks() -> None:
    with open_pty() as pty:
        stream = await open_serial(pty.path, LINE)
        lost = anyio.Event()
        stream.set_receiver(lambda data: None, lost.set)
        pty.close_master()
        with anyio.fail_after(2):
            await lost.wait()
        with pytest.raises(anyio.BrokenResourceError):
            await stream.receive()
        await stream.aclose()


async def test_link_on_a_port_frames_split_chunks_and_times_out_noise() -> None:
    reply = _with_crc(REPLY)
    with open_pty() as pty:
        stream = await open_serial(pty.path, LINE)
        async with Link(stream, LINE, role=Role.MASTER, frame_silence=0.02) as link:
            await anyio.sleep(0.05)  # the power-up silence (INIT) ends on the link's timer
            pty.write(reply[:4])
            await anyio.sleep(0.005)
            pty.write(reply[4:])
            with anyio.fail_after(2):
                event = await link.receive()
            assert isinstance(event, FrameReceived)
            assert event.frame == reply
            pty.write(b"\x11\x03")  # a fragment: only the silence timer ends it
            with anyio.fail_after(2):
                event = await link.receive()
            assert isinstance(event, FrameDiscarded)
            assert event.reason is DiscardReason.TOO_SHORT
            assert event.data == b"\x11\x03"
            pty.close_master()
            with anyio.fail_after(2), pytest.raises(ConnectionLost):
                await link.receive()
            assert link.closed


async def test_master_on_a_port_times_out_on_the_engine_timer_then_reads() -> None:
    reply = _with_crc(bytes.fromhex("0103020007"))  # unit 1, FC 03, one register: 7
    with open_pty() as pty:
        stream = await open_serial(pty.path, LINE)
        request = _with_crc(bytes.fromhex("010300000001"))
        async with Master(stream, LINE, timeout=0.05, retries=0, frame_gap=0) as master:
            for _ in range(2):
                started = anyio.current_time()
                with anyio.fail_after(2), pytest.raises(ResponseTimeout):
                    await master.read_holding_registers(1, 0, 1)
                assert anyio.current_time() - started >= 0.05
                assert await read_master(pty, len(request)) == request  # unanswered
            await anyio.sleep(0.15)  # past the late-reply guard

            async def device() -> None:
                assert await read_master(pty, len(request)) == request
                pty.write(reply)

            async with anyio.create_task_group() as tg:
                tg.start_soon(device)
                with anyio.fail_after(2):
                    assert await master.read_holding_registers(1, 0, 1) == [7]


async def test_an_expected_frame_goes_to_its_callback_and_anything_else_as_events() -> None:
    reply = _with_crc(REPLY)
    with open_pty() as pty:
        stream = await open_serial(pty.path, LINE)
        async with Link(stream, LINE, role=Role.MASTER, frame_silence=0.02) as link:
            await anyio.sleep(0.05)  # past INIT
            taken: list[tuple[bytes, float]] = []
            arrived = anyio.Event()

            def on_frame(frame: bytes, end: float) -> None:
                taken.append((frame, end))
                arrived.set()

            link.expect(ReplyTap(reply[:3], len(reply), on_frame, None))
            # Another unit's frame of the same length is not the one expected.
            other = _with_crc(bytes([18]) + REPLY[1:])
            pty.write(other)
            with anyio.fail_after(2):
                event = await link.receive()
            assert isinstance(event, FrameReceived)
            assert event.frame == other
            assert not taken
            pty.write(reply)
            with anyio.fail_after(2):
                await arrived.wait()
            assert taken[0][0] == reply
            assert taken[0][1] <= link.clock()
            assert link.frames_received == 2
            # Once only: the same frame again comes as an event.
            pty.write(reply)
            with anyio.fail_after(2):
                event = await link.receive()
            assert isinstance(event, FrameReceived)
            # A bad CRC is never handed over: the receiver discards it.
            link.expect(ReplyTap(reply[:3], len(reply), on_frame, None))
            pty.write(reply[:-1] + bytes([reply[-1] ^ 1]))
            with anyio.fail_after(2):
                event = await link.receive()
            assert isinstance(event, FrameDiscarded)
            assert len(taken) == 1
            link.forget_expected()
            pty.write(reply)
            with anyio.fail_after(2):
                event = await link.receive()
            assert isinstance(event, FrameReceived)
            assert len(taken) == 1


async def test_expected_requests_go_to_their_callback_until_stopped() -> None:
    read = _with_crc(bytes.fromhex("0103006b0003"))  # 8 bytes, FC 03
    with open_pty() as pty:
        stream = await open_serial(pty.path, LINE)
        async with Link(stream, LINE, role=Role.SLAVE, frame_silence=0.02) as link:
            await anyio.sleep(0.05)  # past INIT
            taken: list[bytes] = []
            arrived = anyio.Event()

            def on_request(frame: bytes, end: float) -> None:
                assert end <= link.clock()
                taken.append(frame)
                arrived.set()

            link.expect_requests({0x03}, 8, on_request)
            pty.write(read)
            with anyio.fail_after(2):
                await arrived.wait()
            assert taken == [read]
            # Not one of the codes: an event, even at that length.
            other = _with_crc(bytes.fromhex("0105000aff00"))
            pty.write(other)
            with anyio.fail_after(2):
                event = await link.receive()
            assert isinstance(event, FrameReceived)
            assert event.frame == other
            # A bad CRC: the receiver discards it.
            pty.write(read[:-1] + bytes([read[-1] ^ 1]))
            with anyio.fail_after(2):
                event = await link.receive()
            assert isinstance(event, FrameDiscarded)
            assert event.reason is DiscardReason.CRC
            # Persistent, unlike expect(); None stops it.
            arrived = anyio.Event()
            pty.write(read)
            with anyio.fail_after(2):
                await arrived.wait()
            assert len(taken) == 2
            link.expect_requests((), 8, None)
            pty.write(read)
            with anyio.fail_after(2):
                event = await link.receive()
            assert isinstance(event, FrameReceived)
            assert len(taken) == 2
            assert link.frames_received == 4  # not the bad CRC


@pytest.mark.parametrize(
    ("answer", "expected", "skipped", "handed_over"),
    [
        # The usual reply, whole: the link hands it over without an event.
        (["0103020007"], [7], 0, 1),
        # Split in two chunks: the receiver assembles it as usual.
        (["01030200|07"], [7], 0, 0),
        # Another unit first, then ours: the machine has taken the read over, and its
        # table takes the reply.
        (["0203020009", "0103020007"], [7], 1, 0),
        # An exception reply.
        (["018302"], aiortu.ExceptionResponse, 0, 0),
    ],
)
async def test_master_reads_on_a_port_whatever_way_the_reply_comes(
    answer: list[str], expected: object, skipped: int, handed_over: int
) -> None:
    request = _with_crc(bytes.fromhex("010300000001"))
    with open_pty() as pty:
        stream = await open_serial(pty.path, LINE)
        async with Master(stream, LINE, timeout=0.5, retries=0, frame_gap=0) as master:
            await anyio.sleep(0.05)  # past INIT
            link = master.link
            expect = link.expect
            usual_replies: list[bytes] = []

            def counting_expect(tap: ReplyTap) -> None:
                on_frame = tap.on_frame

                def counted(frame: bytes, end: float) -> None:
                    usual_replies.append(frame)
                    on_frame(frame, end)

                expect(ReplyTap(tap.prefix, tap.length, counted, tap.checked))

            link.expect = counting_expect  # type: ignore[method-assign]

            async def device() -> None:
                assert await read_master(pty, len(request)) == request
                for frame in answer:
                    # "|" splits the frame (with its CRC) into two chunks.
                    head, _, tail = frame.partition("|")
                    data = _with_crc(bytes.fromhex(head + tail))
                    cut = len(head) // 2 if tail else len(data)
                    for chunk in (data[:cut], data[cut:]):
                        if chunk:
                            pty.write(chunk)
                            await anyio.sleep(0.005)

            async with anyio.create_task_group() as tg:
                tg.start_soon(device)
                with anyio.fail_after(2):
                    if isinstance(expected, list):
                        assert await master.read_holding_registers(1, 0, 1) == expected
                    else:
                        with pytest.raises(aiortu.ExceptionResponse):
                            await master.read_holding_registers(1, 0, 1)
            stats = master.unit_stats(1)
            assert stats.successes == 1
            assert len(usual_replies) == handed_over
            assert stats.skipped_frames + master.unit_stats(2).skipped_frames == skipped

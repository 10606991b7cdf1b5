"""A slave on a serial port answers what its store answers at once from the read callback.

Over a pty (the serial transport writes without a yield) with ``frame_gap=0``, the
requests the fast paths serve are answered inside the link's read callback, with no task
wake-up; the rest go to the serve loop. Either way the replies, the counters and the
store must be what the same slave gives on a virtual line, where every reply goes out
from the serve loop.
"""

from __future__ import annotations

import contextlib
import dataclasses
import functools
import os
import tty
from typing import Any

import anyio
import pytest

import aiortu
from aiortu.core.machines import SlaveState
from aiortu.core.pdu import RawPDU, ReadHoldingRegistersResponse
from aiortu.core.rtu import CANNOT_KNOW, FrameReceived, encode_frame, expected_response_length
from aiortu.slave import Slave, Table
from aiortu.slave._answer_at_once import FAST_PATHS, Taken
from aiortu.testing import virtual_pair

from .helpers import UNIT, RawMaster, example_store, slave_line

REQUESTS = [
    (UNIT, "03 00 6B 00 03"),  # holding registers
    (UNIT, "01 00 13 00 13"),  # coils
    (UNIT, "02 00 C4 00 16"),  # discrete inputs
    (UNIT, "04 00 08 00 01"),  # input registers
    (UNIT, "06 00 01 00 03"),  # one register written
    (UNIT, "10 00 01 00 02 04 00 0A 01 02"),  # two registers written
    (UNIT, "03 00 6B 00 7E"),  # 126 registers: exception 03
    (UNIT, "03 01 00 00 01"),  # unmapped: exception 02
    (UNIT, "07"),  # no fast path: the serve loop answers
    (UNIT, "08 00 00 12 34"),  # diagnostics, echo
    (5, "03 00 00 00 01"),  # another unit: no reply
    (0, "06 00 02 00 05"),  # broadcast: executed, no reply
    (UNIT, "03 00 00 00 04"),  # sees the broadcast write
    (UNIT, "0B"),  # the event counter after all that
    (UNIT, "0C"),  # and the event log
]


def _reply_due(unit: int) -> bool:
    """Every request in REQUESTS to our unit gets a reply; the other unit's and the
    broadcast none."""
    return unit == UNIT


async def _finished(slave: Slave, frames_before: int) -> None:
    """Wait until *slave*'s line has taken one more frame and the slave is done with it
    (the link's count: restart communications clears the slave's counters)."""
    with anyio.fail_after(5):
        while not (  # noqa: ASYNC110 - polls the slave's state: no event tells it
            slave.link.frames_received > frames_before
            and slave.machine.state is SlaveState.IDLE
            and not slave._queue
        ):
            await anyio.sleep(0.001)


async def _exchange_on_pty(master_fd: int, slave: Slave, frame: bytes, due: bool = True) -> bytes:
    """Write *frame* as the master; return the reply, or b"" when none is *due* (and none
    came by the time the slave was done with the request)."""
    before = slave.link.frames_received
    os.write(master_fd, frame)
    reply = bytearray()
    if not due:
        await _finished(slave, before)
        with pytest.raises(BlockingIOError):
            reply += os.read(master_fd, 256)
        return bytes(reply)
    with anyio.fail_after(5):
        while True:
            length = expected_response_length(bytes(reply))
            if length != CANNOT_KNOW and 0 < length <= len(reply):
                break
            await anyio.wait_readable(master_fd)
            with contextlib.suppress(BlockingIOError):
                reply += os.read(master_fd, 256)
    return bytes(reply)


async def _exchange_on_virtual_line(master: RawMaster, slave: Slave, unit: int, pdu: str) -> bytes:
    """The same on a virtual line."""
    before = slave.link.frames_received
    await master.send_request(unit, pdu)
    if not _reply_due(unit):
        await _finished(slave, before)
        assert master.endpoint.pending == 0
        return b""
    reply = await master.receive_frame(5)
    assert reply is not None
    return reply


@pytest.mark.parametrize("frame_gap", [0.0, 0.004])
async def test_answers_from_the_read_callback_equal_the_serve_loops(frame_gap: float) -> None:
    sent_by_the_serve_loop: list[bytes] = []
    master_fd, port_fd = os.openpty()
    tty.setraw(port_fd)
    os.set_blocking(master_fd, False)
    pty_store = example_store()
    try:
        async with aiortu.serve(
            os.ttyname(port_fd), {UNIT: pty_store}, parity="N", stopbits=2, frame_gap=frame_gap
        ) as slave:
            assert isinstance(slave, Slave)
            send_reply = slave._send_reply

            async def counted(unit: int, reply: Any) -> None:
                sent_by_the_serve_loop.append(reply)
                await send_reply(unit, reply)

            slave._send_reply = counted  # type: ignore[method-assign]
            await anyio.sleep(0.05)  # the receiver first waits for silence
            deliver = slave.link._deliver

            def delivered(events: list[Any]) -> None:
                events_from_the_receiver.extend(events)
                deliver(events)

            events_from_the_receiver: list[Any] = []
            slave.link._deliver = delivered  # type: ignore[method-assign]
            on_pty = [
                await _exchange_on_pty(
                    master_fd, slave, encode_frame(unit, bytes.fromhex(pdu)), _reply_due(unit)
                )
                for unit, pdu in REQUESTS
            ]
            pty_counters = dataclasses.asdict(slave.counters)
            answered_at_once = slave._at_once.answered
    finally:
        for fd in (master_fd, port_fd):
            with contextlib.suppress(OSError):
                os.close(fd)

    async with slave_line() as (master, oracle):
        on_virtual_line = []
        for unit, pdu in REQUESTS:
            on_virtual_line.append(await _exchange_on_virtual_line(master, oracle, unit, pdu))
        oracle_counters = dataclasses.asdict(oracle.counters)
        oracle_store = oracle.units[UNIT]

    assert [reply.hex(" ") for reply in on_pty] == [r.hex(" ") for r in on_virtual_line]
    assert sum(1 for reply in on_pty if reply) == 13  # not the other unit's, nor the broadcast
    assert pty_counters == oracle_counters
    assert isinstance(oracle_store, aiortu.MemoryStore)
    for table, address, count in [
        (Table.COILS, 0x13, 19),
        (Table.HOLDING_REGISTERS, 0, 20),
        (Table.HOLDING_REGISTERS, 0x6B, 3),
    ]:
        assert pty_store.get(table, address, count) == oracle_store.get(table, address, count)
    assert pty_store.get(Table.HOLDING_REGISTERS, 0, 4) == [0, 0x0A, 5, 0xFE]  # broadcast last
    # Only what the fast paths leave to the handlers went through the serve loop's
    # sender: the malformed read (the handler answers 03), 07, 08, the broadcast (no
    # reply) and 0B. Reads, writes and the unmapped read's 02 went from the callback.
    # With a frame gap to keep, every reply waits for it in the serve loop (computed at
    # once all the same).
    codes = [reply[0] if isinstance(reply, bytes) else reply for reply in sent_by_the_serve_loop]
    if frame_gap:
        expected = [
            reply[1] if reply else None
            for (unit, _), reply in zip(REQUESTS, on_pty, strict=True)
            if unit in (UNIT, 0)
        ]
        assert codes == expected
    else:
        assert codes == [0x83, 0x07, 0x08, None, 0x0B, 0x0C]
    # The eight others were computed at once, by the fast paths of their codes.
    at_once = [reply for reply in on_pty if reply and reply[1] & 0x7F in FAST_PATHS]
    assert answered_at_once == len(at_once) - 1 == 8  # less the malformed read's 83
    # The whole 8-byte requests (01 to 06) went from the read callback to the fast paths
    # without the receiver making an event of them, whatever their unit.
    made = [event.frame for event in events_from_the_receiver if type(event) is FrameReceived]
    assert [(frame[0], frame[1]) for frame in made] == [(UNIT, code) for code in (16, 7, 8, 11, 12)]


async def test_a_request_under_way_is_never_dropped_when_the_queue_overflows() -> None:
    _, slave_end = virtual_pair()
    slave = Slave(slave_end, {UNIT: example_store()}, frame_gap=0)
    queue = slave._queue
    taken = Taken(encode_frame(UNIT, bytes.fromhex("07")), bytes.fromhex("07 6D"))
    queue.append(taken)
    other = FrameReceived(encode_frame(9, bytes.fromhex("07")), 0.0, 0.0)
    size = slave.link.queue_size
    for _ in range(size + 5):
        slave._on_link_event(other)
    assert queue[0] is taken
    assert len(queue) == size
    assert slave.link.events_dropped == 6


@contextlib.asynccontextmanager
async def _slave_on_pty(store: aiortu.MemoryStore) -> Any:
    """A slave serving *store* as UNIT on a pty (the push path), and the device's fd."""
    master_fd, port_fd = os.openpty()
    tty.setraw(port_fd)
    os.set_blocking(master_fd, False)
    try:
        async with aiortu.serve(
            os.ttyname(port_fd), {UNIT: store}, parity="N", stopbits=2, frame_gap=0
        ) as slave:
            await anyio.sleep(0.05)  # the receiver first waits for silence
            yield master_fd, slave
    finally:
        for fd in (master_fd, port_fd):
            with contextlib.suppress(OSError):
                os.close(fd)


async def test_listen_only_on_the_push_path_neither_executes_nor_answers() -> None:
    # Reads and single writes are whole 8-byte requests the read callback takes: in
    # listen-only mode they must be monitored only, as on any other line.
    store = example_store()
    async with _slave_on_pty(store) as (master_fd, slave):
        ask = functools.partial(_exchange_on_pty, master_fd, slave, due=False)
        assert await ask(encode_frame(UNIT, bytes.fromhex("08 00 04 00 00"))) == b""
        assert slave.listen_only
        before = dataclasses.asdict(slave.counters)
        monitored = ["03 00 6B 00 03", "06 00 01 00 07", "01 00 13 00 13"]
        monitored.append("10 00 01 00 01 02 00 09")
        for pdu in monitored:
            assert await ask(encode_frame(UNIT, bytes.fromhex(pdu))) == b"", pdu
        assert store.get(Table.HOLDING_REGISTERS, 0, 2) == [0, 0]
        counters = dataclasses.asdict(slave.counters)
        assert counters["server_no_response_count"] == before["server_no_response_count"] + 4
        assert counters["server_message_count"] == before["server_message_count"] + 4
        # Restart communications leaves the mode (itself unanswered); then reads are served.
        assert await ask(encode_frame(UNIT, bytes.fromhex("08 00 01 00 00"))) == b""
        assert not slave.listen_only
        reply = await ask(encode_frame(UNIT, bytes.fromhex("03 00 6B 00 01")), due=True)
        assert reply == encode_frame(UNIT, bytes.fromhex("03 02 AE 41"))
        assert slave.connection_error is None


class _DoublingStore(aiortu.MemoryStore):
    """Not the built-in class: its own read must be called."""

    def read(self, table: Table, address: int, count: int) -> list[int]:
        return [2 * value for value in super().read(table, address, count)]


READ = encode_frame(UNIT, bytes.fromhex("03 00 6B 00 01"))
"""A whole 8-byte request the read callback takes on the push path."""


async def _read_on_pty(configure: Any, store: aiortu.MemoryStore | None = None) -> bytes:
    """Configure a slave on a pty, have it read one register, return the reply frame."""
    async with _slave_on_pty(store or example_store()) as (master_fd, slave):
        configure(slave)
        reply = await _exchange_on_pty(master_fd, slave, READ)
        assert slave.connection_error is None
        return reply


def _answer(pdu_hex: str) -> bytes:
    return encode_frame(UNIT, bytes.fromhex(pdu_hex))


async def test_the_push_path_shows_a_traced_slave_every_frame() -> None:
    seen: list[tuple[str, bytes]] = []
    reply = await _read_on_pty(lambda slave: setattr(slave, "trace", _record(seen)))
    assert reply == _answer("03 02 AE 41")
    assert seen == [("received", READ), ("sent", reply)]


async def test_the_push_path_runs_the_hooks() -> None:
    seen: list[int] = []
    reply = await _read_on_pty(
        lambda slave: slave.before_request(lambda request, context: seen.append(context.unit))
    )
    assert reply == _answer("03 02 AE 41")
    assert seen == [UNIT]


async def test_the_push_path_leaves_a_code_to_the_users_handler() -> None:
    response = ReadHoldingRegistersResponse((7,))
    reply = await _read_on_pty(lambda slave: slave.set_handler(0x03, lambda r, c: response))
    assert reply == _answer("03 02 00 07")


async def test_the_push_path_leaves_other_stores_and_routes_to_them() -> None:
    assert await _read_on_pty(
        lambda slave: None, _DoublingStore(holding_registers={0x6B: [4]})
    ) == _answer("03 02 00 08")
    routed = await _read_on_pty(
        lambda slave: slave.route(Table.HOLDING_REGISTERS, range(0x6B, 0x6C), lambda a: [9])
    )
    assert routed == _answer("03 02 00 09")


def _record(seen: list[tuple[str, bytes]]) -> Any:
    return lambda kind, data: seen.append((kind, data))


def _fresh_slave() -> Slave:
    _, slave_end = virtual_pair()
    units = {UNIT: example_store(), 18: _DoublingStore(holding_registers={0: 1})}
    return Slave(slave_end, units, frame_gap=0)


REFUSALS: dict[str, Any] = {
    "a request queued for the serve loop": lambda s: s._queue.append(Taken(READ, b"\x07\x00")),
    "a request under way": lambda s: s.machine.frame_received(UNIT, 0x03),
    "listen-only mode": lambda s: setattr(s, "listen_only", True),
    "a trace callback": lambda s: setattr(s, "trace", lambda kind, data: None),
    "a before hook": lambda s: s.before_request(lambda request, context: None),
    "an after hook": lambda s: s.after_request(lambda request, context, result: None),
    "the user's handler for the code": lambda s: s.set_handler(0x03, lambda r, c: None),
    "a route on the unit": lambda s: s.route("coils", range(1), lambda access: None),
    "switched off": lambda s: setattr(s._at_once, "enabled", False),
}


@pytest.mark.parametrize("refusal", sorted(REFUSALS))
def test_each_condition_of_the_predicate_refuses_on_its_own(refusal: str) -> None:
    slave = _fresh_slave()
    assert slave._at_once.may_answer(READ[0], READ[1])
    REFUSALS[refusal](slave)
    assert not slave._at_once.may_answer(READ[0], READ[1])


@pytest.mark.parametrize(
    "frame",
    [
        encode_frame(18, bytes.fromhex("03 00 00 00 01")),  # not the built-in store
        encode_frame(0, bytes.fromhex("03 00 00 00 01")),  # a broadcast
        encode_frame(5, bytes.fromhex("03 00 00 00 01")),  # not our unit
        encode_frame(UNIT, bytes.fromhex("05 00 13 FF 00")),  # no fast path for the code
    ],
)
def test_the_predicate_refuses_other_stores_units_and_codes(frame: bytes) -> None:
    assert not _fresh_slave()._at_once.may_answer(frame[0], frame[1])


async def test_a_request_arriving_while_a_handler_awaits_is_answered_after_it() -> None:
    async def slow(request: Any, context: Any) -> Any:
        await anyio.sleep(0.05)
        return RawPDU(0x41, b"\x01")

    async with _slave_on_pty(example_store()) as (master_fd, slave):
        slave.set_handler(0x41, slow)
        os.write(master_fd, encode_frame(UNIT, bytes.fromhex("41")))
        with anyio.fail_after(1):  # 41 has no known length: it ends with silence
            while slave.machine.state is not SlaveState.PROCESSING:  # noqa: ASYNC110
                await anyio.sleep(0.002)
        os.write(master_fd, READ)  # while the handler awaits
        replies = b""
        with anyio.move_on_after(1):
            while len(replies) < 6 + 7:
                await anyio.wait_readable(master_fd)
                with contextlib.suppress(BlockingIOError):
                    replies += os.read(master_fd, 64)
        assert replies == _answer("41 01") + _answer("03 02 AE 41")
        assert slave.connection_error is None


async def test_a_request_behind_a_queued_one_is_answered_after_it() -> None:
    # One chunk, two requests: 05 (no fast path) goes to the serve loop's queue, and the
    # read behind it waits its turn although the machine is still IDLE (the predicate's
    # order condition, the only place it lives).
    write_coil = encode_frame(UNIT, bytes.fromhex("05 00 13 FF 00"))
    async with _slave_on_pty(example_store()) as (master_fd, slave):
        os.write(master_fd, write_coil + READ)
        replies = b""
        with anyio.fail_after(5):
            while len(replies) < len(write_coil) + 7:
                await anyio.wait_readable(master_fd)
                with contextlib.suppress(BlockingIOError):
                    replies += os.read(master_fd, 64)
        assert replies == write_coil + _answer("03 02 AE 41")
        assert slave.connection_error is None

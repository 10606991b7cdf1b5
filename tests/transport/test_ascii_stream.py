"""Modbus ASCII on the master's and the slave's paths: the ASCII stream, `framing="ascii"` on
serial ports, and `ascii+tcp://`."""

from __future__ import annotations

import logging
import random
import socket
from collections.abc import AsyncIterator
from contextlib import asynccontextmanager
from typing import Any

import anyio
import anyio.abc
import pytest

import aiortu
from aiortu.core.ascii import AsciiDiscardReason, encode_ascii_frame
from aiortu.errors import InvalidValue, PortNotFound
from aiortu.testing import PtyBus, virtual_pair
from aiortu.transport import AsciiStream, TcpAddress, open_stream, parse_port_url

pytestmark = pytest.mark.timeout(60)

# A pty keeps neither parity nor 7 data bits: 8N2, the ASCII characters fit.
PTY_LINE: dict[str, Any] = {"bytesize": 8, "parity": "N", "stopbits": 2}


class Tap(anyio.abc.ByteStream):
    """A byte stream that records what is sent through it, and can inject bytes before a send."""

    def __init__(self, stream: anyio.abc.ByteStream) -> None:
        self.stream = stream
        self.sent: list[bytes] = []
        self.before_send = b""

    async def send(self, item: bytes) -> None:
        self.sent.append(bytes(item))
        await self.stream.send(self.before_send + item)

    async def receive(self, max_bytes: int = 65536) -> bytes:
        return await self.stream.receive(max_bytes)

    async def send_eof(self) -> None:
        await self.stream.send_eof()

    async def aclose(self) -> None:
        await self.stream.aclose()


def _store() -> aiortu.MemoryStore:
    return aiortu.MemoryStore(holding_registers={0: [1, 2, 3, 0, 0]}, coils={0: [0] * 8})


@asynccontextmanager
async def ascii_line(
    **slave_options: Any,
) -> AsyncIterator[tuple[aiortu.Master, Tap, Tap, AsciiStream]]:
    """A master and a slave (unit 17) speaking ASCII on an in-memory line; the taps see what
    each end writes; the slave's ASCII stream comes last."""
    left, right = virtual_pair()
    master_tap, slave_tap = Tap(left), Tap(right)
    slave_stream = AsciiStream(slave_tap, **slave_options)
    async with (
        aiortu.Slave(slave_stream, {17: _store()}),
        aiortu.Master(AsciiStream(master_tap), timeout=1.0, retries=0) as master,
    ):
        yield master, master_tap, slave_tap, slave_stream


async def test_a_master_and_a_slave_talk_ascii() -> None:
    async with ascii_line() as (master, master_tap, slave_tap, _):
        assert await master.read_holding_registers(17, 0, 3) == [1, 2, 3]
        await master.write_coils(17, 0, [True, False, True])
        assert await master.read_coils(17, 0, 4) == [True, False, True, False]
        with pytest.raises(aiortu.ExceptionResponse) as caught:
            await master.read_holding_registers(17, 50, 1)
        assert caught.value.code == aiortu.ExceptionCode.ILLEGAL_DATA_ADDRESS
    assert master_tap.sent[0] == encode_ascii_frame(17, bytes.fromhex("03 0000 0003"))
    assert slave_tap.sent[0] == encode_ascii_frame(17, bytes.fromhex("03 06 0001 0002 0003"))
    assert all(frame.startswith(b":") and frame.endswith(b"\r\n") for frame in slave_tap.sent)


async def test_garbage_and_bad_frames_between_requests_are_dropped_and_counted() -> None:
    seed = 3
    rng = random.Random(seed)
    async with ascii_line() as (master, master_tap, _, slave_stream):
        for round_ in range(20):
            noise = bytes(rng.choice(b"0123456789ABCDEFxyz \r\n") for _ in range(rng.randrange(30)))
            master_tap.before_send = noise + b":01030\r\n"  # noise, then an odd frame
            registers = await master.read_holding_registers(17, round_ % 3, 1)
            assert registers == [1 + round_ % 3], f"seed {seed}, round {round_}"
    assert slave_stream.frames_received == 20
    assert slave_stream.discarded[AsciiDiscardReason.MALFORMED] >= 20


async def test_the_slave_stream_counts_what_it_drops() -> None:
    left, right = virtual_pair()
    stream = AsciiStream(right)
    async with left, stream:
        await left.send(b"junk:0103\r\n:010300000001FC\r\n" + encode_ascii_frame(1, b"\x07"))
        with anyio.fail_after(2):
            frame = await stream.receive()
    assert frame[:2] == b"\x01\x07"
    assert stream.discarded == {
        AsciiDiscardReason.NOISE: 1,
        AsciiDiscardReason.MALFORMED: 1,
        AsciiDiscardReason.LRC: 1,
    }
    assert stream.frames_received == 1


async def test_a_stalled_frame_is_dropped_after_the_inter_character_timeout() -> None:
    left, right = virtual_pair()
    stream = AsciiStream(right, timeout=0.1)
    frame = encode_ascii_frame(1, bytes.fromhex("03 0000 0001"))
    received: list[bytes] = []
    done = anyio.Event()

    async def receive() -> None:
        received.append(await stream.receive())
        done.set()

    async with left, stream, anyio.create_task_group() as group:
        group.start_soon(receive)  # reading all along, as a link does
        await left.send(frame[:6])
        await anyio.sleep(0.3)
        assert stream.discarded[AsciiDiscardReason.TIMEOUT] == 1  # dropped at its deadline
        await left.send(frame[6:] + frame)
        with anyio.fail_after(2):
            await done.wait()
    assert received[0][:2] == b"\x01\x03"
    assert stream.discarded[AsciiDiscardReason.TIMEOUT] == 1
    assert stream.frames_received == 1


async def test_change_ascii_input_delimiter_is_honoured_at_both_ends() -> None:
    async with ascii_line() as (master, master_tap, slave_tap, _):
        reply = await master.diagnostics(17, 0x03, b"!\x00")
        assert reply is not None
        assert master_tap.sent[-1].endswith(b"\r\n")  # the request itself ends as before
        assert await master.read_holding_registers(17, 0, 1) == [1]
        assert master_tap.sent[-1].endswith(b"\r!")  # the device now waits for '!'
        assert slave_tap.sent[-1].endswith(b"\r\n")  # the master's own delimiter is LF


async def test_framing_ascii_on_serial_ports_and_the_7_bit_warning(
    caplog: pytest.LogCaptureFixture,
) -> None:
    caplog.set_level(logging.WARNING, logger="aiortu")
    async with PtyBus(ports=2) as bus:
        first, second = bus.paths
        store = _store()
        async with (
            aiortu.serve(second, {17: store}, framing="ascii", **PTY_LINE) as slave,
            aiortu.open_master(first, framing="ascii", timeout=1.0, **PTY_LINE) as master,
        ):
            assert isinstance(slave.link.stream, AsciiStream)
            assert isinstance(master.link.stream, AsciiStream)
            await master.write_registers(17, 3, [7, 8])
            assert await master.read_holding_registers(17, 2, 3) == [3, 7, 8]
    warnings = [r.getMessage() for r in caplog.records if "7 data bits" in r.getMessage()]
    assert len(warnings) == 2
    assert warnings[0].endswith(
        ": Modbus ASCII characters have 7 data bits (7E1, or 7N2 without parity); "
        "opening with 8 as asked (bytesize=7 for the spec's)"
    )


async def test_ascii_over_tcp_both_directions() -> None:
    units = {17: _store()}

    async def serve_line(stream: anyio.abc.ByteStream) -> None:
        async with aiortu.Slave(AsciiStream(stream), units):
            await anyio.sleep_forever()

    listener = await anyio.create_tcp_listener(local_host="127.0.0.1")
    port = listener.extra(anyio.abc.SocketAttribute.local_port)
    async with listener, anyio.create_task_group() as group:
        group.start_soon(listener.serve, serve_line)
        url = f"ascii+tcp://127.0.0.1:{port}"
        assert parse_port_url(url) == TcpAddress("127.0.0.1", port, "ascii")
        async with aiortu.open_master(url, timeout=1.0) as master:
            assert isinstance(master.link.stream, AsciiStream)
            assert await master.read_holding_registers(17, 0, 2) == [1, 2]
        group.cancel_scope.cancel()

    # The other way: aiortu's slave connects to a device server, here a test's ASCII master.
    listener = await anyio.create_tcp_listener(local_host="127.0.0.1")
    port = listener.extra(anyio.abc.SocketAttribute.local_port)
    async with listener, aiortu.serve(f"ascii+tcp://127.0.0.1:{port}", {17: _store()}) as slave:
        assert isinstance(slave.link.stream, AsciiStream)
        connection = await listener.listeners[0].accept()
        async with aiortu.Master(AsciiStream(connection), timeout=1.0) as master:
            assert await master.read_holding_registers(17, 0, 3) == [1, 2, 3]


async def test_a_refused_ascii_tcp_url_is_named_as_given() -> None:
    with socket.socket() as probe:  # a loopback port nothing listens on once it is closed
        probe.bind(("127.0.0.1", 0))
        port = probe.getsockname()[1]
    url = f"ascii+tcp://127.0.0.1:{port}"
    with pytest.raises(
        PortNotFound, match=rf"^ascii\+tcp://127\.0\.0\.1:{port}: connection refused"
    ):
        await open_stream(url)
    with pytest.raises(PortNotFound, match=r"^rtu\+tcp://"):
        await open_stream(f"rtu+tcp://127.0.0.1:{port}", framing="ascii")


async def test_bad_framing_options_are_one_sentence() -> None:
    with pytest.raises(InvalidValue, match=r"^framing must be 'rtu' or 'ascii', not 'asci'$"):
        await open_stream("rtu+tcp://127.0.0.1:1", framing="asci")
    with pytest.raises(InvalidValue, match=r"^ascii_timeout must be given with framing='ascii'"):
        await open_stream("rtu+tcp://127.0.0.1:1", ascii_timeout=2.0)
    with pytest.raises(InvalidValue, match=r"^framing must be 'ascii' for an ascii\+tcp:// URL"):
        await open_stream("ascii+tcp://127.0.0.1:1", framing="rtu")
    with pytest.raises(TypeError, match="Modbus TCP takes no option framing"):
        await open_stream("tcp://127.0.0.1:1", framing="ascii")

"""The one accept loop (`serve_listener`) and the server framings, on loopback: the limit and
its log, back-pressure from the first byte, accept errors (on a virtual clock, the back-off's
times exact), Unix socket modes, and the RTU framing's bounded buffer."""

from __future__ import annotations

import contextlib
import errno
import itertools
import logging
import os
import random
import socket
import stat
from collections.abc import Iterator
from pathlib import Path

import anyio
import anyio.abc
import pytest

from aiortu.core.pdu import ExceptionPDU, encode_exception
from aiortu.core.rtu import MAX_FRAME_LENGTH, crc16, encode_frame
from aiortu.errors import InvalidValue, PortNotFound
from aiortu.testing import virtual_pair
from aiortu.transport import (
    WARNING_INTERVAL,
    ConnectionLimit,
    RtuFraming,
    UnixAddress,
    listen_tcp,
    listen_unix,
    parse_unix_url,
    serve_listener,
)
from tests.tcp_flood import kernel_buffers, send_until_blocked
from tests.virtual_clock import on_virtual_clock

pytestmark = pytest.mark.timeout(60)


def test_the_exception_encoder_is_the_exception_pdus() -> None:
    for code in range(1, 0x80):
        assert encode_exception(code, 2) == ExceptionPDU(code, 2).encode()
    assert encode_exception(0, 1) == b"\x80\x01"  # code 0 still gets its answer
    assert encode_exception(0x83, 1) == b"\x83\x01"


def test_the_rtu_framing_never_holds_more_than_a_frame_between_reads() -> None:
    framing = RtuFraming()
    stream = bytes((17, 0x41)) + bytes(range(256)) * 40  # a user code: its length unknown
    most = 0
    for start in range(0, len(stream), 100):
        framing.feed(stream[start : start + 100])
        most = max(most, framing.buffered)
    assert most <= MAX_FRAME_LENGTH
    assert framing.discarded >= 1
    # ...and it still frames what follows a silence.
    framing.silence()
    request = encode_frame(17, bytes.fromhex("03 0000 0001"))
    assert [adu.pdu for adu in framing.feed(request)] == [bytes.fromhex("03 0000 0001")]
    assert crc16(request[:-2]) == int.from_bytes(request[-2:], "little")


async def _hold(stream: anyio.abc.ByteStream) -> None:
    await anyio.sleep_forever()


async def test_refusals_of_a_burst_are_logged_once(caplog: pytest.LogCaptureFixture) -> None:
    limit = ConnectionLimit("test server", 1)
    listener = await listen_tcp("127.0.0.1", 0)
    port = listener.extra(anyio.abc.SocketAttribute.local_port)
    with caplog.at_level(logging.WARNING, logger="aiortu.transport"):
        async with anyio.create_task_group() as tasks:
            tasks.start_soon(serve_listener, listener, _hold, limit)
            held = await anyio.connect_tcp("127.0.0.1", port)
            for _ in range(20):
                async with await anyio.connect_tcp("127.0.0.1", port) as refused:
                    with pytest.raises((anyio.EndOfStream, anyio.BrokenResourceError)):
                        with anyio.fail_after(5):
                            await refused.receive()
            assert limit.counters.connections_refused == 20
            assert limit.open == 1
            tasks.cancel_scope.cancel()
            await held.aclose()
    refusals = [r for r in caplog.records if "the most allowed" in r.getMessage()]
    assert len(refusals) == 1


async def test_a_client_streaming_before_the_first_read_is_held_back() -> None:
    """The accept loop pauses reading right after accept: a client that streams requests
    that are never read can send no more than the kernel's buffers hold."""
    limit = ConnectionLimit("test server", 4)
    received = anyio.Event()

    async def slow(stream: anyio.abc.ByteStream) -> None:
        await anyio.sleep(0.3)  # the client streams before the first receive()
        await stream.receive(10)
        received.set()
        await anyio.sleep_forever()

    listener = await listen_tcp("127.0.0.1", 0)
    port = listener.extra(anyio.abc.SocketAttribute.local_port)
    bound = kernel_buffers() + (1 << 20)
    async with anyio.create_task_group() as tasks:
        tasks.start_soon(serve_listener, listener, slow, limit)
        sent = await anyio.to_thread.run_sync(_stream_until_blocked, port, bound + (8 << 20))
        await received.wait()
        tasks.cancel_scope.cancel()
    assert sent <= bound, f"{sent} bytes accepted, more than the {bound} the kernel can hold"


def _stream_until_blocked(port: int, most: int) -> int:
    """Send up to `most` bytes of requests without reading; stop once the server has taken
    nothing for 1 s. Return the bytes sent."""
    chunk = bytes.fromhex("0001 0000 0006 11 03 0000 0001") * 4096
    with socket.create_connection(("127.0.0.1", port)) as sock:
        return send_until_blocked(sock, chunk, quiet=1.0, most=most)


class _FailingListener(anyio.abc.SocketListener):
    """A listener whose accepts fail as a process out of descriptors sees, `failures[0]` times,
    then hands over `stream`, then fail `failures[1]` times more, then wait. It notes when
    each accept was called."""

    def __init__(self, stream: anyio.abc.ByteStream, failures: tuple[int, int]) -> None:
        self.stream: anyio.abc.ByteStream | None = stream
        self.failures = list(failures)
        self.calls: list[float] = []

    async def accept(self) -> anyio.abc.SocketStream:
        self.calls.append(anyio.current_time())
        if self.failures[0] or (self.stream is None and self.failures[1]):
            self.failures[0 if self.failures[0] else 1] -= 1
            raise OSError(errno.EMFILE, "Too many open files")
        if self.stream is None:
            await anyio.sleep_forever()
        stream, self.stream = self.stream, None
        return stream  # type: ignore[return-value]  # any byte stream serves

    async def aclose(self) -> None:
        pass

    @property
    def _raw_socket(self) -> socket.socket:
        raise NotImplementedError


@on_virtual_clock
async def test_an_accept_error_backs_off_is_logged_once_and_the_loop_goes_on() -> None:
    near, far = virtual_pair()
    listener = _FailingListener(far, (9, 2))
    limit = ConnectionLimit("test server", 4)

    async def echo(stream: anyio.abc.ByteStream) -> None:
        await stream.send(await stream.receive())

    with _logged("aiortu.transport") as messages:
        async with anyio.create_task_group() as tasks:
            tasks.start_soon(serve_listener, listener, echo, limit)
            await near.send(b"ping")
            assert await near.receive() == b"ping"
            await anyio.sleep(10)
            tasks.cancel_scope.cancel()
    # 10 ms, doubling up to 1 s; from 10 ms again after a connection was accepted.
    backed_off = [later - earlier for earlier, later in itertools.pairwise(listener.calls)]
    assert backed_off == pytest.approx(
        [0.01, 0.02, 0.04, 0.08, 0.16, 0.32, 0.64, 1, 1, 0, 0.01, 0.02]
    )
    assert limit.accept_failures == 11
    failures = [message for message in messages if "cannot accept" in message]
    # Once until a connection is accepted; the next burst, within a minute, at debug level.
    assert len(failures) == 1


@on_virtual_clock
async def test_a_kind_of_trouble_is_a_warning_at_most_once_in_the_interval() -> None:
    limit = ConnectionLimit("test server", 1)
    assert limit.level("refusal") == logging.WARNING
    assert limit.level("accept") == logging.WARNING  # another kind has its own interval
    await anyio.sleep(WARNING_INTERVAL - 1)
    assert limit.level("refusal") == logging.DEBUG
    await anyio.sleep(1)
    assert limit.level("refusal") == logging.WARNING
    assert limit.level("refusal") == logging.DEBUG


@contextlib.contextmanager
def _logged(name: str) -> Iterator[list[str]]:
    """The messages that logger `name` gives meanwhile at WARNING or above."""
    messages: list[str] = []

    class Keep(logging.Handler):
        def emit(self, record: logging.LogRecord) -> None:
            messages.append(record.getMessage())

    logger = logging.getLogger(name)
    handler = Keep(logging.WARNING)
    logger.addHandler(handler)
    try:
        yield messages
    finally:
        logger.removeHandler(handler)


def test_unix_urls_take_a_mode_and_a_group() -> None:
    assert parse_unix_url("tcp://127.0.0.1:1") is None
    assert parse_unix_url("unix:/run/x.sock") == UnixAddress("/run/x.sock")
    assert parse_unix_url("unix:/run/x.sock?mode=0660&group=dialout") == UnixAddress(
        "/run/x.sock", 0o660, "dialout"
    )
    for bad in ("unix:/x?mode=999", "unix:/x?mode=", "unix:/x?owner=me", "unix:/x?mode=1&mode=2"):
        with pytest.raises(InvalidValue):
            parse_unix_url(bad)


async def test_a_unix_socket_gets_the_mode_and_group_asked(tmp_path: Path) -> None:
    path = str(tmp_path / "s.sock")
    group = os.getgid()
    listener = await listen_unix(UnixAddress(path, 0o600, str(group)), f"unix:{path}")
    async with listener:
        info = os.stat(path)
        assert stat.S_IMODE(info.st_mode) == 0o600
        assert info.st_gid == group
    with pytest.raises(PortNotFound, match="no group named"):
        await listen_unix(UnixAddress(str(tmp_path / "t.sock"), None, "no-such-group-x"), "unix:t")


@pytest.mark.parametrize("seed", range(200))
def test_the_rtu_framing_finds_every_request_behind_noise(seed: int) -> None:
    rng = random.Random(seed)
    sent: list[bytes] = []
    stream = b""
    for _ in range(rng.randrange(1, 6)):
        # Noise, then a request: the noise never makes a frame whose CRC checks by chance
        # within this seed's bytes (printed below if it ever did).
        stream += rng.randbytes(rng.randrange(1, 40))
        pdu = bytes((3,)) + rng.randbytes(4)
        sent.append(pdu)
        stream += encode_frame(rng.randrange(1, 248), pdu)
    framing = RtuFraming()
    got: list[bytes] = []
    position = 0
    while position < len(stream):
        size = rng.randrange(1, 64)
        got += [adu.pdu for adu in framing.feed(stream[position : position + size])]
        assert framing.buffered <= MAX_FRAME_LENGTH
        position += size
    got += [adu.pdu for adu in framing.silence()]
    assert got[-len(sent) :] == sent, f"seed {seed}: {stream.hex(' ')}"
    assert framing.buffered == 0

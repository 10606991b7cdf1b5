"""A lost line says what happened to the port in words, once, and keeps the stream's error."""

from __future__ import annotations

import anyio
import anyio.abc
import pytest

from aiortu.errors import ConnectionLost
from aiortu.line import Link
from aiortu.transport import open_serial
from tests.transport.ptys import LINE, open_pty


class _FailingStream(anyio.abc.ByteStream):
    """A stream whose first `receive()` raises `error`."""

    def __init__(self, error: BaseException) -> None:
        self.error = error

    async def receive(self, max_bytes: int = 65536) -> bytes:
        raise self.error

    async def send(self, item: bytes) -> None:
        raise self.error

    async def send_eof(self) -> None:
        pass

    async def aclose(self) -> None:
        pass


async def _lost(link: Link) -> ConnectionLost:
    with anyio.fail_after(2):
        await link.wait_closed()
    with pytest.raises(ConnectionLost) as raised:
        await link.receive()
    return raised.value


def _check_plain(lost: ConnectionLost) -> None:
    message = str(lost)
    assert "Error(" not in message
    assert "(" not in message.replace("the port is gone (", "", 1)
    assert message.count("the line failed") == 1


@pytest.mark.parametrize(
    ("error", "message"),
    [
        (anyio.EndOfStream(), "the line failed: the port closed"),
        (anyio.ClosedResourceError(), "the line failed: the port was closed"),
        (
            OSError(5, "Input/output error"),
            "the line failed: the port is gone (Input/output error)",
        ),
        (
            OSError(2, "No such file or directory", "/dev/ttyUSB0"),
            "the line failed: the port is gone (/dev/ttyUSB0: No such file or directory)",
        ),
        (anyio.BrokenResourceError(), "the line failed: the port is gone"),
    ],
)
async def test_the_cause_is_worded_not_a_repr(error: BaseException, message: str) -> None:
    async with Link(_FailingStream(error), frame_gap=0) as link:
        lost = await _lost(link)
        assert str(lost) == message
        assert lost.__cause__ is error
        assert link.connection_lost_error().__cause__ is error
        _check_plain(lost)


async def test_an_error_without_words_gives_its_cause_words() -> None:
    error = anyio.BrokenResourceError()
    error.__cause__ = OSError(5, "Input/output error")
    async with Link(_FailingStream(error), frame_gap=0) as link:
        lost = await _lost(link)
    assert str(lost) == "the line failed: the port is gone (Input/output error)"


async def test_a_serial_port_that_disappears_is_gone_with_its_path() -> None:
    with open_pty() as pty:
        stream = await open_serial(pty.path, LINE)
        async with Link(stream, LINE, frame_gap=0) as link:
            assert link.loop is not None  # the push path
            pty.close_master()
            lost = await _lost(link)
            with pytest.raises(ConnectionLost) as raised:
                await link.send(b"\x01\x03\x00\x00\x00\x01\x84\x0a")
    expected = (
        f"the line failed: the port is gone ({pty.path}: the serial port failed or disappeared)"
    )
    assert str(lost) == expected
    assert isinstance(lost.__cause__, anyio.BrokenResourceError)
    assert str(raised.value) == expected
    _check_plain(lost)

"""The serial transport over real ptys: settings, data flow, opening errors, echo, hangup."""

from __future__ import annotations

import errno
import os
import termios

import anyio
import pytest

from aiortu.core.serial import LineSettings, Parity
from aiortu.errors import (
    InvalidValue,
    PortBusy,
    PortNotFound,
    PortPermissionDenied,
    UnsupportedSettings,
)
from aiortu.transport import RS485Options, SerialAttribute, SerialStream, open_serial
from tests.transport.ptys import LINE, Pty, open_pty, pty_keeps_even_parity, read_master

REQUEST = bytes.fromhex("1103006b00037687")
REPLY = bytes.fromhex("1103060ae10000000000")


async def receive_exactly(stream: SerialStream, count: int, limit: float = 2.0) -> bytes:
    data = bytearray()
    with anyio.fail_after(limit):
        while len(data) < count:
            data += await stream.receive()
    return bytes(data)


@pytest.mark.parametrize(
    ("settings", "parenb", "cstopb"),
    [
        (LineSettings(9600, 8, "N", 1), False, False),
        (LineSettings(19200, 8, "E", 1), True, False),
        (LineSettings(38400, 8, "N", 2), False, True),
    ],
    ids=["8N1", "8E1", "8N2"],
)
async def test_line_settings_reach_the_tty(
    settings: LineSettings, parenb: bool, cstopb: bool
) -> None:
    with open_pty() as pty:
        if parenb and not pty_keeps_even_parity():
            # The kernel drops parity on ptys: the port must say so, not run 8N1 silently.
            with pytest.raises(UnsupportedSettings, match=f"{pty.path}: .*8E1"):
                await open_serial(pty.path, settings)
            return
        stream = await open_serial(pty.path, settings)
        try:
            _, _, cflag, lflag, ispeed, ospeed, _ = termios.tcgetattr(pty.slave)
            assert cflag & termios.CSIZE == termios.CS8
            assert bool(cflag & termios.PARENB) is parenb
            assert not cflag & termios.PARODD
            assert bool(cflag & termios.CSTOPB) is cstopb
            assert not lflag & (termios.ICANON | termios.ECHO)
            assert ispeed == ospeed == getattr(termios, f"B{settings.baudrate}")
            port = stream.extra(SerialAttribute.serial)
            assert (port.baudrate, port.parity, port.stopbits) == (
                settings.baudrate,
                Parity(settings.parity).value,
                settings.stopbits,
            )
            assert stream.settings == settings
            assert stream.port == pty.path
            assert stream.extra(SerialAttribute.port) == pty.path
        finally:
            await stream.aclose()


async def test_bytes_flow_both_ways() -> None:
    with open_pty() as pty:
        async with await open_serial(pty.path, LINE) as stream:
            await stream.send(REQUEST)
            assert await read_master(pty, len(REQUEST)) == REQUEST
            pty.write(REPLY)
            assert await receive_exactly(stream, len(REPLY)) == REPLY
            # A larger block survives chunking in both directions.
            block = bytes(range(256)) * 16
            async with anyio.create_task_group() as tg:
                tg.start_soon(stream.send, block)
                assert await read_master(pty, len(block)) == block
            pty.write(block[:1000])
            assert await receive_exactly(stream, 1000) == block[:1000]


async def test_receive_honours_max_bytes() -> None:
    with open_pty() as pty:
        async with await open_serial(pty.path, LINE) as stream:
            pty.write(b"abcdef")
            await anyio.sleep(0.05)
            assert await stream.receive(4) == b"abcd"
            assert await stream.receive(4) == b"ef"


async def test_cancelled_receive_loses_nothing() -> None:
    with open_pty() as pty:
        async with await open_serial(pty.path, LINE) as stream:
            with anyio.move_on_after(0.05):
                await stream.receive()
            pty.write(b"\x01\x02")
            assert await receive_exactly(stream, 2) == b"\x01\x02"


async def test_two_receivers_at_once_are_refused() -> None:
    with open_pty() as pty:
        async with await open_serial(pty.path, LINE) as stream, anyio.create_task_group() as tg:
            tg.start_soon(stream.receive)
            await anyio.sleep(0.02)
            with pytest.raises(anyio.BusyResourceError):
                await stream.receive()
            tg.cancel_scope.cancel()


async def test_missing_path_is_port_not_found(tmp_path: os.PathLike[str]) -> None:
    missing = os.path.join(os.fspath(tmp_path), "ttyUSB9")
    with pytest.raises(PortNotFound, match=r"ttyUSB9: no such serial device") as info:
        await open_serial(missing)
    assert info.value.port == missing


async def test_a_file_that_is_not_a_tty_is_port_not_found() -> None:
    with pytest.raises(PortNotFound, match="/dev/null: not a serial device"):
        await open_serial("/dev/null")


async def test_second_exclusive_open_is_port_busy() -> None:
    with open_pty() as pty:
        first = await open_serial(pty.path, LINE)
        with pytest.raises(PortBusy, match=f"{pty.path}: another program has the port open"):
            await open_serial(pty.path, LINE)
        await first.aclose()
        # aclose() releases the lock before it returns.
        second = await open_serial(pty.path, LINE)
        await second.aclose()


async def test_non_exclusive_opens_coexist() -> None:
    with open_pty() as pty:
        first = await open_serial(pty.path, LINE, exclusive=False)
        second = await open_serial(pty.path, LINE, exclusive=False)
        await first.aclose()
        await second.aclose()


async def test_permission_denied(monkeypatch: pytest.MonkeyPatch) -> None:
    # The suite runs as root, which may open anything: make the OS refuse for one path.
    real_open = os.open
    with open_pty() as pty:

        def refusing_open(path: str, flags: int, *args: int) -> int:
            if path == pty.path:
                raise PermissionError(errno.EACCES, os.strerror(errno.EACCES), path)
            return real_open(path, flags, *args)

        monkeypatch.setattr(os, "open", refusing_open)
        with pytest.raises(PortPermissionDenied, match=f"{pty.path}: permission denied.*dialout"):
            await open_serial(pty.path, LINE)


async def test_rs485_on_a_pty_is_unsupported() -> None:
    with open_pty() as pty:
        with pytest.raises(UnsupportedSettings, match=f"{pty.path}: .*RS-485"):
            await open_serial(pty.path, LINE, rs485=RS485Options(delay_before_tx=0.001))
        # The refused open left the port free.
        stream = await open_serial(pty.path, LINE)
        await stream.aclose()


def test_rs485_options_map_to_pyserial() -> None:
    options = RS485Options(
        rts_level_for_tx=False, rts_level_for_rx=True, delay_before_tx=0.002, receive_during_tx=True
    )
    settings = options.to_pyserial()
    assert settings.rts_level_for_tx is False
    assert settings.rts_level_for_rx is True
    assert settings.delay_before_tx == 0.002
    assert settings.delay_before_rx is None
    assert settings.loopback is True
    with pytest.raises(InvalidValue, match="delay_before_rx"):
        RS485Options(delay_before_rx=-1)


async def test_one_and_a_half_stop_bits_need_five_data_bits() -> None:
    with open_pty() as pty, pytest.raises(UnsupportedSettings, match=r"1\.5 stop bits"):
        await open_serial(pty.path, LineSettings(9600, 8, "N", 1.5))


async def echo_back(pty: Pty, sent: bytes, pieces: list[bytes]) -> None:
    """Play an echoing adapter: read what the port sent, return it in *pieces*."""
    assert await read_master(pty, len(sent)) == sent
    for piece in pieces:
        pty.write(piece)
        # Separate reads on the port's side, so the echo really arrives split.
        await anyio.sleep(0.02)


async def test_local_echo_is_stripped_across_reads() -> None:
    with open_pty() as pty:
        async with await open_serial(pty.path, LINE, local_echo=True) as stream:
            await stream.send(REQUEST)
            await echo_back(pty, REQUEST, [REQUEST[:1], REQUEST[1:5], REQUEST[5:] + REPLY[:3]])
            pty.write(REPLY[3:])
            assert await receive_exactly(stream, len(REPLY)) == REPLY
            assert stream.echo is not None
            assert (stream.echo.echoed, stream.echo.mismatches, stream.echo.pending) == (8, 0, 0)
            # Nothing more is waiting: the echo was removed exactly.
            with anyio.move_on_after(0.05):
                extra = await stream.receive()
                pytest.fail(f"unexpected bytes {extra!r}")


async def test_corrupted_echo_is_passed_on_and_counted() -> None:
    with open_pty() as pty:
        async with await open_serial(pty.path, LINE, local_echo=True) as stream:
            await stream.send(REQUEST)
            garbled = REQUEST[:3] + b"\xff" + REQUEST[4:]
            await echo_back(pty, REQUEST, [garbled[:2], garbled[2:]])
            assert await receive_exactly(stream, 5) == garbled[3:]
            assert stream.echo is not None
            assert (stream.echo.echoed, stream.echo.mismatches, stream.echo.pending) == (3, 1, 0)
            # Stripping resumes with the next transmission.
            await stream.send(b"\x01\x02")
            await echo_back(pty, b"\x01\x02", [b"\x01\x02" + REPLY])
            assert await receive_exactly(stream, len(REPLY)) == REPLY


async def test_without_local_echo_nothing_is_stripped() -> None:
    with open_pty() as pty:
        async with await open_serial(pty.path, LINE) as stream:
            assert stream.echo is None
            await stream.send(REQUEST)
            await echo_back(pty, REQUEST, [REQUEST])
            assert await receive_exactly(stream, len(REQUEST)) == REQUEST


async def test_hangup_delivers_what_arrived_then_breaks() -> None:
    with open_pty() as pty:
        stream = await open_serial(pty.path, LINE)
        pty.write(b"\x11\x03")
        await anyio.sleep(0.05)
        pty.close_master()
        assert await receive_exactly(stream, 2) == b"\x11\x03"
        with anyio.fail_after(2), pytest.raises(anyio.BrokenResourceError) as info:
            await stream.receive()
        assert pty.path in str(info.value)
        assert info.value.__cause__ is not None
        with pytest.raises(anyio.BrokenResourceError):
            await stream.send(REQUEST)
        await stream.aclose()


async def test_hangup_wakes_a_waiting_receiver() -> None:
    with open_pty() as pty:
        stream = await open_serial(pty.path, LINE)
        errors: list[BaseException] = []

        async def receiver() -> None:
            try:
                await stream.receive()
            except anyio.BrokenResourceError as exc:
                errors.append(exc)

        with anyio.fail_after(2):
            async with anyio.create_task_group() as tg:
                tg.start_soon(receiver)
                await anyio.sleep(0.05)
                pty.close_master()
        assert len(errors) == 1
        await stream.aclose()


async def test_closed_stream_refuses_use() -> None:
    with open_pty() as pty:
        stream = await open_serial(pty.path, LINE)
        await stream.aclose()
        await stream.aclose()
        with pytest.raises(anyio.ClosedResourceError):
            await stream.receive()
        with pytest.raises(anyio.ClosedResourceError):
            await stream.send(b"\x00")
        assert "closed" in repr(stream)


async def test_aclose_wakes_a_waiting_receiver() -> None:
    with open_pty() as pty:
        stream = await open_serial(pty.path, LINE)
        result: list[BaseException] = []

        async def receiver() -> None:
            try:
                await stream.receive()
            except anyio.ClosedResourceError as exc:
                result.append(exc)

        async with anyio.create_task_group() as tg:
            tg.start_soon(receiver)
            await anyio.sleep(0.02)
            await stream.aclose()
        assert len(result) == 1


async def test_send_eof_refuses_further_sends() -> None:
    with open_pty() as pty:
        async with await open_serial(pty.path, LINE) as stream:
            await stream.send_eof()
            with pytest.raises(anyio.ClosedResourceError):
                await stream.send(b"\x00")
            pty.write(b"\x05")
            assert await receive_exactly(stream, 1) == b"\x05"

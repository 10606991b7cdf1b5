"""A serial port as an anyio byte stream, over pyserial-asyncio-fast.

[`open_serial`][aiortu.transport.open_serial] opens a device path (`/dev/ttyUSB0`,
`/dev/serial/by-id/...`, a pty) with the given [`LineSettings`][aiortu.core.serial.LineSettings] and
returns a [`SerialStream`][aiortu.transport.SerialStream], an `anyio.abc.ByteStream` that the link,
the master and the slave can use like any other stream.

**asyncio only.** pyserial-asyncio-fast drives the port through the asyncio event loop, so
this transport runs on anyio's asyncio backend and nowhere else; under trio, use RTU over
TCP or a pty [`FileDescriptorStream`][aiortu.transport.FileDescriptorStream] instead.

pyserial opens, configures (RS-485 mode included) and closes the port; the bytes go through the
port's file descriptor directly, one non-blocking `read` per readiness event and one `write` per
frame (pyserial's own `read` adds a `select` before and after each read), with the transport
buffering only what the driver does not take at once.
[`SerialStream.set_receiver`][aiortu.transport.SerialStream.set_receiver] hands received bytes
straight from the event loop's read callback to a consumer (the [`Link`][aiortu.line.Link] uses it),
with no task wake-up per chunk.

Errors while opening are [`PortError`][aiortu.errors.PortError] subclasses that name the port and
the cause: [`PortNotFound`][aiortu.errors.PortNotFound] (no such device, or not a serial device),
[`PortBusy`][aiortu.errors.PortBusy] (another program holds the port),
[`PortPermissionDenied`][aiortu.errors.PortPermissionDenied] (EACCES/EPERM: on Linux, join the
`dialout` group) and [`UnsupportedSettings`][aiortu.errors.UnsupportedSettings] (the settings, or
RS-485 mode, refused by the driver).

Errors while running follow anyio's conventions: when the port fails under us (a USB adapter
unplugged, the other end of a pty closed), bytes already received are still delivered, then
[`SerialStream.receive`][aiortu.transport.SerialStream.receive] and
[`SerialStream.send`][aiortu.transport.SerialStream.send] raise `anyio.BrokenResourceError`, chained
to pyserial's error. A serial port has no orderly end, so `anyio.EndOfStream` is never raised. After
[`SerialStream.aclose`][aiortu.transport.SerialStream.aclose] both raise
`anyio.ClosedResourceError`.
"""

from __future__ import annotations

import asyncio
import errno
import os
import sys
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from types import ModuleType
from typing import Any

import anyio
import anyio.lowlevel
import serial
import serial.rs485
from anyio.abc import ByteStream
from serial_asyncio_fast import SerialTransport

from aiortu.core.serial import LineSettings, Parity
from aiortu.errors import (
    InvalidValue,
    PortBusy,
    PortError,
    PortNotFound,
    PortPermissionDenied,
    UnsupportedSettings,
)
from aiortu.transport._echo import LocalEchoFilter
from aiortu.transport._push import PushStream

__all__ = ("RS485Options", "SerialAttribute", "SerialStream", "open_serial")

_READ_BUFFER_LIMIT = 64 * 1024
"""Received bytes held for a slow reader before the port stops being read."""

_CLOSE_TIMEOUT = 2.0
"""Seconds aclose() waits for pending output to drain and the port to close."""

_termios: ModuleType | None
try:
    import termios

    _termios = termios
    _TERMIOS_ERROR: type[Exception] = termios.error
except ImportError:  # pragma: no cover - no termios off POSIX, where pyserial raises OSError
    _termios = None
    _TERMIOS_ERROR = OSError

_CMSPAR = getattr(_termios, "CMSPAR", 0o10000000000)
"""Mark/space parity; Linux has it, and Python's termios does not always name it."""


_NOT_FOUND = frozenset({errno.ENOENT, errno.ENODEV, errno.ENXIO, errno.ENOTDIR, errno.EIO})
_BUSY = frozenset({errno.EBUSY, errno.EAGAIN, errno.EWOULDBLOCK})
_DENIED = frozenset({errno.EACCES, errno.EPERM})


@dataclass(frozen=True, slots=True)
class RS485Options:
    """Kernel RS-485 mode: the driver switches the transceiver with RTS around each write.

    Passed to pyserial as `serial.rs485.RS485Settings` and applied with the `TIOCSRS485` ioctl, so
    it needs a UART driver with RS-485 support; a pty or a plain RS-232 port refuses it and
    [`open_serial`][aiortu.transport.open_serial] raises
    [`UnsupportedSettings`][aiortu.errors.UnsupportedSettings]. Delays are in seconds (the kernel
    keeps milliseconds).
    """

    rts_level_for_tx: bool = True
    """RTS level while transmitting."""
    rts_level_for_rx: bool = False
    """RTS level while receiving."""
    delay_before_tx: float | None = None
    """Seconds between raising RTS and the first bit; None keeps the driver's value."""
    delay_before_rx: float | None = None
    """Seconds between the last bit and releasing RTS; None keeps the driver's value."""
    receive_during_tx: bool = False
    """Keep the receiver on while transmitting: the port then echoes what we send
    (combine with `local_echo=True`)."""

    def __post_init__(self) -> None:
        for name in ("delay_before_tx", "delay_before_rx"):
            value = getattr(self, name)
            if value is not None and not 0 <= value <= 65.535:
                raise InvalidValue(name, value, "0..65.535 seconds, or None")

    def to_pyserial(self) -> Any:
        """The equivalent `serial.rs485.RS485Settings`."""
        return serial.rs485.RS485Settings(
            rts_level_for_tx=self.rts_level_for_tx,
            rts_level_for_rx=self.rts_level_for_rx,
            loopback=self.receive_during_tx,
            delay_before_tx=self.delay_before_tx,
            delay_before_rx=self.delay_before_rx,
        )


class SerialAttribute(anyio.TypedAttributeSet):
    """Typed attributes a [`SerialStream`][aiortu.transport.SerialStream] offers through
    `stream.extra(...)`."""

    port: str = anyio.typed_attribute()
    """The device path the stream was opened with."""
    settings: LineSettings = anyio.typed_attribute()
    """The line settings in force."""
    serial: Any = anyio.typed_attribute()
    """The underlying `serial.Serial`, for modem lines; never read or write it."""


_NO_DATA = (
    "device reports readiness to read but returned no data "
    "(device disconnected or multiple access on port?)"
)
"""What pyserial says of a port that reads as ready but empty (a device gone)."""


class _PortTransport(SerialTransport):
    """pyserial-asyncio-fast's transport, with the port's descriptor read and written
    directly: one `read` system call per readiness event (pyserial's `read` selects
    before and after it) and one `write` per frame. pyserial still opens, configures
    and closes the port; its errors are reported as pyserial reports them.

    The write path is ours from end to end: what the driver does not take at once waits in
    `_pending`, and a writer callback of our own is on the descriptor exactly while something waits,
    taken off in the same call that writes the last byte. (The dependency's own writer stays
    registered once its buffer is empty, and then fails on every pass of the event loop.) The
    protocol is paused while anything waits, so that
    [`SerialStream.send`][aiortu.transport.SerialStream.send] returns once its bytes are with the
    driver.
    """

    def __init__(
        self, loop: asyncio.AbstractEventLoop, protocol: _PortProtocol, serial_instance: Any
    ) -> None:
        super().__init__(loop, protocol, serial_instance)
        self._fd: int = serial_instance.fileno()
        self._port_protocol = protocol
        self._pending = bytearray()
        """Bytes the driver has not taken yet, oldest first."""
        self._watching_writable = False
        """Whether `_on_writable` is registered on the descriptor."""

    def _read_ready(self) -> None:
        try:
            data = os.read(self._fd, self._max_read_size)
        except (BlockingIOError, InterruptedError):
            return
        except OSError as exc:
            self._close(exc=serial.SerialException(f"read failed: {exc}"))
            return
        if not data:
            self._close(exc=serial.SerialException(_NO_DATA))
            return
        protocol = self._port_protocol
        if protocol.receiver is not None and protocol.echo is None:
            protocol.receiver(data)  # what data_received would do, one call shorter
            return
        protocol.data_received(data)

    def can_write_now(self) -> bool:
        """Whether `write_now` would take data: open, and nothing queued before it."""
        return not self._pending and not self._closing

    def write_now(self, data: bytes) -> bool:
        """`write()` straight to the descriptor, where `can_write_now` says yes
        (the rest is queued if the driver takes only part of it); else nothing is
        written. Returns whether `data` was taken."""
        if self._pending or self._closing:
            return False
        self._write_data(data)
        return True

    def write(self, data: bytes | bytearray | memoryview) -> None:
        """Write `data` now, or after the bytes still queued; ignored once closing."""
        if self._closing or not data:
            return
        if self._pending:
            self._pending += data
            return
        self._write_data(data)

    def get_write_buffer_size(self) -> int:
        """Bytes queued that the driver has not taken yet."""
        return len(self._pending)

    def flush(self) -> None:
        """Drop the bytes still queued."""
        self._pending.clear()
        self._stop_watching_writable()

    def abort(self) -> None:
        """Close at once, dropping the bytes still queued."""
        self.flush()
        super().abort()

    def _write_data(self, data: bytes | bytearray | memoryview) -> None:
        try:
            written = os.write(self._fd, data)
        except (BlockingIOError, InterruptedError):
            written = 0
        except OSError as exc:
            self._write_failed(exc)
            return
        if written < len(data):
            self._pending += data[written:]  # the rest when the port can take it
            self._watch_writable()

    def _on_writable(self) -> None:
        """The descriptor can take bytes: write what waits; stop watching once all went."""
        try:
            written = os.write(self._fd, self._pending)
        except (BlockingIOError, InterruptedError):
            return
        except OSError as exc:
            self._write_failed(exc)
            return
        del self._pending[:written]
        if self._pending:
            return
        self._stop_watching_writable()
        if self._closing:
            self._close()  # close() waited for the queued bytes: now it can finish

    def _watch_writable(self) -> None:
        if not self._watching_writable:
            self._loop.add_writer(self._fd, self._on_writable)
            self._watching_writable = True
            self._port_protocol.pause_writing()

    def _stop_watching_writable(self) -> None:
        if self._watching_writable:
            self._loop.remove_writer(self._fd)
            self._watching_writable = False
            self._port_protocol.resume_writing()

    def _write_failed(self, exc: OSError) -> None:
        """The port failed under a write: drop what waits and close with the error, as a
        failed read does. The stream reports it (`BrokenResourceError` chained to it);
        an unplugged adapter is no event loop error."""
        self.flush()
        self._abort(serial.SerialException(f"write failed: {exc}"))


class _PortProtocol(asyncio.Protocol):
    """Collects what the transport reports; the stream waits on its events."""

    def __init__(self, echo: LocalEchoFilter | None) -> None:
        self.echo = echo
        self.transport: asyncio.Transport | None = None
        self.buffer = bytearray()
        self.data_ready = asyncio.Event()
        self.writable = asyncio.Event()
        self.writable.set()
        self.done = asyncio.Event()
        self.lost = False
        self.error: BaseException | None = None
        self._reading_paused = False
        self.receiver: Callable[[bytes], None] | None = None
        """While set, received bytes go straight to it instead of to `buffer`."""
        self.on_lost: Callable[[], None] | None = None
        """Called once the port has failed or closed, while a receiver is set."""

    def connection_made(self, transport: asyncio.BaseTransport) -> None:
        assert isinstance(transport, asyncio.Transport)
        self.transport = transport

    def data_received(self, data: bytes) -> None:
        if self.echo is not None:
            data = self.echo.feed(data)
        if not data:
            return
        receiver = self.receiver
        if receiver is not None:
            receiver(data)
            return
        self.buffer += data
        self.data_ready.set()
        if len(self.buffer) > _READ_BUFFER_LIMIT and not self._reading_paused:
            assert self.transport is not None
            self._reading_paused = True
            self.transport.pause_reading()

    def take(self, max_bytes: int) -> bytes:
        chunk = bytes(self.buffer[:max_bytes])
        del self.buffer[:max_bytes]
        if self._reading_paused and len(self.buffer) <= _READ_BUFFER_LIMIT // 2 and not self.lost:
            assert self.transport is not None
            self._reading_paused = False
            self.transport.resume_reading()
        return chunk

    def pause_writing(self) -> None:
        self.writable.clear()

    def resume_writing(self) -> None:
        self.writable.set()

    def connection_lost(self, exc: Exception | None) -> None:
        self.lost = True
        self.error = exc
        # Wake every waiter so that it sees the loss.
        self.data_ready.set()
        self.writable.set()
        self.done.set()
        if self.on_lost is not None:
            self.on_lost()


_LINUX: bool = sys.platform.startswith("linux")


def _is_pseudo_terminal(fd: int) -> bool:
    """Whether `fd` is a pseudo-terminal (Linux: device majors 136 to 143; elsewhere
    by its name)."""
    try:
        if _LINUX:
            return 136 <= os.major(os.fstat(fd).st_rdev) <= 143
        name = os.ttyname(fd)
    except OSError:
        return False
    return name.startswith(("/dev/pts/", "/dev/ttys", "/dev/pty"))


class SerialStream(ByteStream, PushStream):
    """An open serial port as a byte stream. Made by [`open_serial`][aiortu.transport.open_serial].

    [`receive`][aiortu.transport.SerialStream.receive] returns the bytes as the port delivers them
    (with the local echo removed when asked); [`send`][aiortu.transport.SerialStream.send] returns
    once the transport has handed every byte to the OS driver, which then clocks them out at the
    baud rate. One task may receive while another sends; two concurrent receivers (or senders) raise
    `anyio.BusyResourceError`.
    """

    def __init__(
        self,
        port: str,
        settings: LineSettings,
        transport: _PortTransport,
        protocol: _PortProtocol,
        serial_instance: Any,
    ) -> None:
        self._port = port
        self._settings = settings
        self._transport = transport
        self._protocol = protocol
        self._serial = serial_instance
        self._closed = False
        self._eof_sent = False
        self._receive_guard = anyio.ResourceGuard("reading from")
        self._send_guard = anyio.ResourceGuard("writing to")
        self._backend: Any = None

    @property
    def wire_timed(self) -> bool:
        """Whether bytes take their wire time at the baud rate: true for a real port,
        false for a pseudo-terminal, which delivers at once whatever the baud rate
        (see [`aiortu.line.Link.wire_timed`][aiortu.line.Link.wire_timed])."""
        return not _is_pseudo_terminal(self._serial.fileno())

    @property
    def port(self) -> str:
        """The device path this stream was opened with."""
        return self._port

    @property
    def settings(self) -> LineSettings:
        """The line settings in force."""
        return self._settings

    @property
    def echo(self) -> LocalEchoFilter | None:
        """The local echo filter with its counters, or None when `local_echo` is off."""
        return self._protocol.echo

    @property
    def extra_attributes(self) -> Mapping[Any, Callable[[], Any]]:
        """The [`SerialAttribute`][aiortu.transport.SerialAttribute] values, for
        `stream.extra(...)`."""
        return {
            SerialAttribute.port: lambda: self._port,
            SerialAttribute.settings: lambda: self._settings,
            SerialAttribute.serial: lambda: self._serial,
        }

    def _broken(self) -> anyio.BrokenResourceError:
        error = anyio.BrokenResourceError(f"{self._port}: the serial port failed or disappeared")
        error.__cause__ = self._protocol.error
        return error

    def set_receiver(
        self,
        receiver: Callable[[bytes], None] | None,
        on_lost: Callable[[], None] | None = None,
    ) -> None:
        """Hand received bytes to `receiver` as they arrive, from the event loop's read callback,
        instead of keeping them for [`receive`][aiortu.transport.SerialStream.receive] (`None` keeps
        them again).

        Bytes already kept go to `receiver` at once. `on_lost` is called once the port has failed or
        closed (at once if it already has); [`receive`][aiortu.transport.SerialStream.receive] then
        raises the error. While a receiver is set, nothing is left for
        [`receive`][aiortu.transport.SerialStream.receive] to return. This is how a
        [`Link`][aiortu.line.Link] reads the port without a task wake-up per chunk.
        """
        protocol = self._protocol
        protocol.receiver = receiver
        protocol.on_lost = on_lost if receiver is not None else None
        if receiver is None:
            return
        if protocol.buffer:
            receiver(protocol.take(len(protocol.buffer)))
        if (protocol.lost or self._closed) and on_lost is not None:
            on_lost()

    async def receive(self, max_bytes: int = 65536) -> bytes:
        """Return the next chunk of received bytes, at most `max_bytes`, waiting for one.

        Raises `anyio.BrokenResourceError` once the port has failed and every byte
        received before the failure was returned, and `anyio.ClosedResourceError`
        after [`aclose`][aiortu.transport.SerialStream.aclose].
        """
        if max_bytes < 1:
            raise ValueError("max_bytes must be at least 1")
        with self._receive_guard:
            protocol = self._protocol
            if protocol.buffer or protocol.lost or self._closed:
                # Nothing to wait for: still a checkpoint, so that a reader of a flood
                # lets other tasks run. When it waits, the wait is the checkpoint.
                await anyio.lowlevel.checkpoint()
            while True:
                if self._closed:
                    raise anyio.ClosedResourceError
                if protocol.buffer:
                    return protocol.take(max_bytes)
                if protocol.lost:
                    raise self._broken()
                protocol.data_ready.clear()
                await protocol.data_ready.wait()

    def send_nowait(self, item: bytes) -> bool:
        """Write `item` now, without a yield, if the port can take it; return whether it
        did.

        False means nothing was written: the port is closed or failed, or earlier bytes still wait
        in the transport; [`send`][aiortu.transport.SerialStream.send] then says why or waits its
        turn. True means the transport has the bytes: the driver took them, or the few it could not
        take yet follow as soon as it can (a failure there closes the port, as for
        [`send`][aiortu.transport.SerialStream.send]). A [`Link`][aiortu.line.Link] writes its
        frames this way, in the loop iteration that decided to send them.
        """
        protocol = self._protocol
        transport = self._transport
        if self._closed or self._eof_sent or protocol.lost:
            return False
        echo = protocol.echo
        if echo is None:
            return transport.write_now(item)
        if not transport.can_write_now():
            return False
        echo.expect(item)  # before the write: the echo may come back at once
        return transport.write_now(item)

    async def send(self, item: bytes) -> None:
        """Write all of `item` and wait until the transport has handed it to the driver.

        Yields to the event loop only while the driver's buffer is full (the bytes are
        then waiting in the transport); a write the driver takes at once returns without
        a yield.

        If the caller is cancelled while waiting, the bytes still go out: they are already queued.
        Raises `anyio.BrokenResourceError` if the port has failed and `anyio.ClosedResourceError`
        after [`aclose`][aiortu.transport.SerialStream.aclose] or
        [`send_eof`][aiortu.transport.SerialStream.send_eof].
        """
        with self._send_guard:
            # A cancellation point, but no yield unless the driver's buffer is full: a
            # request goes out in the same loop iteration that sends it.
            if self._backend is None:
                self._backend = anyio.lowlevel.current_token().backend_class
            await self._backend.checkpoint_if_cancelled()
            if self._closed or self._eof_sent:
                raise anyio.ClosedResourceError
            if self._protocol.lost or self._transport.is_closing():
                raise self._broken()
            if not item:
                return
            if self._protocol.echo is not None:
                # Before the write: the echo may be read in the same loop iteration.
                self._protocol.echo.expect(item)
            self._transport.write(item)
            writable = self._protocol.writable
            if not writable.is_set():
                await writable.wait()
            if self._closed:
                raise anyio.ClosedResourceError
            # The transport reports a failed write by closing itself, not by raising.
            if self._protocol.lost or self._transport.is_closing():
                raise self._broken()

    async def send_eof(self) -> None:
        """Refuse further sends; the line itself has no end-of-file to transmit."""
        await anyio.lowlevel.checkpoint()
        self._eof_sent = True

    async def aclose(self) -> None:
        """Close the port, letting pending output drain first (for at most 2 s).

        Idempotent; waits until the port is really released, so that it can be reopened
        at once.
        """
        if not self._closed:
            self._closed = True
            self._protocol.data_ready.set()
            self._protocol.writable.set()
            if self._protocol.on_lost is not None:
                self._protocol.on_lost()
            if not self._transport.is_closing():
                self._transport.close()
            with anyio.move_on_after(_CLOSE_TIMEOUT, shield=True):
                await self._protocol.done.wait()
            # Output stuck behind flow control: drop it. While output is still buffered the
            # transport has not started closing the port, so aborting cannot close it twice.
            if not self._protocol.done.is_set() and self._transport.get_write_buffer_size():
                self._transport.abort()
                with anyio.move_on_after(_CLOSE_TIMEOUT, shield=True):
                    await self._protocol.done.wait()
        await anyio.lowlevel.checkpoint()

    def __repr__(self) -> str:
        state = "closed" if self._closed else "lost" if self._protocol.lost else "open"
        return f"<SerialStream {self._port} {self._settings} {state}>"


def _errno_of(exc: BaseException) -> int | None:
    """The OS error number behind a pyserial or termios error, if one is known."""
    seen: BaseException | None = exc
    while seen is not None:
        number = getattr(seen, "errno", None)
        if isinstance(number, int):
            return number
        if isinstance(seen, _TERMIOS_ERROR) and seen.args and isinstance(seen.args[0], int):
            return int(seen.args[0])
        seen = seen.__cause__ or seen.__context__
    return None


def _open_error(port: str, exc: BaseException, what: str) -> PortError:
    """Translate an error raised while opening `port` into aiortu's error for it."""
    number = _errno_of(exc)
    if isinstance(exc, ValueError):
        return UnsupportedSettings(port, f"the port refuses {what}: {exc}")
    cause = os.strerror(number) if number is not None else str(exc)
    if number == errno.ENOTTY:
        return PortNotFound(port, f"not a serial device ({cause})")
    if number == errno.EISDIR:
        return PortNotFound(port, "a directory, not a device file")
    if number in _NOT_FOUND:
        return PortNotFound(port, f"no such serial device ({cause})")
    if number in _BUSY:
        return PortBusy(port, f"another program has the port open ({cause})")
    if number in _DENIED:
        return PortPermissionDenied(
            port,
            "permission denied: give the user access to the device "
            f"(on Linux, add it to the 'dialout' group) ({cause})",
        )
    if number == errno.EINVAL:
        return UnsupportedSettings(port, f"the port refuses {what} ({cause})")
    return PortError(port, f"cannot open the port: {exc}")


def _new_serial(
    port: str, settings: LineSettings, exclusive: bool, rs485: RS485Options | None
) -> Any:
    """A configured but unopened `serial.Serial`."""
    if os.name == "posix" and settings.stopbits == 1.5 and settings.bytesize != 5:
        # termios has no 1.5 stop bits: pyserial would quietly use 2.
        raise UnsupportedSettings(port, "1.5 stop bits exist only with 5 data bits on POSIX")
    try:
        instance = serial.Serial()
        instance.baudrate = settings.baudrate
        instance.bytesize = settings.bytesize
        instance.parity = Parity(settings.parity).value
        instance.stopbits = settings.stopbits
        instance.exclusive = exclusive
        if rs485 is not None:
            instance.rs485_mode = rs485.to_pyserial()
        instance.port = port
    except ValueError as exc:
        raise UnsupportedSettings(port, f"the settings {settings} are refused: {exc}") from exc
    return instance


def _applied_format(fd: int) -> str | None:
    """The character format the tty really has, as `8E1`; None where termios is missing."""
    if _termios is None:
        return None
    cflag = _termios.tcgetattr(fd)[2]
    bytesize = {_termios.CS5: 5, _termios.CS6: 6, _termios.CS7: 7, _termios.CS8: 8}.get(
        cflag & _termios.CSIZE, 0
    )
    if not cflag & _termios.PARENB:
        parity = Parity.NONE
    elif cflag & _CMSPAR:
        parity = Parity.MARK if cflag & _termios.PARODD else Parity.SPACE
    else:
        parity = Parity.ODD if cflag & _termios.PARODD else Parity.EVEN
    stopbits = 2 if cflag & _termios.CSTOPB else 1
    return f"{bytesize}{parity.value}{stopbits}"


def _expected_format(settings: LineSettings) -> str:
    stopbits = 1 if settings.stopbits == 1 else 2  # termios spells 1.5 as 2 (CSTOPB)
    return f"{settings.bytesize}{Parity(settings.parity).value}{stopbits}"


def _open(port: str, instance: Any, settings: LineSettings, what: str) -> None:
    """Open and check the port; runs in a worker thread, as opening may block."""
    try:
        instance.open()
    except (serial.SerialException, OSError, ValueError, _TERMIOS_ERROR) as exc:
        raise _open_error(port, exc, what) from exc
    try:
        # Some drivers accept tcsetattr() and quietly keep other settings.
        applied = _applied_format(instance.fileno())
    except (OSError, _TERMIOS_ERROR) as exc:
        instance.close()
        raise _open_error(port, exc, what) from exc
    if applied is not None and applied != _expected_format(settings):
        asked = _expected_format(settings)
        hint = _pty_hint(applied, asked) if _is_pseudo_terminal(instance.fileno()) else ""
        instance.close()
        raise UnsupportedSettings(port, f"the driver kept {applied} instead of {asked}{hint}")


def _pty_hint(applied: str, asked: str) -> str:
    """Why a pty kept `applied` where `asked` was asked, and what to open it with instead:
    a pty keeps no parity bit, and 8 data bits whatever it is told (Modbus ASCII's 7 too)."""
    if applied[0] != asked[0]:
        return (
            "; a pseudo-terminal keeps 8 data bits and no parity bit: open it with 8 data bits, "
            "parity N and 2 stop bits (8N2, the same character time as 8E1; for Modbus ASCII "
            "too, as long as both ends use it)"
        )
    return (
        "; a pseudo-terminal keeps no parity bit: open it with parity N and 2 stop bits (8N2, "
        "the same character time as 8E1)"
    )


def _running_loop() -> asyncio.AbstractEventLoop:
    try:
        return asyncio.get_running_loop()
    except RuntimeError:
        raise RuntimeError(
            "open_serial() runs on asyncio only (pyserial-asyncio-fast); under trio, use "
            "RTU over TCP or a pty FileDescriptorStream"
        ) from None


async def open_serial(
    port: str,
    settings: LineSettings = LineSettings(),  # noqa: B008 - frozen, safe to share
    *,
    exclusive: bool = True,
    rs485: RS485Options | None = None,
    local_echo: bool = False,
) -> SerialStream:
    """Open the serial device `port` with `settings` and return it as a byte stream.

    `exclusive` locks the port (`flock`) so that a second program using the same
    convention gets [`PortBusy`][aiortu.errors.PortBusy] instead of stealing bytes. `rs485`
    turns on the driver's RS-485 mode. `local_echo` strips the echo of our own
    transmissions that some RS-485 adapters return (see [`aiortu.transport`][aiortu.transport] for
    what happens when the echo does not match).

    Raises [`PortNotFound`][aiortu.errors.PortNotFound], [`PortBusy`][aiortu.errors.PortBusy],
    [`PortPermissionDenied`][aiortu.errors.PortPermissionDenied] or
    [`UnsupportedSettings`][aiortu.errors.UnsupportedSettings], each naming the port and the cause,
    and `RuntimeError` when not running on asyncio.
    """
    loop = _running_loop()
    instance = _new_serial(port, settings, exclusive, rs485)
    what = f"the settings {settings}" + (" with RS-485 mode" if rs485 is not None else "")
    # Shielded: a cancellation arriving while the worker thread opens the port would
    # otherwise leave the port open with nobody to close it.
    with anyio.CancelScope(shield=True):
        await anyio.to_thread.run_sync(_open, port, instance, settings, what)
    protocol = _PortProtocol(LocalEchoFilter() if local_echo else None)
    try:
        # The transport sets non-blocking timeouts, which reconfigures the open port.
        transport = _PortTransport(loop, protocol, instance)
    except (serial.SerialException, OSError, ValueError, _TERMIOS_ERROR) as exc:
        instance.close()
        raise _open_error(port, exc, what) from exc
    return SerialStream(port, settings, transport, protocol, instance)

"""A virtual RS-485 bus over pseudo-terminals, so that any program can sit on it by device path.

[`PtyBus`][aiortu.testing.PtyBus] opens one pseudo-terminal per port. Each port's slave device
(`/dev/pts/N`, in [`PtyBus.paths`][aiortu.testing.PtyBus.paths]) is what other programs open:
pyserial, pymodbus, mbpoll, C programs using libmodbus. A relay reads what each program writes (from
the pty master, through [`FileDescriptorStream`][aiortu.transport.FileDescriptorStream]) and puts it
on a [`VirtualBus`][aiortu.testing.VirtualBus], whose wire model does the pacing, adapter chunking,
faults, collision counting and trace; what the bus delivers to a port is written to that port's
master, where the program reads it.

Port lifetime: the relay keeps every slave open itself, so a program that closes its
port and opens it again finds it working; without that, the last close would hang the
pty up and reads of the master would fail with `EIO`.

Who has a port open: on Linux the relay watches the slave devices with inotify and counts the opens
and closes by other programs. Bytes for a port that no program has open are dropped, as on a cable
that nobody listens to, so a program that opens a port late never reads earlier traffic. When the
last program closes a port, the relay flushes the port's input and puts back the bus's raw settings.
Where inotify is missing, bytes for a port nobody has open wait in the pty's kernel buffer and then
in the bus's bounded receive buffer for the port (oldest dropped first); pyserial discards them on
open, and [`PtyBus.discard_input`][aiortu.testing.PtyBus.discard_input] does it by hand. Either way
a port that nobody reads never stalls the bus or the other ports.

Parity on a pty: Linux ptys have no parity and clear `PARENB` from every setting, and
glibc's `tcsetattr` reports `EINVAL` when the flags it asked for did not all stick
and nothing else changed. The relay leaves idle ports in raw mode plus two echo flags that
are inert without ECHO and that raw-mode programs clear, so a program's first
configuration of a port always succeeds, with any parity. A second configuration with
the same settings still fails with parity E or O: pyserial's `timeout` setter does this
(and pymodbus's serial server with it), as does closing and at once reopening the port
before the relay has seen the close. Programs that reconfigure an open port are best run
with parity N on a pty bus; the bus paces by its own `settings` anyway.

Two ways to relay: on an unpaced bus with no adapter model and no faults, under asyncio,
the relay reads a port's master from an event-loop reader callback, puts the bytes on the
bus and writes what the bus delivered straight to the other ports' masters, in the same
callback (a port whose master is full keeps the rest and takes it up again in a writer
callback, with the bus's bounded receive buffer behind it). Otherwise two tasks per port
carry the bytes, one reading the master onto the bus, one writing what the bus delivers
at its paced times back to the master. Both follow the open-port tracking above, and both
keep the same trace.

The slave devices are put in raw mode when created (no echo, no line editing, no
translation of bytes), which is how serial libraries set them anyway, and back in it when
the last program closes them.
"""

from __future__ import annotations

import asyncio
import contextlib
import ctypes
import fcntl
import os
import select
import struct
import termios
from collections.abc import Callable, Iterator
from types import TracebackType

import anyio
import anyio.abc
import anyio.from_thread

from aiortu.core.serial import LineSettings
from aiortu.errors import PortBusy
from aiortu.testing._faults import FaultPlan
from aiortu.testing._virtual_bus import TraceEntry, VirtualBus
from aiortu.transport import FileDescriptorStream

_LINK_LOCK = ".virtual-bus.lock"
"""The file in a bus's `link_dir` that it holds locked while it runs."""

__all__ = ("PtyBus", "make_raw")


def make_raw(fd: int, baudrate: int | None = None) -> None:
    """Put the terminal `fd` in raw 8-bit mode, and set its nominal speed to `baudrate`.

    A pty has no real baud rate; the speed is only reported to programs that ask.
    """
    iflag, oflag, cflag, lflag, ispeed, ospeed, cc = termios.tcgetattr(fd)
    iflag &= ~(
        termios.IGNBRK
        | termios.BRKINT
        | termios.PARMRK
        | termios.ISTRIP
        | termios.INLCR
        | termios.IGNCR
        | termios.ICRNL
        | termios.IXON
        | termios.IXOFF
        | termios.IXANY
    )
    oflag &= ~termios.OPOST
    lflag &= ~(termios.ECHO | termios.ECHONL | termios.ICANON | termios.ISIG | termios.IEXTEN)
    cflag = (cflag & ~(termios.CSIZE | termios.PARENB)) | termios.CS8 | termios.CREAD
    cflag |= termios.CLOCAL
    cc[termios.VMIN] = 1
    cc[termios.VTIME] = 0
    speed = getattr(termios, f"B{baudrate}", None) if baudrate is not None else None
    if speed is not None:
        ispeed = ospeed = speed
    termios.tcsetattr(fd, termios.TCSANOW, [iflag, oflag, cflag, lflag, ispeed, ospeed, cc])


_IN_CLOSE_WRITE = 0x08
_IN_CLOSE_NOWRITE = 0x10
_IN_OPEN = 0x20
_IN_Q_OVERFLOW = 0x4000
_EVENT_HEADER = struct.Struct("iIII")


class _OpenWatch:
    """Counts how many open files other programs hold on each port, from inotify events."""

    def __init__(self, paths: list[str], on_last_close: Callable[[int], None]) -> None:
        libc = ctypes.CDLL(None, use_errno=True)
        fd = libc.inotify_init1(os.O_NONBLOCK | os.O_CLOEXEC)
        if fd < 0:
            raise OSError(ctypes.get_errno(), "inotify_init1 failed")
        self._fd: int = fd
        self._ports: dict[int, int] = {}
        self.counts = [0] * len(paths)
        self._on_last_close = on_last_close
        try:
            for index, path in enumerate(paths):
                mask = _IN_OPEN | _IN_CLOSE_WRITE | _IN_CLOSE_NOWRITE
                watch = libc.inotify_add_watch(fd, os.fsencode(path), mask)
                if watch < 0:
                    raise OSError(ctypes.get_errno(), "inotify_add_watch failed", path)
                self._ports[watch] = index
            # Asking an epoll of its own whether events are queued costs a fraction of a
            # read that fails: the relay asks before every delivery.
            self._probe = select.epoll()
            self._probe.register(fd, select.EPOLLIN)
        except BaseException:
            os.close(fd)
            raise

    def poll(self) -> None:
        """Take in every event already queued, calling back when the last program left a port."""
        if self._fd < 0 or not self._probe.poll(0):
            return
        while True:
            try:
                data = os.read(self._fd, 65536)
            except (BlockingIOError, OSError):
                return
            offset = 0
            while offset + _EVENT_HEADER.size <= len(data):
                watch, mask, _cookie, length = _EVENT_HEADER.unpack_from(data, offset)
                offset += _EVENT_HEADER.size + length
                if mask & _IN_Q_OVERFLOW:
                    # Lost count: assume every port is in use rather than drop real traffic.
                    self.counts = [max(count, 1) for count in self.counts]
                    continue
                index = self._ports.get(watch)
                if index is None:
                    continue
                if mask & _IN_OPEN:
                    self.counts[index] += 1
                elif mask & (_IN_CLOSE_WRITE | _IN_CLOSE_NOWRITE) and self.counts[index] > 0:
                    # The port is reset before it is seen as closed, so that whoever waits
                    # for the close finds it ready to be opened again.
                    if self.counts[index] == 1:
                        self._on_last_close(index)
                    self.counts[index] -= 1

    async def wait(self) -> None:
        """Wait until events are queued."""
        await anyio.wait_readable(self._fd)

    def close(self) -> None:
        """Stop watching."""
        if self._fd >= 0:
            anyio.notify_closing(self._fd)
            self._probe.close()
            os.close(self._fd)
            self._fd = -1


def _set_idle_settings(fd: int, baudrate: int | None) -> None:
    """Raw mode, plus two echo flags that do nothing while ECHO is off.

    Programs that set raw mode clear those flags, so their first configuration always
    changes something, and glibc's `tcsetattr` then accepts it even with parity (see
    the module docs).
    """
    make_raw(fd, baudrate)
    attributes = termios.tcgetattr(fd)
    attributes[3] |= termios.ECHOKE | termios.ECHOCTL
    termios.tcsetattr(fd, termios.TCSANOW, attributes)


class _Port:
    """One pty: the master the relay uses, the slave it keeps open, and their names."""

    __slots__ = ("fd", "link", "master", "path", "slave", "stopped", "unsent", "writing")

    def __init__(self, master: FileDescriptorStream, slave: int, path: str) -> None:
        self.master = master
        self.fd = master.fd
        self.slave = slave
        self.path = path
        self.link: str | None = None
        # The direct relay's state: bytes taken from the bus but not yet written to the
        # master, whether a writer callback waits for room, and whether the port is done.
        self.unsent: memoryview | None = None
        self.writing = False
        self.stopped = False


class PtyBus:
    """A multi-drop serial bus whose ports are pseudo-terminal device paths.

    The options are [`VirtualBus`][aiortu.testing.VirtualBus]'s; `link_dir`, when given, gets
    symbolic links `port0`, `port1`, ... to the devices, so that scripts can use stable
    names (stale links from an earlier run are replaced; the links are removed on close).
    A bus holds a lock on its `link_dir` (the file `.virtual-bus.lock` there) while it runs:
    a second bus given the same directory raises [`PortBusy`][aiortu.errors.PortBusy] instead of
    taking the first one's links away.

    Use it as `async with PtyBus(ports=2) as bus:` (the relay runs in a task group of the
    calling task) or, from synchronous code and test fixtures, as
    `with PtyBus(ports=2).running_in_thread() as bus:` (the relay runs in an event loop of
    its own, in a background thread).

    Raises [`InvalidValue`][aiortu.errors.InvalidValue] (caused by the caller) for bad options,
    and `OSError` (caused by the environment) when no pty can be opened.
    """

    def __init__(
        self,
        ports: int = 2,
        *,
        settings: LineSettings | None = None,
        chunk_size: int | None = None,
        latency: float = 0.0,
        faults: FaultPlan | None = None,
        link_dir: str | os.PathLike[str] | None = None,
        receive_buffer_size: int = 65536,
        trace_size: int = 1000,
    ) -> None:
        self.bus = VirtualBus(
            ports,
            settings=settings,
            chunk_size=chunk_size,
            latency=latency,
            faults=faults,
            receive_buffer_size=receive_buffer_size,
            trace_size=trace_size,
        )
        """The in-memory bus that carries the traffic; its endpoint *i* stands for port *i*."""
        self.link_dir = os.fspath(link_dir) if link_dir is not None else None
        self._ports: list[_Port] = []
        self._task_group: anyio.abc.TaskGroup | None = None
        self._watch: _OpenWatch | None = None
        self._entered = False
        self._loop: asyncio.AbstractEventLoop | None = None
        self._link_lock: int | None = None

    @property
    def paths(self) -> tuple[str, ...]:
        """The slave device paths (`/dev/pts/N`), one per port; empty until started."""
        return tuple(port.path for port in self._ports)

    @property
    def links(self) -> tuple[str, ...]:
        """The symbolic links made in *link_dir* (empty without one)."""
        return tuple(port.link for port in self._ports if port.link is not None)

    @property
    def devices(self) -> tuple[str, ...]:
        """The names programs should open: the links if there are any, else the paths."""
        return self.links or self.paths

    @property
    def collisions(self) -> int:
        """Transmissions that started while another port's bytes were on the wire."""
        return self.bus.collisions

    @property
    def trace(self) -> tuple[TraceEntry, ...]:
        """A snapshot of the bus trace (safe to take from another thread)."""
        return tuple(self.bus.trace)

    def is_open(self, port: int) -> bool | None:
        """Whether some program has `port` open; None where the relay cannot tell."""
        if self._watch is None:
            return None
        return self._watch.counts[port] > 0

    def discard_input(self, port: int) -> None:
        """Drop every byte that waits to be read on `port`, in the relay and in the kernel."""
        endpoint = self.bus[port]
        endpoint._buffer.clear()
        self._ports[port].unsent = None
        termios.tcflush(self._ports[port].slave, termios.TCIFLUSH)

    async def __aenter__(self) -> PtyBus:
        if self._entered:
            raise RuntimeError("a PtyBus can only be started once")
        self._entered = True
        try:
            self._open_ports()
            self._task_group = anyio.create_task_group()
            await self._task_group.__aenter__()
        except BaseException:
            await self._close_ports()
            raise
        if self._watch is not None:
            self._task_group.start_soon(self._watch_ports, name="pty bus port watch")
        loop = self._direct_loop()
        if loop is not None:
            self._loop = loop
            for index, port in enumerate(self._ports):
                loop.add_reader(port.fd, self._forward, index)
            return self
        for index in range(len(self._ports)):
            self._task_group.start_soon(self._pump_in, index, name=f"pty bus port {index} in")
            self._task_group.start_soon(self._pump_out, index, name=f"pty bus port {index} out")
        return self

    async def __aexit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> bool | None:
        task_group, self._task_group = self._task_group, None
        try:
            if task_group is not None:
                task_group.cancel_scope.cancel()
                return await task_group.__aexit__(exc_type, exc, tb)
            return None
        finally:
            with anyio.CancelScope(shield=True):
                await self._close_ports()

    @contextlib.contextmanager
    def running_in_thread(self) -> Iterator[PtyBus]:
        """Run the relay in a background thread with its own event loop, for the `with` block.

        For synchronous code (a pyserial or pymodbus sync client) and for test fixtures
        whose setup and teardown run in different tasks.
        """
        with (
            anyio.from_thread.start_blocking_portal() as portal,
            portal.wrap_async_context_manager(self) as bus,
        ):
            yield bus

    def _lock_link_dir(self) -> None:
        """Hold `link_dir`'s lock, or raise PortBusy naming the bus that holds it."""
        assert self.link_dir is not None
        os.makedirs(self.link_dir, exist_ok=True)
        path = os.path.join(self.link_dir, _LINK_LOCK)
        while True:
            lock = os.open(path, os.O_RDWR | os.O_CREAT, 0o644)
            try:
                fcntl.flock(lock, fcntl.LOCK_EX | fcntl.LOCK_NB)
            except BlockingIOError:
                holder = os.read(lock, 32).decode(errors="replace").strip()
                os.close(lock)
                by = f" (process {holder})" if holder.isdigit() else ""
                raise PortBusy(
                    self.link_dir,
                    f"another virtual bus{by} keeps its links here: stop it, or give another "
                    "directory",
                ) from None
            # A bus that was closing may have removed the file we locked: lock the new one.
            with contextlib.suppress(FileNotFoundError):
                if os.stat(path).st_ino == os.fstat(lock).st_ino:
                    break
            os.close(lock)
        os.ftruncate(lock, 0)
        os.write(lock, f"{os.getpid()}\n".encode())
        self._link_lock = lock

    def _open_ports(self) -> None:
        if self.link_dir is not None:
            self._lock_link_dir()
        baudrate = self.bus.settings.baudrate if self.bus.settings is not None else None
        for index in range(len(self.bus)):
            master, slave = os.openpty()
            try:
                _set_idle_settings(slave, baudrate)
                path = os.ttyname(slave)
                stream = FileDescriptorStream(master)
            except BaseException:
                os.close(master)
                os.close(slave)
                raise
            port = _Port(stream, slave, path)
            self._ports.append(port)
            if self.link_dir is not None:
                port.link = self._make_link(index, path)
        try:
            self._watch = _OpenWatch(list(self.paths), self._reset_port)
        except (OSError, AttributeError):
            self._watch = None

    def _make_link(self, index: int, path: str) -> str:
        assert self.link_dir is not None
        os.makedirs(self.link_dir, exist_ok=True)
        link = os.path.join(self.link_dir, f"port{index}")
        temporary = f"{link}.{os.getpid()}.tmp"
        with contextlib.suppress(FileNotFoundError):
            os.unlink(temporary)
        os.symlink(path, temporary)
        os.replace(temporary, link)
        return link

    async def _close_ports(self) -> None:
        self._stop_direct()
        ports, self._ports = self._ports, []
        self.bus.close()
        if self._watch is not None:
            self._watch.close()
        for port in ports:
            await port.master.aclose()
            os.close(port.slave)
            if port.link is not None:
                with contextlib.suppress(OSError):
                    if os.readlink(port.link) == port.path:
                        os.unlink(port.link)
        lock, self._link_lock = self._link_lock, None
        if lock is not None and self.link_dir is not None:
            # Removed while still held: a bus waiting on this file then locks a new one.
            with contextlib.suppress(OSError):
                os.unlink(os.path.join(self.link_dir, _LINK_LOCK))
            os.close(lock)

    # --- the direct relay (unpaced, no adapter model, no faults, asyncio) -----------------

    def _direct_loop(self) -> asyncio.AbstractEventLoop | None:
        """The running asyncio loop if the bytes can go straight through, else None."""
        bus = self.bus
        if (
            bus.settings is not None
            or bus.injector is not None
            or bus.chunk_size is not None
            or bus.latency > 0
        ):
            return None
        try:
            return asyncio.get_running_loop()
        except RuntimeError:  # another event loop (trio): the tasks do the relaying
            return None

    def _stop_direct(self) -> None:
        """Take the direct relay's callbacks off the loop (before the masters are closed)."""
        loop, self._loop = self._loop, None
        if loop is None:
            return
        for port in self._ports:
            port.stopped = True
            loop.remove_reader(port.fd)
            if port.writing:
                port.writing = False
                loop.remove_writer(port.fd)

    def _forward(self, index: int) -> None:
        """Reader callback: carry what the program on port `index` wrote to the other ports."""
        port = self._ports[index]
        try:
            data = os.read(port.fd, 65536)
        except BlockingIOError:
            return
        except OSError:
            data = b""
        loop = self._loop
        assert loop is not None
        endpoint = self.bus.endpoints[index]
        if not data or endpoint.closed:
            # The end of the stream, or the bus is closed: this port sends nothing more.
            loop.remove_reader(port.fd)
            return
        self.bus._transmit_now(endpoint, data, loop.time())
        # Read the open events before writing: a program that opened its port before these
        # bytes were sent must get them.
        self._update_open_ports()
        for other_index, other in enumerate(self._ports):
            if other_index != index and not other.writing and not other.stopped:
                self._drain(other, other_index)

    def _drain(self, port: _Port, index: int) -> None:
        """Write what the bus delivered to `port` (number `index`) to its master, as it fits."""
        endpoint = self.bus.endpoints[index]
        watch = self._watch
        fd = port.fd
        while True:
            view = port.unsent
            if view is None:
                data = endpoint._take()
                if not data:
                    break
                if watch is not None and watch.counts[index] == 0:
                    continue  # nobody has the port open: the bytes are lost, as on a cable
                view = memoryview(data)
            try:
                written = os.write(fd, view)
            except BlockingIOError:
                written = 0
            except OSError:
                # The master is broken: this port gets nothing more (its bus buffer fills
                # up and drops its oldest bytes, as for a program that does not read).
                port.stopped = True
                port.unsent = None
                break
            if written < len(view):
                port.unsent = view[written:]
                if not port.writing:
                    assert self._loop is not None
                    port.writing = True
                    self._loop.add_writer(fd, self._resume, index)
                return
            port.unsent = None
        if port.writing:
            assert self._loop is not None
            port.writing = False
            self._loop.remove_writer(fd)

    def _resume(self, index: int) -> None:
        """Writer callback: the master of port `index` has room again."""
        self._update_open_ports()
        self._drain(self._ports[index], index)

    # --- the relay tasks (pacing, adapter model, faults, or an event loop other than asyncio)

    async def _pump_in(self, index: int) -> None:
        """Carry what the program on port `index` writes onto the wire."""
        master = self._ports[index].master
        endpoint = self.bus[index]
        while True:
            try:
                data = await master.receive()
            except (anyio.EndOfStream, anyio.BrokenResourceError, anyio.ClosedResourceError):
                return
            try:
                await endpoint.send(data)
            except anyio.ClosedResourceError:
                return

    def _reset_port(self, index: int) -> None:
        """Flush a port the last program has left, and put back the idle settings."""
        if index >= len(self._ports):
            return
        baudrate = self.bus.settings.baudrate if self.bus.settings is not None else None
        slave = self._ports[index].slave
        with contextlib.suppress(OSError, termios.error):
            termios.tcflush(slave, termios.TCIFLUSH)
            _set_idle_settings(slave, baudrate)

    def _update_open_ports(self) -> None:
        if self._watch is not None:
            self._watch.poll()

    async def _watch_ports(self) -> None:
        """Follow programs opening and closing the ports."""
        assert self._watch is not None
        while True:
            try:
                await self._watch.wait()
            except (anyio.ClosedResourceError, OSError):
                return
            self._update_open_ports()

    async def _pump_out(self, index: int) -> None:
        """Carry what the wire delivers to port `index` to the program on it."""
        master = self._ports[index].master
        endpoint = self.bus[index]
        while True:
            try:
                data = await endpoint.receive()
                # The events are read here, not only in the watch task: a program that opened
                # the port before these bytes were sent must get them.
                self._update_open_ports()
                if self._watch is not None and self._watch.counts[index] == 0:
                    continue
                await master.send(data)
            except (anyio.EndOfStream, anyio.BrokenResourceError, anyio.ClosedResourceError):
                return

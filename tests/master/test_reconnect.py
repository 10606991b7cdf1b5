"""Reconnecting: the port disappears under a running master (a USB adapter unplugged) and
comes back under the same name.

The scenarios run on a virtual clock (`tests/virtual_clock.py`), on a port of virtual lines
that the test plugs in and out: each time is exact, the back-off's included, and none is
waited in real time. One test runs `open_master` on a pty whose name (a symlink) is re-pointed,
in real time: the opener that reopens a device path by its name is the part it checks, and
a pty's bytes come in real time."""

from __future__ import annotations

import contextlib
import errno
import logging
import os
from collections.abc import AsyncIterator, Iterator
from pathlib import Path

import anyio
import anyio.abc
import pytest

import aiortu
from aiortu.core.pdu import Request
from aiortu.core.serial import LineSettings
from aiortu.testing import VirtualEndpoint, make_raw, virtual_pair
from aiortu.transport import FileDescriptorStream
from tests.virtual_clock import on_virtual_clock

from .fakes import FakeSlave, answer, register_value

pytestmark = pytest.mark.timeout(30)

LINE = {"baudrate": 19200, "parity": "N", "stopbits": 2}
DELAY = (0.05, 0.2)
"""The reconnect back-off of these tests: 50 ms, doubling up to 200 ms."""


async def hold(fake: FakeSlave, unit: int, request: Request) -> None:
    """A step that answers too late for any request of these tests."""
    await anyio.sleep(10)


class Port:
    """A serial port that the test plugs in and out: each plug is a new virtual line with a
    fake slave on its far end; `open` is the master's opener, and notes when it was called."""

    def __init__(self, tasks: anyio.abc.TaskGroup) -> None:
        self.tasks = tasks
        self.opened: list[float] = []
        """When the port was opened or tried (first by the test, then by the master)."""
        self.fake: FakeSlave | None = None
        self._near: VirtualEndpoint | None = None
        self._scope = anyio.CancelScope()

    async def open(self) -> anyio.abc.ByteStream:
        self.opened.append(anyio.current_time())
        near, self._near = self._near, None  # one open per plug
        if near is None:
            raise FileNotFoundError(errno.ENOENT, "No such file or directory", "/dev/ttyUSB9")
        return near

    def plug(self, *, slow: bool = False) -> None:
        near, far = virtual_pair()
        self._near = near
        fake = self.fake = FakeSlave(far, default=hold if slow else answer)
        scope = self._scope = anyio.CancelScope()

        async def run() -> None:
            with scope:
                await fake.run()

        self.tasks.start_soon(run)

    def unplug(self) -> None:
        assert self.fake is not None
        self._scope.cancel()
        self._near = None
        self.fake.stream.close()  # the master's end sees its line end now


@contextlib.asynccontextmanager
async def plugged_master(**options: object) -> AsyncIterator[tuple[aiortu.Master, Port]]:
    """A master on a plugged-in `Port`, with the port's opener; the port's tasks end with it."""
    async with anyio.create_task_group() as tasks:
        port = Port(tasks)
        port.plug()
        stream = await port.open()
        master = aiortu.Master(stream, LineSettings(**LINE), opener=port.open, **options)  # type: ignore[arg-type]
        async with master:
            await anyio.sleep(0.05)  # both receivers past their first silence
            yield master, port
        tasks.cancel_scope.cancel()


@contextlib.contextmanager
def warnings_of_aiortu() -> Iterator[list[str]]:
    """The messages of the warnings aiortu logs meanwhile."""
    messages: list[str] = []

    class Keep(logging.Handler):
        def emit(self, record: logging.LogRecord) -> None:
            messages.append(record.getMessage())

    logger = logging.getLogger("aiortu")
    handler, level = Keep(logging.WARNING), logger.level
    logger.addHandler(handler)
    logger.setLevel(logging.WARNING)
    try:
        yield messages
    finally:
        logger.removeHandler(handler)
        logger.setLevel(level)


def back_off_times(first: float, count: int) -> list[float]:
    """When the reopen attempts after a failure at `first` go out, by the policy `DELAY`."""
    times, delay, now = [], DELAY[0], first
    for _ in range(count):
        now += delay
        times.append(now)
        delay = min(2 * delay, DELAY[1])
    return times


@on_virtual_clock
async def test_requests_fail_while_the_port_is_gone_then_recover() -> None:
    expected = [register_value(1, 5), register_value(1, 6)]
    options = {"timeout": 0.3, "retries": 0, "reconnect_delay": DELAY}
    async with plugged_master(**options) as (master, port):
        assert await master.read_holding_registers(1, 5, 2) == expected
        # Pulled between requests: the master sees it at once, and reopens by the back-off.
        gone = anyio.current_time()
        port.unplug()
        await anyio.sleep(0.5)
        assert not master.connected
        assert port.opened[1:] == pytest.approx(back_off_times(gone, 3))  # 50, 150, 350 ms
        # The slow device: reconnected at the next attempt, then pulled mid-request.
        port.plug(slow=True)
        await master.connection.wait_connected()
        assert anyio.current_time() == pytest.approx(back_off_times(gone, 4)[-1])  # 550 ms
        failures: list[float] = []

        async def in_flight() -> None:
            with pytest.raises(aiortu.ConnectionLost):
                await master.read_holding_registers(1, 5, 2, timeout=5.0)
            failures.append(anyio.current_time())

        port.tasks.start_soon(in_flight)
        await anyio.sleep(0.1)
        assert port.fake is not None
        assert len(port.fake.seen) == 1  # on the wire, unanswered
        pulled = anyio.current_time()
        port.unplug()
        await anyio.sleep(0.01)
        # A request in flight when the port disappears fails at once, not at its timeout.
        assert failures == [pulled]
        assert not master.connected
        # Requests made while it is gone wait their own timeout for it, then fail.
        start = anyio.current_time()
        with pytest.raises(aiortu.ConnectionLost, match=r"did not come back within 0\.3 s"):
            await master.read_holding_registers(1, 5, 2)
        assert anyio.current_time() - start == pytest.approx(0.3)
        # Plugged back in: a waiting request goes through at the next attempt.
        attempts = len(port.opened)
        plugged = anyio.current_time()
        port.plug()
        assert await master.read_holding_registers(1, 5, 2, timeout=3.0) == expected
        assert len(port.opened) == attempts + 1
        assert port.opened[-1] - plugged <= DELAY[1]
        assert master.connected
        connection = master.connection
        assert (connection.reconnects, connection.disconnects) == (2, 2)
        assert connection.failed_attempts == len(port.opened) - 1 - 2
        assert await master.read_holding_registers(1, 7, 1) == [register_value(1, 7)]


@on_virtual_clock
async def test_a_request_in_its_late_reply_guard_fails_at_once_when_the_port_goes() -> None:
    # Its first attempt timed out; its retry waits for the guard of silence. Pulled then, it
    # fails at once with the error of a request on the wire, not once the guard is over.
    options = {"timeout": 0.1, "retries": 1, "late_reply_guard": 5.0, "reconnect_delay": DELAY}
    async with plugged_master(**options) as (master, port):
        failures: list[tuple[float, str]] = []

        async def request(patience: float) -> None:
            with pytest.raises(aiortu.ConnectionLost) as lost:
                await master.read_holding_registers(1, 5, 2, timeout=patience)
            failures.append((anyio.current_time(), str(lost.value)))

        async def pulled_during(patience: float) -> float:
            port.unplug()
            await anyio.sleep(0.01)  # the master sees it gone
            port.plug(slow=True)
            await master.connection.wait_connected()
            await anyio.sleep(0.05)  # the fake's receiver past its first silence
            port.tasks.start_soon(request, patience)
            await anyio.sleep(0.3)
            assert port.fake is not None
            assert len(port.fake.seen) == 1  # the first attempt only
            pulled = anyio.current_time()
            port.unplug()
            await anyio.sleep(0.01)
            return pulled

        in_guard = await pulled_during(0.1)  # timed out at 0.1 s: in the guard until 5.1 s
        on_the_wire = await pulled_during(5.0)  # waiting for its reply
        assert [when for when, _ in failures] == [in_guard, on_the_wire]
        assert failures[0][1] == failures[1][1]
        assert master.unit_stats(1).retries == 1


@on_virtual_clock
async def test_fail_fast_while_reconnecting() -> None:
    options = {"timeout": 2.0, "reconnect_delay": DELAY, "reconnect_fail_fast": True}
    with warnings_of_aiortu() as warnings:
        async with plugged_master(**options) as (master, port):
            assert await master.read_coils(1, 0, 3)
            port.unplug()
            await anyio.sleep(0.1)
            start = anyio.current_time()
            with pytest.raises(aiortu.ConnectionLost, match="fail fast"):
                await master.read_coils(1, 0, 3)
            assert anyio.current_time() == start  # at once, not at its timeout
            port.plug()
            await master.connection.wait_connected()
            assert len(await master.read_coils(1, 0, 3)) == 3
            port.unplug()
            await anyio.sleep(0.01)
    # A warning each time the port went, worded once: why it failed, then what happens.
    reopening = [message for message in warnings if "reopening" in message]
    assert len(reopening) == 2, reopening
    for message in reopening:
        assert message.startswith("the line failed: ")
        assert message.endswith("; reopening it")
        assert message.count("the line failed") == 1


@on_virtual_clock
async def test_without_reconnect_the_master_stays_failed() -> None:
    async with plugged_master(reconnect=False, reconnect_delay=DELAY) as (master, port):
        await master.read_coils(1, 0, 3)
        port.unplug()
        port.plug()
        await anyio.sleep(1.0)
        start = anyio.current_time()
        with pytest.raises(aiortu.ConnectionLost):
            await master.read_coils(1, 0, 3)
        assert anyio.current_time() == start
        assert len(port.opened) == 1  # the test's own open: the master never tried
        assert master.connection.reconnects == 0


class Device:
    """A fake slave behind a pty whose device *link* points to; plugged in and out."""

    def __init__(self, link: Path, tasks: anyio.abc.TaskGroup) -> None:
        self.link = link
        self.tasks = tasks
        self.fake: FakeSlave | None = None
        self._scope: anyio.CancelScope | None = None
        self._slave_fd: int | None = None

    async def plug(self) -> None:
        master_fd, slave_fd = os.openpty()
        make_raw(slave_fd)
        temporary = self.link.with_suffix(".tmp")
        temporary.unlink(missing_ok=True)
        temporary.symlink_to(os.ttyname(slave_fd))
        os.replace(temporary, self.link)
        self._slave_fd = slave_fd
        self.fake = FakeSlave(FileDescriptorStream(master_fd))
        self._scope = anyio.CancelScope()
        scope, fake = self._scope, self.fake

        async def run() -> None:
            with scope:
                await fake.run()

        self.tasks.start_soon(run)
        await anyio.sleep(0.05)

    async def unplug(self) -> None:
        assert self._scope is not None
        assert self.fake is not None
        self._scope.cancel()
        await anyio.sleep(0.01)
        await self.fake.stream.aclose()
        if self._slave_fd is not None:
            with contextlib.suppress(OSError):
                os.close(self._slave_fd)
        self.link.unlink(missing_ok=True)


async def test_open_master_reopens_a_port_by_its_name(tmp_path: Path) -> None:
    # Real time: a pty's bytes are the operating system's.
    async with anyio.create_task_group() as tasks:
        device = Device(tmp_path / "ttyRTU", tasks)
        await device.plug()
        options = {"timeout": 0.3, "retries": 0, "reconnect_delay": DELAY}
        async with aiortu.open_master(str(device.link), **LINE, **options) as master:
            assert await master.read_holding_registers(1, 5, 1) == [register_value(1, 5)]
            await device.unplug()
            with anyio.fail_after(3):
                while master.connected:  # noqa: ASYNC110  # the read of the pty ends soon
                    await anyio.sleep(0.01)
            with pytest.raises(aiortu.ConnectionLost):
                await master.read_holding_registers(1, 5, 1)
            await device.plug()  # a new pty, under the same name
            with anyio.fail_after(3):
                await master.connection.wait_connected()
            assert await master.read_holding_registers(1, 7, 1) == [register_value(1, 7)]
            assert (master.connection.reconnects, master.connection.disconnects) == (1, 1)
            await device.unplug()
        tasks.cancel_scope.cancel()

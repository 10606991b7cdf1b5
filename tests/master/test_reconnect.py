"""Reconnecting: the port disappears under a running master (a pty closed, like a USB
adapter unplugged) and comes back under the same name (a symlink we re-point)."""

from __future__ import annotations

import contextlib
import logging
import os
from pathlib import Path

import anyio
import anyio.abc
import pytest

import aiortu
from aiortu.core.pdu import Request
from aiortu.testing import make_raw
from aiortu.transport import FileDescriptorStream

from .fakes import FakeSlave, answer, register_value

pytestmark = pytest.mark.timeout(30)

LINE = {"baudrate": 19200, "parity": "N", "stopbits": 2}


async def hold(fake: FakeSlave, unit: int, request: Request) -> None:
    """A step that answers too late for any request of these tests."""
    await anyio.sleep(10)


class Device:
    """A fake slave behind a pty whose device *link* points to; plugged in and out."""

    def __init__(self, link: Path, tasks: anyio.abc.TaskGroup) -> None:
        self.link = link
        self.tasks = tasks
        self.fake: FakeSlave | None = None
        self._scope: anyio.CancelScope | None = None
        self._slave_fd: int | None = None

    async def plug(self, *, slow: bool = False) -> None:
        master_fd, slave_fd = os.openpty()
        make_raw(slave_fd)
        temporary = self.link.with_suffix(".tmp")
        temporary.unlink(missing_ok=True)
        temporary.symlink_to(os.ttyname(slave_fd))
        os.replace(temporary, self.link)
        self._slave_fd = slave_fd
        self.fake = FakeSlave(FileDescriptorStream(master_fd), default=hold if slow else answer)
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


async def test_requests_fail_while_the_port_is_gone_then_recover(tmp_path: Path) -> None:
    expected = [register_value(1, 5), register_value(1, 6)]
    async with anyio.create_task_group() as tasks:
        device = Device(tmp_path / "ttyRTU", tasks)
        await device.plug()
        options = {"timeout": 0.3, "retries": 0, "reconnect_delay": (0.05, 0.2)}
        async with aiortu.open_master(str(device.link), **LINE, **options) as master:
            assert await master.read_holding_registers(1, 5, 2) == expected
            await device.unplug()
            await device.plug(slow=True)
            # A request in flight when the port disappears fails at once, not at its
            # timeout.
            failures: list[float] = []

            async def in_flight() -> None:
                with pytest.raises(aiortu.ConnectionLost):
                    await master.read_holding_registers(1, 5, 2, timeout=5.0)
                failures.append(anyio.current_time())

            # The slow device first: reconnect to it, then pull it mid-request.
            with anyio.fail_after(3):
                await master.connection.wait_connected()
            tasks.start_soon(in_flight)
            await anyio.sleep(0.1)
            pulled = anyio.current_time()
            await device.unplug()
            await anyio.sleep(0.1)
            assert failures
            assert failures[0] - pulled < 0.1
            assert not master.connected
            # Requests made while it is gone wait within their own timeout, then fail.
            start = anyio.current_time()
            with pytest.raises(aiortu.ConnectionLost):
                await master.read_holding_registers(1, 5, 2)
            assert 0.25 < anyio.current_time() - start < 1.0
            # Plugged back in under the same name: a waiting request goes through.
            async with anyio.create_task_group() as plugging:
                plugging.start_soon(device.plug)
                with anyio.fail_after(4):
                    assert await master.read_holding_registers(1, 5, 2, timeout=3.0) == expected
            assert master.connected
            assert master.connection.reconnects == 2
            assert master.connection.disconnects == 2
            assert await master.read_holding_registers(1, 7, 1) == [register_value(1, 7)]
            await device.unplug()
        tasks.cancel_scope.cancel()


async def test_fail_fast_while_reconnecting(
    tmp_path: Path, caplog: pytest.LogCaptureFixture
) -> None:
    caplog.set_level(logging.WARNING, logger="aiortu")
    async with anyio.create_task_group() as tasks:
        device = Device(tmp_path / "ttyRTU", tasks)
        await device.plug()
        options = {"timeout": 2.0, "reconnect_delay": (0.05, 0.1), "reconnect_fail_fast": True}
        async with aiortu.open_master(str(device.link), **LINE, **options) as master:
            assert await master.read_coils(1, 0, 3)
            await device.unplug()
            await anyio.sleep(0.1)
            with anyio.fail_after(0.5), pytest.raises(aiortu.ConnectionLost):
                await master.read_coils(1, 0, 3)
            await device.plug()
            with anyio.fail_after(3):
                await master.connection.wait_connected()
            assert len(await master.read_coils(1, 0, 3)) == 3
            await device.unplug()
        tasks.cancel_scope.cancel()
    # A warning each time the port went (the last unplug may come too late to be seen),
    # worded once: why it failed, then what happens.
    reopening = [r.getMessage() for r in caplog.records if "reopening" in r.getMessage()]
    assert 1 <= len(reopening) <= 2, reopening
    for message in reopening:
        assert message.startswith("the line failed: ")
        assert message.endswith("; reopening it")
        assert message.count("the line failed") == 1


async def test_without_reconnect_the_master_stays_failed(tmp_path: Path) -> None:
    async with anyio.create_task_group() as tasks:
        device = Device(tmp_path / "ttyRTU", tasks)
        await device.plug()
        async with aiortu.open_master(str(device.link), **LINE, reconnect=False) as master:
            await master.read_coils(1, 0, 3)
            await device.unplug()
            await device.plug()
            await anyio.sleep(0.3)
            with anyio.fail_after(0.5), pytest.raises(aiortu.ConnectionLost):
                await master.read_coils(1, 0, 3)
            assert master.connection.reconnects == 0
            await device.unplug()
        tasks.cancel_scope.cancel()

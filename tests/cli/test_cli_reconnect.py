"""``aiortu poll`` and ``aiortu serve`` when their port disappears (a pty closed, like a USB
adapter unplugged) and comes back under the same name (a symlink re-pointed): by default
they reopen it and go on; with ``--no-reconnect`` they exit 1 with one line."""

from __future__ import annotations

import contextlib
import os
import re
from collections.abc import AsyncIterator
from pathlib import Path

import anyio
import anyio.abc
import pytest

import aiortu
from aiortu.core.serial import LineSettings
from aiortu.testing import make_raw
from aiortu.transport import FileDescriptorStream
from tests.cli.cli_helpers import aiortu_command
from tests.master.fakes import register_value
from tests.master.test_reconnect import Device

pytestmark = pytest.mark.timeout(60)

DEVICES = str(Path(__file__).parents[2] / "examples" / "devices.toml")


class Output:
    """What a subprocess wrote on one of its pipes, read as it comes."""

    def __init__(self, stream: anyio.abc.ByteReceiveStream) -> None:
        self.stream = stream
        self.text = ""

    async def wait_for(self, text: str, *, after: int = 0, within: float = 10) -> int:
        """Wait until *text* appears at or after offset *after*; return where it ends."""
        with anyio.fail_after(within):
            while (found := self.text.find(text, after)) < 0:
                try:
                    self.text += (await self.stream.receive()).decode()
                except anyio.EndOfStream:
                    raise AssertionError(f"{text!r} never came:\n{self.text}") from None
        return found + len(text)


@contextlib.asynccontextmanager
async def aiortu_process(*args: str) -> AsyncIterator[anyio.abc.Process]:
    command = aiortu_command(*args)
    async with await anyio.open_process(command) as process:
        try:
            yield process
        finally:
            if process.returncode is None:
                process.terminate()
                with anyio.fail_after(10):
                    await process.wait()


async def test_poll_says_the_line_is_down_and_goes_on_once_the_port_is_back(
    tmp_path: Path,
) -> None:
    value = f"40001               1  {register_value(1, 0)}"
    async with anyio.create_task_group() as tasks:
        device = Device(tmp_path / "ttyRTU", tasks)
        await device.plug()
        async with aiortu_process(
            "poll", str(device.link), "--unit", "1", "--ref", "40001",
            "--interval", "0.1", "--timeout", "0.3",
        ) as process:  # fmt: skip
            assert process.stdout is not None
            out = Output(process.stdout)
            seen = await out.wait_for(value)
            await device.unplug()
            seen = await out.wait_for("line down, reopening", after=seen)
            assert "-- line lost" in out.text[seen - 300 : seen]
            await device.plug()
            await out.wait_for(value, after=seen)
            process.terminate()
            with anyio.fail_after(10):
                assert await process.wait() == 0
            assert process.stderr is not None
            errors = await _rest(process.stderr)
        await device.unplug()
        tasks.cancel_scope.cancel()
    # The table says the line is down; the library's own log stays out of stderr.
    assert errors == ""


async def _rest(stream: anyio.abc.ByteReceiveStream) -> str:
    """Everything left on a finished process's pipe."""
    text = b""
    with contextlib.suppress(anyio.EndOfStream):
        while True:
            text += await stream.receive()
    return text.decode()


async def test_poll_with_no_reconnect_exits_1_with_one_line(tmp_path: Path) -> None:
    async with anyio.create_task_group() as tasks:
        device = Device(tmp_path / "ttyRTU", tasks)
        await device.plug()
        async with aiortu_process(
            "poll", str(device.link), "--unit", "1", "--ref", "40001", "--interval", "0.1",
            "--no-reconnect",
        ) as process:  # fmt: skip
            assert process.stdout is not None
            assert process.stderr is not None
            await Output(process.stdout).wait_for("unit 1: online")
            await device.unplug()
            with anyio.fail_after(10):
                assert await process.wait() == 1
            errors = (await process.stderr.receive()).decode()
        tasks.cancel_scope.cancel()
    # One line: the command, what failed and why in words; no repr, no traceback.
    assert re.fullmatch(r"aiortu poll: the line failed: the port (closed|is gone \(.+\))\n", errors)
    assert errors.count("the line failed") == 1
    assert "Error(" not in errors


class Wire:
    """The far end of a pty whose device *link* points to: a master reads through it."""

    def __init__(self, link: Path) -> None:
        self.link = link
        self.fd: int | None = None

    def plug(self) -> FileDescriptorStream:
        master_fd, slave_fd = os.openpty()
        make_raw(slave_fd)
        temporary = self.link.with_suffix(".tmp")
        temporary.unlink(missing_ok=True)
        temporary.symlink_to(os.ttyname(slave_fd))
        os.replace(temporary, self.link)
        # The serving process opens the pty itself; this end only keeps it in existence.
        os.close(slave_fd)
        self.fd = master_fd
        return FileDescriptorStream(master_fd, owns_fd=False)

    def unplug(self) -> None:
        if self.fd is not None:
            os.close(self.fd)
            self.fd = None
        self.link.unlink(missing_ok=True)


SETTINGS = LineSettings(19200, parity="N", stopbits=2)


async def read_through(stream: FileDescriptorStream) -> list[int]:
    async with aiortu.Master(stream, SETTINGS, timeout=0.5, retries=3) as master:
        return await master.read_holding_registers(17, 0x6B, 3)


@pytest.mark.parametrize("reconnect", [True, False])
async def test_serve_after_its_port_is_lost(tmp_path: Path, reconnect: bool) -> None:
    wire = Wire(tmp_path / "ttySIM")
    stream = wire.plug()
    flags = [] if reconnect else ["--no-reconnect"]
    async with aiortu_process("serve", str(wire.link), "--config", DEVICES, *flags) as process:
        assert process.stderr is not None
        err = Output(process.stderr)
        seen = await err.wait_for("Ctrl-C to stop\n")
        assert await read_through(stream) == [0xAE41, 0x5652, 0x4340]
        wire.unplug()
        if not reconnect:
            with anyio.fail_after(10):
                assert await process.wait() == 1
            with contextlib.suppress(anyio.EndOfStream):
                err.text += (await process.stderr.receive()).decode()
            failure = err.text[seen:]
            assert failure.startswith("aiortu serve: the line failed: ")
            assert failure.count("the line failed") == 1
            assert failure.count("\n") == 1
            assert "Error(" not in failure
            return
        seen = await err.wait_for("; reopening ", after=seen)
        stream = wire.plug()
        await err.wait_for("Ctrl-C to stop\n", after=seen)
        assert await read_through(stream) == [0xAE41, 0x5652, 0x4340]
        process.terminate()
        with anyio.fail_after(10):
            code = await process.wait()
        with contextlib.suppress(anyio.EndOfStream):
            while True:
                err.text += (await process.stderr.receive()).decode()
        assert code == 0, err.text
    wire.unplug()
    assert "Traceback" not in err.text


async def test_monitor_fails_with_one_line_when_its_port_is_lost(tmp_path: Path) -> None:
    async with anyio.create_task_group() as tasks:
        device = Device(tmp_path / "ttyRTU", tasks)
        await device.plug()
        async with aiortu_process("monitor", str(device.link)) as process:
            assert process.stderr is not None
            err = Output(process.stderr)
            seen = await err.wait_for("Ctrl-C to stop\n")
            await device.unplug()
            with anyio.fail_after(10):
                assert await process.wait() == 1
            with contextlib.suppress(anyio.EndOfStream):
                while True:
                    err.text += (await process.stderr.receive()).decode()
        tasks.cancel_scope.cancel()
    failure = err.text[seen:]
    assert failure.startswith("aiortu monitor: the line failed: the port is gone (")
    assert failure.count("\n") == 1
    assert "Error(" not in failure

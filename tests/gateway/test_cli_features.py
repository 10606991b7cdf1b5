"""`aiortu gateway` end to end on a pty bus: `--line` with a unit range, a `unix:` listener,
`--cache-ms`, `--stats` on stderr and `--metrics` over HTTP."""

from __future__ import annotations

import os
import re
import signal
import stat
import subprocess
from collections.abc import AsyncIterator
from contextlib import asynccontextmanager
from pathlib import Path

import anyio
import anyio.abc
import pytest

from aiortu.testing import PtyBus
from tests.cli.cli_helpers import aiortu_command
from tests.gateway.helpers import TcpClient

pytestmark = pytest.mark.timeout(60)


class Output:
    """What a process wrote on stderr so far, searched as it comes."""

    def __init__(self, stream: anyio.abc.ByteReceiveStream) -> None:
        self.stream = stream
        self.text = b""

    async def wait_for(self, pattern: bytes) -> re.Match[bytes]:
        with anyio.fail_after(20):
            while (found := re.search(pattern, self.text)) is None:
                self.text += await self.stream.receive()
        return found


@asynccontextmanager
async def _command(*args: str) -> AsyncIterator[Output]:
    command = aiortu_command(*args)
    async with await anyio.open_process(command, stderr=subprocess.PIPE) as process:
        assert process.stderr is not None
        try:
            yield Output(process.stderr)
        finally:
            process.send_signal(signal.SIGTERM)
            with anyio.fail_after(20):
                assert await process.wait() == 0


async def _metrics(port: int) -> str:
    async with await anyio.connect_tcp("127.0.0.1", port) as stream:
        await stream.send(b"GET /metrics HTTP/1.0\r\n\r\n")
        data = b""
        with anyio.fail_after(5):
            try:
                while True:
                    data += await stream.receive()
            except anyio.EndOfStream:
                pass
    return data.decode()


async def test_line_unix_cache_stats_and_metrics_from_the_command(tmp_path: Path) -> None:
    socket_path = str(tmp_path / "gw.sock")
    with PtyBus(2).running_in_thread() as bus:
        gateway_args = [
            "gateway", "--line", f"{bus.paths[0]}:1-20", "--listen", f"unix:{socket_path}",
            "--cache-ms", "60000", "--stats", "0.2", "--metrics", "http://127.0.0.1:0/metrics",
        ]  # fmt: skip
        async with (
            _command("serve", bus.paths[1], "--config", "examples/devices.toml") as slave,
            _command(*gateway_args) as gateway,
        ):
            await slave.wait_for(rb"Ctrl-C")
            port = int((await gateway.wait_for(rb"metrics on http://127\.0\.0\.1:(\d+)"))[1])
            async with await anyio.connect_unix(socket_path) as stream:
                tcp = TcpClient(stream)
                first = await tcp.request("03 006B 0003", unit=17)
                assert await tcp.request("03 006B 0003", unit=17) == first
                assert await tcp.request("03 0000 0001", unit=21) == "83 0A"
            await gateway.wait_for(rb"unit 17: requests=2 replies=2")
            assert b"cache_hits=1" in gateway.text
            body = await _metrics(port)
            assert 'aiortu_gateway_client_requests_total{client="unix"} 3' in body


async def test_the_command_logs_the_librarys_warnings_and_sets_the_socket_mode(
    tmp_path: Path,
) -> None:
    socket_path = str(tmp_path / "gw.sock")
    with PtyBus(2).running_in_thread() as bus:
        gateway_args = [
            "gateway", bus.paths[0], "--listen", f"unix:{socket_path}?mode=0600",
            "--max-connections", "1",
        ]  # fmt: skip
        async with _command(*gateway_args) as gateway:
            await gateway.wait_for(rb"Ctrl-C")
            assert stat.S_IMODE(os.stat(socket_path).st_mode) == 0o600
            async with await anyio.connect_unix(socket_path):
                for _ in range(5):  # a burst of refusals: one line
                    async with await anyio.connect_unix(socket_path) as refused:
                        with pytest.raises((anyio.EndOfStream, anyio.BrokenResourceError)):
                            with anyio.fail_after(5):
                                await refused.receive()
            await gateway.wait_for(rb"aiortu gateway: gateway: 1 connections open, the most")
        assert gateway.text.count(b"the most allowed") == 1

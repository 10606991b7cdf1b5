"""The pytest plugin's fixtures in other kinds of suites: strict mode, no pytest-asyncio."""

from __future__ import annotations

import subprocess
import sys
import textwrap

import pytest

pytestmark = pytest.mark.timeout(60)

SUITE = textwrap.dedent(
    """
    import os
    import pytest
    import anyio
    from aiortu.core.serial import LineSettings
    from aiortu.testing import FaultPlan

    {marker}
    async def test_pair(virtual_pair):
        a, b = virtual_pair
        await a.send(b"hi")
        assert await b.receive() == b"hi"

    {marker}
    async def test_bus_factory(virtual_bus):
        bus = virtual_bus(ports=3, settings=LineSettings(115200), faults=FaultPlan(seed=1))
        await bus[0].send(b"x")
        assert await bus[2].receive() == b"x"
        async with virtual_bus(ports=2) as other:
            await other[1].send(b"y")
            assert await other[0].receive() == b"y"

    def test_pty_sync(pty_bus):
        bus = pty_bus(ports=2)
        fds = [os.open(path, os.O_RDWR | os.O_NOCTTY) for path in bus.paths]
        try:
            os.write(fds[0], b"sync")
            data = b""
            while len(data) < 4:
                data += os.read(fds[1], 4)
            assert data == b"sync"
        finally:
            for fd in fds:
                os.close(fd)
    """
)


def start_suite(directory, marker: str, *options: str) -> subprocess.Popen[str]:
    directory.mkdir()
    (directory / "test_suite.py").write_text(SUITE.format(marker=marker))
    return subprocess.Popen(
        [sys.executable, "-m", "pytest", "-q", "-p", "no:cacheprovider", *options, str(directory)],
        stdout=subprocess.PIPE,
        stderr=subprocess.STDOUT,
        text=True,
        cwd=directory,
    )


def test_strict_mode_and_without_pytest_asyncio(tmp_path):
    # Auto mode is what this suite itself runs in. The two runs go in parallel: most of
    # their time is pytest starting up.
    runs = {
        "strict": start_suite(
            tmp_path / "strict", "@pytest.mark.asyncio", "-o", "asyncio_mode=strict", "-rA"
        ),
        "no pytest-asyncio": start_suite(
            tmp_path / "plain", "@pytest.mark.anyio", "-p", "no:asyncio", "-rA"
        ),
    }
    # anyio's plugin runs each anyio test once per installed backend: trio is a required
    # test extra, so the fixtures are checked under trio too.
    anyio_backends = ["asyncio", "trio"]
    expected = {
        "strict": ["test_pair", "test_bus_factory", "test_pty_sync"],
        "no pytest-asyncio": [
            *(f"{test}[{backend}]" for test in ("test_pair", "test_bus_factory")
              for backend in anyio_backends),
            "test_pty_sync",
        ],
    }  # fmt: skip
    for name, process in runs.items():
        output, _ = process.communicate(timeout=50)
        assert process.returncode == 0, f"{name}: {output}"
        for test in expected[name]:
            assert f"PASSED test_suite.py::{test}\n" in output, f"{name}: {output}"
        assert f"{len(expected[name])} passed" in output, f"{name}: {output}"

"""Multi-drop: a master and two ``aiortu serve`` processes on one ``aiortu virtual-bus``,
and a slave fed bus traces where other slaves' replies look like requests."""

from __future__ import annotations

import signal
import subprocess
import sys
import time
from collections.abc import Iterator
from pathlib import Path

import anyio
import pytest

import aiortu
from aiortu.core.pdu import pack_registers, unpack_registers
from aiortu.core.rtu import encode_frame
from aiortu.slave import MemoryStore, Table

from .helpers import slave_line

# A request to unit 3 (read one holding register), hidden in unit 5's registers.
HIDDEN = encode_frame(3, bytes.fromhex("03 00 00 00 01"))
HIDDEN_WORDS = list(unpack_registers(HIDDEN, 0, len(HIDDEN) // 2))

CONFIG_A = f"""
[[slave]]
unit = 5
[[slave.holding_registers]]
start = 0
count = 10
values = [{", ".join(map(str, HIDDEN_WORDS))}]
"""

CONFIG_B = """
[[slave]]
units = [3, 4]
[[slave.holding_registers]]
start = 0
count = 10
"""


def _wait_for(path: Path, text: str, process: subprocess.Popen[bytes]) -> None:
    deadline = time.monotonic() + 15
    while time.monotonic() < deadline:
        if path.exists() and text in path.read_text():
            return
        if process.poll() is not None:
            raise AssertionError(f"exited {process.returncode}: {path.read_text()}")
        time.sleep(0.05)
    raise AssertionError(f"{text!r} never appeared in {path}")


@pytest.fixture
def bus(tmp_path: Path) -> Iterator[tuple[str, Path, Path, list[subprocess.Popen[bytes]]]]:
    command = [sys.executable, "-m", "aiortu"]
    line = ["--parity", "N", "--stopbits", "2"]
    bus = subprocess.Popen([*command, "virtual-bus", "--ports", "3", *line], stdout=subprocess.PIPE)
    processes = [bus]
    try:
        assert bus.stdout is not None
        ports = [bus.stdout.readline().decode().strip() for _ in range(3)]
        logs = []
        for index, config in enumerate((CONFIG_A, CONFIG_B)):
            config_path = tmp_path / f"slave{index}.toml"
            config_path.write_text(config)
            log = tmp_path / f"slave{index}.log"
            logs.append(log)
            with log.open("wb") as stderr:
                processes.append(
                    subprocess.Popen(
                        [
                            *(*command, "serve", ports[index + 1], "--config", str(config_path)),
                            *(*line, "--frame-gap", "0.002", "--trace"),
                        ],
                        stderr=stderr,
                    )
                )
        for log, process in zip(logs, processes[1:], strict=True):
            _wait_for(log, "aiortu serve: unit", process)
        yield ports[0], logs[0], logs[1], processes
    finally:
        for process in reversed(processes):
            if process.poll() is None:
                process.send_signal(signal.SIGTERM)
        for process in reversed(processes):
            try:
                process.wait(10)
            except subprocess.TimeoutExpired:
                process.kill()


def _sent(log: Path) -> int:
    return sum(" -> " in line for line in log.read_text().splitlines())


@pytest.mark.interop
async def test_two_serve_processes_share_one_bus(
    bus: tuple[str, Path, Path, list[subprocess.Popen[bytes]]],
) -> None:
    port, log_a, log_b, processes = bus
    async with aiortu.open_master(
        port, parity="N", stopbits=2, timeout=0.5, retries=0, turnaround_delay=0.1
    ) as master:
        await anyio.sleep(0.05)
        # Unit 5's reply carries a valid-looking request to unit 3: B must not answer it.
        assert await master.read_holding_registers(5, 0, 4) == HIDDEN_WORDS
        assert await master.read_holding_registers(3, 0, 1) == [0]
        assert await master.read_holding_registers(4, 1, 1) == [0]
        with pytest.raises(aiortu.ResponseTimeout):
            await master.read_holding_registers(6, 0, 1)
        await master.broadcast.write_register(8, 0x1234)
        assert await master.read_holding_registers(5, 8, 1) == [0x1234]
        assert await master.read_holding_registers(3, 8, 1) == [0x1234]
    await anyio.sleep(0.1)
    # Each process answered only its own units' unicast requests, never the broadcast.
    assert _sent(log_a) == 2
    assert _sent(log_b) == 3
    assert "unit 3" in log_b.read_text()  # B saw the frames: the trace names them
    for process in processes[1:]:
        process.send_signal(signal.SIGINT)
        assert process.wait(10) == 0


@pytest.mark.parametrize("padding", [0, 1, 2, 5, 20])
async def test_replies_that_look_like_requests_are_never_answered(padding: int) -> None:
    store = MemoryStore(holding_registers={0: 10})
    words = [0x0103] * padding + HIDDEN_WORDS + [0x0300]
    async with slave_line({3: store}) as (master, slave):
        for _ in range(3):
            await master.send(encode_frame(5, bytes.fromhex("03 00 00") + bytes((0, len(words)))))
            data = pack_registers(words)
            await master.send(encode_frame(5, bytes((0x03, len(data))) + data))
            await anyio.sleep(0.01)
        assert await master.receive_frame(0.05) is None
        assert await master.request(3, "03 00 00 00 01") == "03 02 00 00"
    assert slave.counters.other_unit_count == 6
    assert store.get(Table.HOLDING_REGISTERS, 0) == [0]

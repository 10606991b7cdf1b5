"""PtyBus: real device paths that pyserial opens; bytes cross, ports reopen, pacing holds."""

from __future__ import annotations

import os
import time

import anyio
import pytest
import serial

from aiortu.core.serial import LineSettings
from aiortu.testing import PtyBus
from aiortu.transport import FileDescriptorStream

pytestmark = pytest.mark.timeout(20)


def read_exactly(port: serial.Serial, count: int) -> bytes:
    data = b""
    deadline = time.monotonic() + 5
    while len(data) < count and time.monotonic() < deadline:
        data += port.read(count - len(data))
    return data


def wait_for(condition, timeout: float = 2.0) -> None:
    deadline = time.monotonic() + timeout
    while not condition():
        assert time.monotonic() < deadline, "condition not met in time"
        time.sleep(0.005)


def test_pyserial_both_directions(pty_bus):
    bus = pty_bus(ports=2)
    assert all(path.startswith("/dev/") for path in bus.paths)
    with (
        serial.Serial(bus.paths[0], 19200, parity="E", timeout=0.5) as a,
        serial.Serial(bus.paths[1], 19200, parity="E", timeout=0.5) as b,
    ):
        a.write(b"\x11\x03\x00\x6b\x00\x03\x76\x87")
        assert read_exactly(b, 8) == b"\x11\x03\x00\x6b\x00\x03\x76\x87"
        reply = bytes.fromhex("1103 06 AE41 5652 4340 49AD")
        b.write(reply)
        assert read_exactly(a, len(reply)) == reply
        payload = bytes(range(256)) * 8
        b.write(payload)
        assert read_exactly(a, len(payload)) == payload


def test_port_closed_and_reopened_still_works(pty_bus):
    bus = pty_bus(ports=2)
    with serial.Serial(bus.paths[1], 19200, timeout=0.5) as b:
        for round_ in range(3):
            with serial.Serial(bus.paths[0], 19200, timeout=0.5) as a:
                a.write(b"ping %d" % round_)
                assert read_exactly(b, 6) == b"ping %d" % round_
                b.write(b"pong %d" % round_)
                assert read_exactly(a, 6) == b"pong %d" % round_


def test_reopen_with_parity_once_the_bus_saw_the_close(pty_bus):
    bus = pty_bus(ports=2)
    if bus.is_open(0) is None:
        pytest.skip("no inotify: the relay cannot tell when a port is closed")
    for _ in range(2):
        with serial.Serial(bus.paths[0], 19200, parity="E", timeout=0.5):
            wait_for(lambda: bus.is_open(0))
        wait_for(lambda: not bus.is_open(0))


def test_bytes_for_a_port_nobody_has_open_are_dropped(pty_bus):
    bus = pty_bus(ports=2)
    if bus.is_open(1) is None:
        pytest.skip("no inotify: the relay cannot tell who has a port open")
    with serial.Serial(bus.paths[0], 19200, timeout=0.5) as a:
        a.write(b"nobody hears this")
        wait_for(lambda: bus.bus[1].pending == 0 and len(bus.trace) == 1)
        with serial.Serial(bus.paths[1], 19200, timeout=0.2) as b:
            a.write(b"hello")
            assert read_exactly(b, 5) == b"hello"
            assert b.read(100) == b""


def test_three_ports_broadcast_and_links(pty_bus, tmp_path):
    bus = pty_bus(ports=3, link_dir=tmp_path)
    assert bus.devices == tuple(str(tmp_path / f"port{i}") for i in range(3))
    assert [os.path.realpath(link) for link in bus.links] == list(bus.paths)
    ports = [serial.Serial(device, 19200, timeout=0.5) for device in bus.devices]
    try:
        ports[2].write(b"to all")
        assert read_exactly(ports[0], 6) == b"to all"
        assert read_exactly(ports[1], 6) == b"to all"
        assert ports[2].read(10) == b""
    finally:
        for port in ports:
            port.close()


def test_links_are_removed_on_close(tmp_path):
    with PtyBus(2, link_dir=tmp_path).running_in_thread() as bus:
        assert all(os.path.islink(link) for link in bus.links)
    assert list(tmp_path.iterdir()) == []


def test_paced_pty_trace(pty_bus):
    settings = LineSettings(9600)
    bus = pty_bus(ports=2, settings=settings)
    with (
        serial.Serial(bus.paths[0], 9600, timeout=0.5) as a,
        serial.Serial(bus.paths[1], 9600, timeout=0.5) as b,
    ):
        started = time.monotonic()
        a.write(bytes(100))
        assert read_exactly(b, 100) == bytes(100)
        assert time.monotonic() - started >= 100 * settings.char_time * 0.95
    (entry,) = bus.trace
    assert entry.end - entry.start == pytest.approx(100 * settings.char_time)


async def test_async_with_in_the_test_loop():
    async with PtyBus(2) as bus:
        fds = [os.open(path, os.O_RDWR | os.O_NOCTTY) for path in bus.paths]
        a, b = (FileDescriptorStream(fd) for fd in fds)
        async with a, b:
            await a.send(b"over the loop")
            data = b""
            with anyio.fail_after(5):
                while len(data) < 13:
                    data += await b.receive()
            assert data == b"over the loop"


def test_unpaced_relay_holds_what_a_slow_reader_has_no_room_for(pty_bus):
    # The direct relay writes to a master until it is full, then waits for room: nothing
    # is lost or reordered while it fits in the bus's receive buffer.
    bus = pty_bus(ports=2)
    payload = bytes(range(251)) * 160  # more than a pty holds
    with (
        serial.Serial(bus.paths[0], 19200, timeout=0.5) as a,
        serial.Serial(bus.paths[1], 19200, timeout=0.5) as b,
    ):
        a.write(payload)
        a.flush()
        wait_for(lambda: sum(len(entry.data) for entry in bus.trace) == len(payload))
        assert read_exactly(b, len(payload)) == payload
        b.write(b"back")
        assert read_exactly(a, 4) == b"back"
    assert bus.bus[1].overrun_bytes == 0
    assert [entry.start == entry.end for entry in bus.trace] == [True] * len(bus.trace)

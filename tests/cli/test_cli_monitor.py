"""``aiortu monitor`` as users run it: a subprocess listening on one port of a pty bus.

The monitor ends a frame where it sees a silence (20 ms, tolerant timing) or where the frame's
known length and CRC end it. On a paced pty bus the bytes reach it when the bus's relay thread
writes them, at their wire times: a relay (or monitor) held off the CPU for 20 ms in the middle
of a frame is a silence the monitor cannot tell from a real one, and the frame comes out in two
pieces. What each frame means is therefore checked on an unpaced bus, whose relay writes each
frame to the monitor's port in one write, so that a stall only delays it; the paced bus is
checked for what holds whatever the load: every byte comes out once, in order.
"""

from __future__ import annotations

import json
import signal
import subprocess
import threading
import time
from collections.abc import Callable

import pytest
import serial

from aiortu.cli import main
from aiortu.core.serial import LineSettings
from tests.cli.cli_helpers import run_aiortu, start_aiortu

pytestmark = pytest.mark.timeout(30)

# Ptys here do not keep even or odd parity through a reconfiguration: 8N2 on both sides.
SETTINGS = LineSettings(19200, parity="N", stopbits=2)
LINE = ("--baudrate", "19200", "--parity", "N", "--stopbits", "2")

TRAFFIC = [
    "11 03 00 6B 00 03 76 87",  # the spec's worked example: request
    "11 03 06 AE 41 56 52 43 40 49 AD",  # and its reply
    "01 01 00 13 00 13 8C 02",  # read coils on unit 1
    "01 81 02 C1 91",  # answered with exception 02
    "00 06 00 10 00 07 C8 1C",  # broadcast
    "11 03 06 AE 41 56 52 43 40 49 AE",  # a reply with a bad CRC
]

TEXT = [
    "request   ok        unit 17 read holding registers 107..109 (3)",
    "reply     ok        unit 17 reply holding 107..109 = [44609, 22098, 17216]",
    "request   ok        unit 1 read coils 19..37 (19)",
    "exception ok        unit 1 exception ILLEGAL_DATA_ADDRESS to read coils 19..37 (19)",
    "broadcast ok        broadcast write register 16 = 7",
    "unknown   error     CRC error: 11 03 06 AE 41 56 52 43 40 49 AE",
]


def monitor(port: str, *args: str) -> subprocess.Popen[str]:
    """Start ``aiortu monitor`` on *port* and wait until it listens."""
    process = start_aiortu("monitor", port, *LINE, *args)
    assert process.stderr is not None
    ready = process.stderr.readline()
    assert ready.startswith(f"aiortu monitor: listening on {port} at 19200 8N2"), ready
    return process


def play(port: str) -> None:
    """Write the traffic from *port*, each frame in one write, with silence between them."""
    with serial.Serial(port, 19200, parity="N", stopbits=2) as line:
        time.sleep(0.05)  # the monitor's receiver first waits for silence
        for frame in TRAFFIC:
            line.write(bytes.fromhex(frame))
            line.flush()
            time.sleep(0.05)


def stop_when_printed(
    process: subprocess.Popen[str], done: Callable[[list[str]], bool], how: signal.Signals
) -> tuple[list[str], str]:
    """Wait until the lines *process* printed make `done` true (at most 10 s), then stop it
    with *how*: its lines and its standard error, once it exited with 0. A signal sent on a
    fixed delay could come before the monitor read the last frame."""
    lines: list[str] = []
    stdout, stderr = process.stdout, process.stderr
    assert stdout is not None
    assert stderr is not None
    reader = threading.Thread(target=lambda: lines.extend(stdout))
    reader.start()
    deadline = time.monotonic() + 10
    while not done(list(lines)) and time.monotonic() < deadline and reader.is_alive():
        time.sleep(0.01)
    process.send_signal(how)
    try:
        err = stderr.read()
        assert process.wait(timeout=10) == 0, err
    finally:
        reader.join(timeout=10)
    return [line.rstrip("\n") for line in lines], err


def stop_after(
    process: subprocess.Popen[str], count: int, how: signal.Signals
) -> tuple[list[str], str]:
    """`stop_when_printed` once *process* printed `count` lines."""
    return stop_when_printed(process, lambda lines: len(lines) >= count, how)


@pytest.mark.parametrize("how", [signal.SIGINT, signal.SIGTERM])
def test_prints_each_frame_with_its_meaning(pty_bus, how):
    bus = pty_bus(ports=2)
    process = monitor(bus.paths[0])
    try:
        play(bus.paths[1])
    finally:
        lines, err = stop_after(process, len(TRAFFIC), how)
    times = [float(line[:10]) for line in lines]
    assert [line[11:] for line in lines] == TEXT
    assert times == sorted(times)
    assert 0 < times[0] < 10
    assert err == ""


def test_raw_adds_the_hex(pty_bus):
    bus = pty_bus(ports=2)
    process = monitor(bus.paths[0], "--raw")
    try:
        play(bus.paths[1])
    finally:
        lines, _ = stop_after(process, len(TRAFFIC), signal.SIGINT)
    expected = [f"{text} | {frame}" for text, frame in zip(TEXT, TRAFFIC, strict=True)]
    assert [line[11:] for line in lines] == expected


def test_json_lines(pty_bus):
    bus = pty_bus(ports=2)
    process = monitor(bus.paths[0], "--json", "--time", "iso")
    try:
        play(bus.paths[1])
    finally:
        lines, _ = stop_after(process, len(TRAFFIC), signal.SIGTERM)
    records = [json.loads(line) for line in lines]
    for record in records:
        assert record.pop("time").startswith(time.strftime("%Y-"))
        assert "T" in record.pop("end")
        assert "frame" not in record
    assert records[0] == {
        "index": 0,
        "unit": 17,
        "direction": "request",
        "function_code": 3,
        "function": "read holding registers",
        "crc": "ok",
        "description": "unit 17 read holding registers 107..109 (3)",
        "pdu": {"type": "ReadHoldingRegistersRequest", "address": 107, "count": 3},
        "error": None,
        "request_index": None,
        "discard_reason": None,
        "table": "holding_registers",
        "address": 107,
        "count": 3,
    }
    assert records[1] == {
        "index": 1,
        "unit": 17,
        "direction": "reply",
        "function_code": 3,
        "function": "read holding registers",
        "crc": "ok",
        "description": "unit 17 reply holding 107..109 = [44609, 22098, 17216]",
        "pdu": {"type": "ReadHoldingRegistersResponse", "values": [44609, 22098, 17216]},
        "error": None,
        "request_index": 0,
        "discard_reason": None,
        "table": "holding_registers",
        "address": 107,
        "count": 3,
        "values": [44609, 22098, 17216],
    }
    assert records[3]["pdu"] == {
        "type": "ExceptionPDU",
        "exception": "ILLEGAL_DATA_ADDRESS",
        "function_code": 1,
        "exception_code": 2,
    }
    assert records[5] == {
        "index": 5,
        "unit": None,
        "direction": "unknown",
        "function_code": None,
        "function": None,
        "crc": "error",
        "description": "CRC error: 11 03 06 AE 41 56 52 43 40 49 AE",
        "pdu": None,
        "error": "CRC mismatch: frame carries 0xAE49, content gives 0xAD49",
        "request_index": None,
        "discard_reason": "crc",
    }
    assert [record["description"] for record in records] == [text[20:] for text in TEXT]


def test_a_paced_bus_gives_every_byte_once_in_order_whatever_the_load(pty_bus):
    # At 19200 baud the bus's relay writes each byte at its wire time; where it is held off
    # the CPU in mid-frame the frame may come out in pieces (see the module docstring), but
    # no byte is lost, repeated or moved, and a frame that comes whole means what it says.
    bus = pty_bus(ports=2, settings=SETTINGS)
    process = monitor(bus.paths[0], "--json", "--raw")
    played = "".join(frame.replace(" ", "") for frame in TRAFFIC)

    def all_bytes_out(lines: list[str]) -> bool:
        return len("".join(json.loads(line)["frame"] for line in lines).replace(" ", "")) >= len(
            played
        )

    try:
        play(bus.paths[1])
    finally:
        lines, _ = stop_when_printed(process, all_bytes_out, signal.SIGTERM)
    records = [json.loads(line) for line in lines]
    assert "".join(record["frame"] for record in records).replace(" ", "") == played
    assert [record["index"] for record in records] == list(range(len(records)))
    meaning = dict(zip(TRAFFIC, (text[20:] for text in TEXT), strict=True))
    whole = [record for record in records if record["frame"] in meaning]
    assert whole, "no frame came whole"
    for record in whole:
        if record["direction"] != "reply":  # a reply's meaning needs its request whole too
            assert record["description"] == meaning[record["frame"]]


@pytest.mark.parametrize("port", ["/dev/aiortu-no-such-port", "rtu+tcp://127.0.0.1:1"])
def test_a_bad_port_is_one_line_and_exit_1(port):
    result = run_aiortu("monitor", port, timeout=20)
    assert result.returncode == 1
    assert result.stdout == ""
    assert result.stderr.count("\n") == 1
    assert result.stderr.startswith(f"aiortu monitor: cannot open the port: {port}")


def test_modbus_tcp_is_refused_as_nothing_to_monitor():
    result = run_aiortu("monitor", "tcp://127.0.0.1:1")
    assert (result.returncode, result.stdout) == (2, "")
    assert result.stderr == (
        "aiortu monitor: error: PORT must be a serial device path or rtu+tcp://host:port, "
        "not tcp://127.0.0.1:1 (a Modbus TCP connection carries only its own requests and "
        "replies)\n"
    )


@pytest.mark.parametrize(
    "argv",
    [
        ["monitor"],
        ["monitor", "/dev/x", "--parity", "Q"],
        ["monitor", "/dev/x", "--timing", "loose"],
        ["monitor", "/dev/x", "--baudrate", "0"],
        ["monitor", "ftp://host:1"],
    ],
)
def test_bad_arguments_exit_2_with_one_line(argv, capsys):
    try:
        code = main(argv)
    except SystemExit as exc:
        code = exc.code
    assert code == 2
    captured = capsys.readouterr()
    assert captured.out == ""
    assert len(captured.err.strip().splitlines()) == 1


def test_help_has_examples_exit_codes_and_mbpoll(capsys):
    with pytest.raises(SystemExit) as raised:
        main(["monitor", "--help"])
    assert raised.value.code == 0
    out = capsys.readouterr().out
    assert "examples:" in out
    assert "exit codes:" in out
    assert "mbpoll -P even|odd|none" in out

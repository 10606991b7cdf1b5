"""``aiortu monitor --framing ascii``: Modbus ASCII frames decoded with their meaning, bad ones
shown with the receiver's reason; and the ASCII line defaults (7E1, 8N2 on a pty)."""

from __future__ import annotations

import argparse
import signal
import time

import serial

from aiortu.cli._arguments import resolve_line_settings
from aiortu.cli._monitor_ascii import AsciiBusDecoder
from aiortu.core.ascii import encode_ascii_frame
from aiortu.core.rtu import CrcStatus
from aiortu.core.serial import LineSettings
from tests.cli.cli_helpers import start_aiortu, stop

SETTINGS = LineSettings(19200, parity="N", stopbits=2)

REQUEST = encode_ascii_frame(17, bytes.fromhex("03 006B 0003"))
REPLY = encode_ascii_frame(17, bytes.fromhex("03 06 AE41 5652 4340"))
BAD_LRC = REPLY[:-4] + b"00\r\n"

TEXT = [
    "request   ok        unit 17 read holding registers 107..109 (3)",
    "reply     ok        unit 17 reply holding 107..109 = [44609, 22098, 17216]",
]


def test_the_decoder_pairs_requests_and_replies_and_names_bad_frames() -> None:
    decoder = AsciiBusDecoder()
    records = decoder.feed(REQUEST + REPLY + BAD_LRC + b":11ZZ\r\n", now=1.0)
    assert [record.description for record in records[:2]] == [text[20:] for text in TEXT]
    assert records[0].frame == bytes.fromhex("11 03 006B 0003 7E")  # unit, PDU, LRC
    assert records[2].crc is CrcStatus.ERROR
    assert "LRC" in records[2].description
    assert records[3].crc is CrcStatus.UNCHECKED
    assert records[3].description.endswith(":11ZZ")


def test_the_inter_character_timeout_ends_a_frame_that_stops() -> None:
    decoder = AsciiBusDecoder()
    assert decoder.feed(REQUEST[:7], now=0.0) == []
    deadline = decoder.receiver.next_deadline()
    assert deadline is not None
    assert decoder.expire(deadline) == []
    (record,) = decoder.expire(deadline + 0.001)
    assert record.crc is CrcStatus.UNCHECKED
    assert record.description.endswith(REQUEST[:7].decode())


def test_the_monitor_command_prints_ascii_frames(pty_bus) -> None:  # type: ignore[no-untyped-def]
    bus = pty_bus(ports=2, settings=SETTINGS)
    process = start_aiortu("monitor", bus.paths[0], "--framing", "ascii")
    try:
        assert process.stderr is not None
        ready = process.stderr.readline()
        # A pty keeps neither parity nor 7 data bits: ASCII there defaults to 8N2.
        assert ready.startswith(f"aiortu monitor: listening on {bus.paths[0]} at 19200 8N2"), ready
        with serial.Serial(bus.paths[1], 19200, parity="N", stopbits=2) as line:
            time.sleep(0.05)
            for frame in (REQUEST, REPLY, BAD_LRC):
                line.write(frame)
                line.flush()
                time.sleep(0.05)
            time.sleep(0.2)
    finally:
        out, err = stop(process, signal.SIGINT)
    lines = [line[11:] for line in out.splitlines()]
    assert lines[:2] == TEXT
    assert lines[2].startswith("unknown   error     ")
    assert err == ""


def _resolved(port: str, framing: str, bytesize: int | None = None) -> str:
    args = argparse.Namespace(
        port=port, framing=framing, bytesize=bytesize, parity=None, stopbits=None
    )
    resolve_line_settings(args)
    return f"{args.bytesize}{args.parity}{args.stopbits}"


def test_ascii_defaults_to_7e1_and_to_8n2_on_a_pty(pty_bus) -> None:  # type: ignore[no-untyped-def]
    assert _resolved("/dev/ttyUSB0", "ascii") == "7E1"
    assert _resolved("/dev/ttyUSB0", "rtu") == "8E1"
    assert _resolved("/dev/ttyUSB0", "ascii", 8) == "8E1"  # as asked, with the warning
    bus = pty_bus(ports=2, settings=SETTINGS)
    assert _resolved(bus.paths[0], "ascii") == "8N2"

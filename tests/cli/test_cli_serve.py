"""``aiortu serve``'s trace and timing options, and how ``poll`` shows a failed point."""

from __future__ import annotations

import contextlib
import json
import logging
import re
from collections.abc import AsyncIterator
from typing import Any

import pytest

from aiortu.cli import _serve, build_parser
from aiortu.cli._poll import _format_value, _json_sample
from aiortu.core.model import Point
from aiortu.core.rtu import encode_frame
from aiortu.errors import (
    ConnectionLost,
    CRCError,
    ExceptionResponse,
    FrameError,
    ResponseTimeout,
    UnitOffline,
    UnitSkipped,
)
from aiortu.master import Sample

STAMP = r"\d\d:\d\d:\d\d\.\d{3}"


def test_the_trace_stamps_milliseconds_and_shows_the_coils_asked_for(
    capsys: pytest.CaptureFixture[str],
) -> None:
    trace = _serve.Tracer()
    trace("received", encode_frame(17, bytes([0x01, 0x00, 0x13, 0x00, 0x03])))
    trace("sent", encode_frame(17, bytes([0x01, 0x01, 0b101])))
    trace("discarded", b"\x01\x02")
    lines = capsys.readouterr().err.splitlines()
    assert re.fullmatch(
        f"{STAMP} <- 11 01 00 13 00 03 8f 5e  unit 17 read coils 19..21 \\(3\\)", lines[0]
    )
    # Three coils, as asked, not the eight bits of the reply's byte.
    assert re.fullmatch(
        f"{STAMP} -> 11 01 01 05 95 4b  unit 17 reply coils 19..21 = \\[1, 0, 1\\]", lines[1]
    )
    assert re.fullmatch(f"{STAMP} xx 01 02  discarded 2 bytes", lines[2])


@pytest.mark.parametrize("timing", ["strict", "tolerant"])
async def test_serve_passes_its_timing_to_the_slave(
    timing: str, monkeypatch: pytest.MonkeyPatch
) -> None:
    seen: dict[str, Any] = {}

    class Stopped:
        connection_error = ConnectionLost("the line failed: the port closed")

        async def wait_stopped(self) -> None:
            pass

    @contextlib.asynccontextmanager
    async def fake_serve(port: str, units: object, **options: Any) -> AsyncIterator[Stopped]:
        seen.update(options)
        yield Stopped()

    monkeypatch.setattr(_serve, "serve", fake_serve)
    args = build_parser("serve").parse_args(
        ["serve", "/dev/null", "--config", "x.toml", "--timing", timing, "--parity", "even"]
    )
    _serve.resolve_line_settings(args)
    error = await _serve._serve_once(args, {}, None)
    assert seen["timing"] == timing
    assert (seen["parity"], seen["stopbits"]) == ("E", 1)
    assert error is Stopped.connection_error


def test_a_point_refused_by_the_device_shows_the_exception_code() -> None:
    point = Point.of("a", 1, "40001")
    refused = Sample(point, None, 0.0, 0, ExceptionResponse(2, 3, 1))
    assert _format_value(refused) == "-- exception 02 (illegal data address)"


@pytest.mark.parametrize(
    ("error", "shown"),
    [
        (ResponseTimeout("no reply from unit 1"), "-- no reply"),
        (UnitSkipped(1, 4.2), "-- skipped, unit offline"),
        (UnitOffline(1, 3), "-- unit offline"),
        (CRCError(0x1234, 0x4321), "-- bad CRC"),
        (FrameError("the reply is not one to this request"), "-- bad reply"),
        (ConnectionLost("the line failed: the port is gone"), "-- line lost"),
        (
            ExceptionResponse(0x0B, 3, 1),
            "-- exception 0B (gateway target device failed to respond)",
        ),
        (ExceptionResponse(0x42, 3, 1), "-- exception 42"),
    ],
)
def test_a_point_without_a_value_says_why_in_words(error: Exception, shown: str) -> None:
    sample = Sample(Point.of("a", 1, "40001"), None, 0.0, 0, error)
    assert _format_value(sample) == shown


def test_a_json_sample_gives_the_error_as_the_library_words_it() -> None:
    point = Point.of("a", 1, "40001")
    lost = Sample(point, None, 0.0, 4, ConnectionLost("the line failed: the port closed"))
    assert json.loads(_json_sample(lost)) == {
        "cycle": 5,
        "name": "a",
        "unit": 1,
        "value": None,
        "error": "the line failed: the port closed",
    }


def test_the_librarys_warnings_show_as_one_line_each_while_serving(
    capsys: pytest.CaptureFixture[str],
) -> None:
    from aiortu.cli._messages import library_warnings_on_stderr

    log = logging.getLogger("aiortu.slave")
    with library_warnings_on_stderr("serve"):
        log.info("not shown")
        log.warning("RTU over TCP: %d lines connected, the most allowed", 8)
        try:
            raise OSError("the peer reset the connection")
        except OSError:
            log.exception("RTU over TCP: a line failed; it is closed")
    log.warning("after the command: not shown")
    assert capsys.readouterr().err == (
        "aiortu serve: RTU over TCP: 8 lines connected, the most allowed\n"
        "aiortu serve: RTU over TCP: a line failed; it is closed (the peer reset the connection)\n"
    )

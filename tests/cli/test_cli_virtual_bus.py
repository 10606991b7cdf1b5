"""``aiortu virtual-bus`` as users run it: a subprocess that prints paths and relays."""

from __future__ import annotations

import signal
import subprocess
import time

import pytest
import serial

from aiortu.cli import main
from tests.cli.cli_helpers import run_aiortu, start_aiortu

pytestmark = pytest.mark.timeout(30)


def start_bus(*args: str) -> tuple[subprocess.Popen[str], list[str]]:
    process = start_aiortu("virtual-bus", *args)
    assert process.stdout is not None
    count = int(args[args.index("--ports") + 1]) if "--ports" in args else 2
    paths = [process.stdout.readline().strip() for _ in range(count)]
    return process, paths


def read_exactly(port: serial.Serial, count: int) -> bytes:
    data = b""
    deadline = time.monotonic() + 5
    while len(data) < count and time.monotonic() < deadline:
        data += port.read(count - len(data))
    return data


@pytest.mark.parametrize("stop", [signal.SIGTERM, signal.SIGINT])
def test_relays_and_exits_cleanly(stop):
    process, paths = start_bus("--ports", "2")
    try:
        assert len(paths) == 2
        assert all(path.startswith("/dev/") for path in paths)
        with (
            serial.Serial(paths[0], 19200, timeout=0.5) as a,
            serial.Serial(paths[1], 19200, timeout=0.5) as b,
        ):
            a.write(b"\x01\x03\x00\x00\x00\x01\x84\x0a")
            assert read_exactly(b, 8) == b"\x01\x03\x00\x00\x00\x01\x84\x0a"
            b.write(b"back")
            assert read_exactly(a, 4) == b"back"
    finally:
        process.send_signal(stop)
        assert process.wait(timeout=10) == 0


def test_links_and_options(tmp_path):
    process, paths = start_bus(
        "--ports", "3", "--baudrate", "9600", "--parity", "N", "--stopbits", "2",
        "--chunk-size", "8", "--latency", "0.002", "--link-dir", str(tmp_path),
    )  # fmt: skip
    try:
        assert paths == [str(tmp_path / f"port{i}") for i in range(3)]
    finally:
        process.terminate()
        assert process.wait(timeout=10) == 0
    assert list(tmp_path.iterdir()) == []


@pytest.mark.parametrize(
    "argv",
    [
        ["virtual-bus", "--ports", "0"],
        ["virtual-bus", "--ports", "x"],
        ["virtual-bus", "--parity", "Q"],
        ["virtual-bus", "--drop-rate", "2"],
        ["virtual-bus", "--gap-rate", "0.1"],
        ["virtual-bus", "--latency", "-1"],
        ["virtual-bus", "--bogus"],
        ["no-such-command"],
        [],
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
    assert "error" in captured.err


def test_a_gap_rate_without_a_gap_names_both_flags(capsys):
    assert main(["virtual-bus", "--gap-rate", "0.1"]) == 2
    assert capsys.readouterr().err == (
        "aiortu virtual-bus: error: --gap-rate needs --gap SECONDS, the length of each pause\n"
    )


def test_bad_arguments_in_a_subprocess():
    result = run_aiortu("virtual-bus", "--ports", "-3", timeout=20)
    assert result.returncode == 2
    assert result.stdout == ""
    assert result.stderr.count("\n") == 1


def test_help_has_examples(capsys):
    with pytest.raises(SystemExit) as raised:
        main(["virtual-bus", "--help"])
    assert raised.value.code == 0
    out = capsys.readouterr().out
    assert "examples:" in out
    assert "mbpoll" in out

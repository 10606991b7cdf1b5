"""What mbpoll users look for: `aiortu identify` (device identification and server id), hex
display, addresses in the notation given, and the RS-485 options of the library on the
command line."""

from __future__ import annotations

import argparse
import json
from collections.abc import Iterator
from pathlib import Path

import pytest

from aiortu.cli._master import rs485_options
from aiortu.core.serial import LineSettings
from aiortu.testing import PtyBus
from aiortu.transport import RS485Options
from tests.cli.cli_helpers import run_aiortu, serving_tcp, start_aiortu, stop

pytestmark = pytest.mark.timeout(60)

DEVICES = str(Path(__file__).parents[2] / "examples" / "devices.toml")


@pytest.fixture(scope="module")
def port() -> Iterator[str]:
    """A pty bus port; `aiortu serve` of examples/devices.toml (5, 6, 17) on the other."""
    with PtyBus(2, settings=LineSettings(19200, parity="N", stopbits=2)).running_in_thread() as bus:
        serve = start_aiortu("serve", bus.paths[1], "--config", DEVICES)
        assert serve.stderr is not None
        assert "Ctrl-C to stop" in serve.stderr.readline()
        try:
            yield bus.paths[0]
        finally:
            stop(serve)


def test_identify_reads_the_objects_and_the_server_id(port: str) -> None:
    result = run_aiortu("identify", port, "--unit", "17")
    assert (result.returncode, result.stderr) == (0, "")
    assert result.stdout.splitlines() == [
        "vendor name: aiortu",
        "product code: SIM-17",
        "major minor revision: 1.0",
        "product name: simulated meter",
        "0x80: serial 0001",
        "server id: 0x11, run indicator on",
        "additional data: meter",
    ]
    as_json = json.loads(run_aiortu("identify", port, "--unit", "17", "--json").stdout)
    assert as_json == {
        "unit": 17,
        "device_identification": {
            "vendor_name": "aiortu", "product_code": "SIM-17", "major_minor_revision": "1.0",
            "product_name": "simulated meter", "0x80": "serial 0001",
        },
        "server_id": {"id": "11", "running": True, "data": "meter"},
    }  # fmt: skip
    basic = run_aiortu("identify", port, "--unit", "17", "--level", "basic")
    assert basic.stdout.splitlines()[:4] == [
        "vendor name: aiortu", "product code: SIM-17", "major minor revision: 1.0",
        "server id: 0x11, run indicator on",
    ]  # fmt: skip


def test_identify_says_which_of_the_two_a_unit_refuses(port: str) -> None:
    result = run_aiortu("identify", port, "--unit", "5")
    assert (result.returncode, result.stderr) == (0, "")
    assert result.stdout == (
        "device identification: refused (exception 01, illegal function)\n"
        "server id: 0x05, run indicator on\n"
    )
    as_json = json.loads(run_aiortu("identify", port, "--unit", "5", "--json").stdout)
    assert as_json["device_identification"] is None


def test_identify_a_unit_that_has_neither_fails_with_its_exception(tmp_path: Path) -> None:
    # A Modbus TCP server answers no serial-line code unless told to: unit 5 has neither.
    with serving_tcp(DEVICES) as url:
        result = run_aiortu("identify", url, "--unit", "5")
    assert (result.returncode, result.stdout) == (4, "")
    assert result.stderr == (
        "aiortu identify: exception response ILLEGAL_FUNCTION (0x01) from unit 5, function 0x2B\n"
    )


def test_read_shows_references_as_given_and_hex_on_request(port: str) -> None:
    by_ref = run_aiortu("read", port, "--unit", "17", "--ref", "40108", "--count", "3")
    assert by_ref.stdout == "40108 44609\n40109 22098\n40110 17216\n"
    six = run_aiortu("read", port, "--unit", "17", "--ref", "400108", "--count", "2", "--hex")
    assert six.stdout == "400108 0xAE41\n400109 0x5652\n"
    by_address = run_aiortu("read", port, "--unit", "17", "--table", "holding",
                            "--address", "107", "--count", "1", "--hex")  # fmt: skip
    assert by_address.stdout == "107 0xAE41\n"
    coils = run_aiortu("read", port, "--unit", "17", "--ref", "00020", "--count", "3", "--hex")
    assert coils.stdout == "00020 1\n00021 0\n00022 1\n"


def test_write_shows_the_reference_it_was_given(port: str) -> None:
    written = run_aiortu("write", port, "--unit", "5", "--ref", "40003", "--values", "7,8")
    assert (written.returncode, written.stdout) == (0, "40003 7\n40004 8\n")


def test_poll_shows_whole_numbers_in_hex_as_wide_as_the_point(port: str) -> None:
    result = run_aiortu("poll", port, "--point", "w=17:40108", "--point", "d=17:40108:int32",
                        "--cycles", "1", "--hex")  # fmt: skip
    assert result.returncode == 0, result.stderr
    assert result.stdout.splitlines()[2:4] == [
        "w                  17  0xAE41",
        "d                  17  0xAE415652",
    ]


def test_the_rs485_flags_are_the_librarys_options() -> None:
    def options(*flags: str) -> dict[str, object]:
        parser = argparse.ArgumentParser()
        parser.add_argument("port")
        from aiortu.cli._master import add_rs485_options

        add_rs485_options(parser)
        return rs485_options(parser.parse_args(["/dev/ttyUSB0", *flags]))

    assert options() == {}
    assert options("--rs485") == {"rs485": RS485Options(), "local_echo": False}
    assert options("--rs485-rts-low", "--rs485-delay-before-tx", "0.002") == {
        "rs485": RS485Options(False, True, delay_before_tx=0.002), "local_echo": False,
    }  # fmt: skip
    assert options("--rs485-receive-during-tx") == {
        "rs485": RS485Options(receive_during_tx=True), "local_echo": True,
    }  # fmt: skip


def test_rs485_reaches_the_driver_which_a_pty_refuses(port: str) -> None:
    result = run_aiortu("read", port, "--unit", "17", "--ref", "40108", "--rs485")
    assert result.returncode == 1
    assert "RS-485" in result.stderr
    assert result.stderr.count("\n") == 1
    url = run_aiortu("read", "tcp://127.0.0.1:1", "--unit", "1", "--ref", "40001", "--rs485")
    assert (url.returncode, url.stderr) == (
        2, "aiortu read: error: the --rs485 options are for a serial port, not a URL\n"
    )  # fmt: skip

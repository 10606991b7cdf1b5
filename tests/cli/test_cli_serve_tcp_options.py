"""``aiortu serve tcp://`` with the Modbus TCP server's settings the Python API has: the
serial-line codes (``--serial-line-codes``) and unit aliases (``--unit-alias ID=UNIT``)."""

from __future__ import annotations

from pathlib import Path

import pytest

from tests.cli.cli_helpers import run_aiortu, serving_tcp

pytestmark = pytest.mark.timeout(60)

DEVICES = str(Path(__file__).parents[2] / "examples" / "devices.toml")


def test_serial_line_codes_and_aliases_on_the_command_line() -> None:
    with serving_tcp(DEVICES, "--serial-line-codes", "--unit-alias", "255=17",
                     "--unit-alias", "0x00=5") as url:  # fmt: skip
        identified = run_aiortu("identify", url, "--unit", "255", "--level", "basic")
        read = run_aiortu("read", url, "--unit", "0", "--ref", "40001", "--count", "2")
        written = run_aiortu("write", url, "--unit", "5", "--ref", "40001", "--values", "9")
        again = run_aiortu("read", url, "--unit", "0", "--ref", "40001")
    assert (identified.returncode, identified.stderr) == (0, "")
    assert identified.stdout.splitlines()[-2:] == [
        "server id: 0x11, run indicator on",
        "additional data: meter",
    ]
    assert (read.returncode, read.stdout) == (0, "40001 0\n40002 0\n")
    assert written.returncode == 0
    assert again.stdout == "40001 9\n"


def test_without_them_the_server_keeps_the_specs_defaults() -> None:
    # Several units: no alias, and the serial-line codes get exception 01.
    with serving_tcp(DEVICES) as url:
        identified = run_aiortu("identify", url, "--unit", "17", "--level", "basic")
        unaliased = run_aiortu("read", url, "--unit", "255", "--ref", "40108")
    assert identified.stdout.splitlines()[-1] == (
        "server id: refused (exception 01, illegal function)"
    )
    assert unaliased.returncode == 4


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (["/dev/null", "--serial-line-codes"],
         "--serial-line-codes is for a Modbus TCP server (tcp://, udp://, tls://): a serial "
         "line serves every code and has no unit ids but its units"),
        (["/dev/null", "--unit-alias", "255=17"],
         "--unit-alias is for a Modbus TCP server (tcp://, udp://, tls://): a serial line "
         "serves every code and has no unit ids but its units"),
        (["tcp://127.0.0.1:0", "--unit-alias", "255=99"],
         f"--unit-alias names unit 99, which {DEVICES} does not describe (it has 5, 6, 17)"),
        (["tcp://127.0.0.1:0", "--unit-alias", "256=5"],
         "argument --unit-alias: must be ID=UNIT, a unit id 0..255 and a served unit 1..247 "
         "(255=17), not 256=5"),
        (["tcp://127.0.0.1:0", "--unit-alias", "17"],
         "argument --unit-alias: must be ID=UNIT, a unit id 0..255 and a served unit 1..247 "
         "(255=17), not 17"),
    ],
)  # fmt: skip
def test_bad_settings_are_one_line(args: list[str], message: str) -> None:
    port, *options = args
    result = run_aiortu("serve", port, "--config", DEVICES, *options)
    assert (result.returncode, result.stdout) == (2, "")
    assert result.stderr == f"aiortu serve: error: {message}\n"


WITH_TCP_TABLE = """\
[[slave]]
unit = 17
[[slave.holding_registers]]
start = 0
values = [7]
[slave.server_id]
id = [0x11]
run = true

[[slave]]
unit = 5
[[slave.holding_registers]]
start = 0
values = [5]

[modbus_tcp]
serial_line_codes = true
unit_aliases = { "255" = 17 }
"""


def test_the_files_modbus_tcp_table_sets_the_same(tmp_path: Path) -> None:
    config = tmp_path / "devices.toml"
    config.write_text(WITH_TCP_TABLE)
    with serving_tcp(config, "--unit-alias", "0=5") as url:
        identified = run_aiortu("identify", url, "--unit", "255", "--level", "basic")
        as_17 = run_aiortu("read", url, "--unit", "255", "--ref", "40001")
        as_5 = run_aiortu("read", url, "--unit", "0", "--ref", "40001")
    assert identified.stdout.splitlines()[-1] == "server id: 0x11, run indicator on"
    assert (as_17.stdout, as_5.stdout) == ("40001 7\n", "40001 5\n")

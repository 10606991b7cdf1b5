"""The TOML device description: what it builds, and one clear line for every mistake."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

from aiortu.errors import ExceptionResponse, InvalidValue
from aiortu.slave import ConfigError, MemoryStore, Table, load_config, parse_config

EXAMPLE = Path(__file__).parents[2] / "examples" / "devices.toml"


def test_the_example_file_builds_every_feature() -> None:
    units = load_config(EXAMPLE).units
    assert sorted(units) == [5, 6, 17]
    store = units[17]
    assert store.get(Table.HOLDING_REGISTERS, 0x6B, 3) == [0xAE41, 0x5652, 0x4340]
    assert store.get(Table.INPUT_REGISTERS, 0x6B) == [0xAE41]  # aliased
    assert store.read_fifo_queue(0x04DE) == [440, 25]
    assert store.read_file_record(4, 0, 3) == [0x06AF, 0x04BE, 0x100D]
    assert store.device_identification()[0x80] == b"serial 0001"
    assert store.report_server_id() is not None
    assert units[5] is units[6]
    with pytest.raises(Exception, match=r"02|ILLEGAL"):
        store.write(Table.HOLDING_REGISTERS, 0x100, [1])


BAD = [
    ("", "slave", "missing"),
    ("x = 1", "(top).x", "unknown key"),
    ("[[slave]]\nunit = 0", "slave[0].unit", "1..247"),
    ("[[slave]]\nunit = '1'", "slave[0].unit", "integer"),
    ("[[slave]]\n", "slave[0].unit", "missing"),
    ("[[slave]]\nunit = 1\nunits = [2]", "slave[0].units", "not both"),
    ("[[slave]]\nunit = 1\ncolor = 1", "slave[0].color", "unknown key"),
    ("[[slave]]\nunit = 1\n[[slave]]\nunit = 1", "slave[1].unit", "twice"),
    (
        "[[slave]]\nunit = 1\n[[slave.coils]]\nstart = 0",
        "slave[0].coils[0].count",
        "missing",
    ),
    (
        "[[slave]]\nunit = 1\n[[slave.coils]]\nstart = 0\ncount = 0",
        "slave[0].coils[0].count",
        "1..",
    ),
    (
        "[[slave]]\nunit = 1\n[[slave.coils]]\nstart = 0\nvalues = [2]",
        "slave[0].coils[0].values[0]",
        "0..1",
    ),
    (
        "[[slave]]\nunit = 1\n[[slave.holding_registers]]\nstart = 0\ncount = 1\nvalues = [1, 2]",
        "slave[0].holding_registers[0].values",
        "more than count",
    ),
    (
        "[[slave]]\nunit = 1\n[[slave.holding_registers]]\nstart = 70000\ncount = 1",
        "slave[0].holding_registers[0].start",
        "0..65535",
    ),
    (
        "[[slave]]\nunit = 1\n[[slave.holding_registers]]\nstart = 0\ncount = 2\n"
        "[[slave.holding_registers]]\nstart = 1\ncount = 2",
        "slave[0]",
        "overlap",
    ),
    ("[[slave]]\nunit = 1\nholding_registers = 3", "slave[0].holding_registers", "array"),
    ("[[slave]]\nunit = 1\n[slave.aliases]\ncoils = 'nothing'", "slave[0].aliases.coils", "table"),
    (
        "[[slave]]\nunit = 1\n[slave.aliases]\ncoils = 'holding_registers'",
        "slave[0]",
        "same kind",
    ),
    (
        "[[slave]]\nunit = 1\n[[slave.read_only]]\ntable = 'x'\nstart = 0\ncount = 1",
        "slave[0].read_only[0].table",
        "table",
    ),
    ("[[slave]]\nunit = 1\n[[slave.fifo]]\nvalues = [1]", "slave[0].fifo[0].address", "missing"),
    (
        "[[slave]]\nunit = 1\n[[slave.files]]\nfile = 0\nrecords = 1",
        "slave[0].files[0].file",
        "1..",
    ),
    ("[[slave]]\nunit = 1\n[[slave.files]]\nfile = 1", "slave[0].files[0].records", "missing"),
    (
        "[[slave]]\nunit = 1\n[slave.device_identification]\ncolour = 'red'",
        "slave[0].device_identification.colour",
        "unknown object",
    ),
    (
        "[[slave]]\nunit = 1\n[slave.device_identification]\nobjects = { 'x' = 'a' }",
        "slave[0].device_identification.objects.x",
        "object id",
    ),
    (
        "[[slave]]\nunit = 1\n[slave.device_identification]\nvendor_name = '" + "v" * 245 + "'",
        "slave[0].device_identification",
        "244",
    ),
    ("[[slave]]\nunit = 1\n[slave.server_id]\nrun = true", "slave[0].server_id.id", "missing"),
    ("[[slave]]\nunit = 1\n[slave.server_id]\nid = ''", "slave[0].server_id", "at least one"),
    ("[[slave]]\nunit = 1\n[slave.server_id]\nid = 'a'\nrun = 1", "slave[0].server_id.run", "true"),
    ("[[slave]]\nunit = 1\nexception_status = 256", "slave[0].exception_status", "0..255"),
    ("[[slave]\nunit = 1", "(syntax)", ""),
    (
        "[[slave]]\nunit = 1\n[[slave.fifo]]\naddress = 5\n[[slave.fifo]]\naddress = 5",
        "slave[0].fifo[1].address",
        "FIFO queue 5 is described twice",
    ),
    (
        "[[slave]]\nunit = 1\n[[slave.files]]\nfile = 3\nrecords = 4\n"
        "[[slave.files]]\nfile = 3\nvalues = [1]",
        "slave[0].files[1].file",
        "file 3 is described twice",
    ),
    (
        "[[slave]]\nunit = 1\n[[slave.holding_registers]]\nstart = 10\ncount = 5\n"
        "[[slave.read_only]]\ntable = 'holding_registers'\nstart = 100\ncount = 2",
        "slave[0].read_only[0]",
        "address 100 of the range is outside every holding_registers block",
    ),
    (
        "[[slave]]\nunit = 1\n[[slave.holding_registers]]\nstart = 10\ncount = 5\n"
        "[[slave.read_only]]\ntable = 'holding_registers'\nstart = 12\ncount = 5",
        "slave[0].read_only[0]",
        "address 15 of the range is outside",
    ),
    (
        "[[slave]]\nunit = 1\n[[slave.holding_registers]]\nstart = 0\ncount = 5\n"
        "[slave.aliases]\ninput_registers = 'holding_registers'\n"
        "[[slave.read_only]]\ntable = 'input_registers'\nstart = 5\ncount = 1",
        "slave[0].read_only[0]",
        "address 5 of the range is outside every input_registers block",
    ),
    (
        "[[slave]]\nunit = 1\nread_only_exception = 99",
        "slave[0].read_only_exception",
        "must be one of the spec's exception codes (1, 2, 3, 4, 5, 6, 8, 10, 11), not 99",
    ),
]


@pytest.mark.parametrize(("text", "key", "problem"), BAD)
def test_every_mistake_names_file_key_and_problem(text: str, key: str, problem: str) -> None:
    with pytest.raises(ConfigError) as caught:
        parse_config(text, "dev.toml")
    message = str(caught.value)
    assert message.startswith(f"dev.toml: {key}: "), message
    assert problem in message
    assert "\n" not in message


def test_serve_with_a_bad_file_prints_one_line_and_exits_2(tmp_path: Path) -> None:
    path = tmp_path / "bad.toml"
    path.write_text("[[slave]]\nunit = 300\n")
    result = subprocess.run(
        [sys.executable, "-m", "aiortu", "serve", "/dev/null", "--config", str(path)],
        capture_output=True,
        text=True,
        timeout=30,
        check=False,
    )
    assert result.returncode == 2
    lines = result.stderr.strip().splitlines()
    assert lines == [f"aiortu serve: error: {path}: slave[0].unit: must be 1..247, not 300"]


def test_serve_with_a_missing_file_exits_2(tmp_path: Path) -> None:
    result = subprocess.run(
        [sys.executable, "-m", "aiortu", "serve", "/dev/null", "--config", str(tmp_path / "no")],
        capture_output=True,
        text=True,
        timeout=30,
        check=False,
    )
    assert result.returncode == 2
    assert len(result.stderr.strip().splitlines()) == 1
    assert result.stderr == f"aiortu serve: error: --config {tmp_path / 'no'} does not exist\n"


def test_read_only_ranges_may_span_adjacent_blocks_and_aliases() -> None:
    text = (
        "[[slave]]\nunit = 1\nread_only_exception = 4\n"
        "[[slave.holding_registers]]\nstart = 10\ncount = 5\n"
        "[[slave.holding_registers]]\nstart = 15\ncount = 5\n"
        "[slave.aliases]\ninput_registers = 'holding_registers'\n"
        "[[slave.read_only]]\ntable = 'holding_registers'\nstart = 12\ncount = 8\n"
        "[[slave.read_only]]\ntable = 'input_registers'\nstart = 10\ncount = 1"
    )
    store = parse_config(text).units[1]
    with pytest.raises(ExceptionResponse) as refused:
        store.write(Table.HOLDING_REGISTERS, 19, [1])
    assert refused.value.code == 4
    store.write(Table.HOLDING_REGISTERS, 11, [1])


def test_a_memory_store_refuses_an_exception_code_the_spec_lacks() -> None:
    with pytest.raises(InvalidValue) as caught:
        MemoryStore(read_only_exception=99)  # type: ignore[arg-type]
    assert str(caught.value).startswith("read_only_exception must be ")
    assert str(caught.value).endswith(", not 99")


def test_the_modbus_tcp_table_gives_the_servers_settings() -> None:
    head = "[[slave]]\nunit = 17\n[[slave]]\nunit = 5\n"
    assert parse_config(head).modbus_tcp == {}
    config = parse_config(
        head + '[modbus_tcp]\nserial_line_codes = true\nunit_aliases = { "255" = 17, "0x00" = 5 }\n'
    )
    assert config.modbus_tcp == {"serial_line_codes": True, "unit_aliases": {255: 17, 0: 5}}


@pytest.mark.parametrize(
    ("table", "message"),
    [
        ('serial_line_codes = "yes"',
         "modbus_tcp.serial_line_codes: must be true or false, not yes"),
        ('unit_aliases = { "256" = 17 }',
         "modbus_tcp.unit_aliases.256: must be a unit id 0..255, not 256"),
        ('unit_aliases = { "x" = 17 }',
         "modbus_tcp.unit_aliases.x: must be a unit id 0..255, not x"),
        ('unit_aliases = { "255" = 9 }',
         "modbus_tcp.unit_aliases.255: unit 9 is not described (units: 17)"),
        ("max_connections = 3", "modbus_tcp.max_connections: unknown key"),
    ],
)  # fmt: skip
def test_a_bad_modbus_tcp_table_is_one_line(table: str, message: str) -> None:
    with pytest.raises(ConfigError) as failure:
        parse_config(f"[[slave]]\nunit = 17\n[modbus_tcp]\n{table}\n", "d.toml")
    assert str(failure.value).startswith(f"d.toml: {message}")

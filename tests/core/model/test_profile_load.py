"""Loading profiles: good files give the records they describe, bad ones one clear line that
names the file, the line, the point and the key."""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

import pytest

import aiortu.bridge
import aiortu.slave
from aiortu.core.model import Access, Layout, PointType, Table, load_profile, parse_profile
from aiortu.errors import ConfigError
from aiortu.transport import load_rules

HEAD = """
[device]
manufacturer = "ACME"
model = "M1"
"""


def profile(body: str, head: str = HEAD) -> str:
    return head + body


def error_of(text: str) -> str:
    with pytest.raises(ConfigError) as caught:
        parse_profile(text, "meter.toml")
    message = str(caught.value)
    assert "\n" not in message
    assert message.startswith("meter.toml")
    return message


def test_a_full_point_is_read_as_written() -> None:
    text = profile(
        """
[defaults]
table = "input_registers"
layout = "CDAB"
base = 1
max_block = 60
max_gap = 3

[poll]
fast = 0.5

[[point]]
name = "power"
address = 11
type = "i32"
scale = 0.1
offset = -5
unit = "W"
poll = "fast"
meta = { device_class = "power" }

[[point]]
name = "setpoint"
table = "holding_registers"
address = 1
type = "uint16"
access = "rw"
min = 0
max = 100
value = 42
"""
    )
    loaded = parse_profile(text, "x.toml")
    power, setpoint = loaded.points
    assert (power.table, power.address, power.type, power.size) == (
        Table.INPUT_REGISTERS,
        10,
        PointType.I32,
        2,
    )
    assert (power.layout, power.scale, power.offset, power.unit, power.poll) == (
        Layout.CDAB,
        0.1,
        -5.0,
        "W",
        "fast",
    )
    assert power.meta == {"device_class": "power"}
    assert (setpoint.address, setpoint.type, setpoint.access) == (0, PointType.U16, Access.RW)
    assert (setpoint.minimum, setpoint.maximum, setpoint.initial) == (0, 100, 42)
    assert loaded.limits.max_block == 60
    assert loaded.limits.max_gap == 3
    assert loaded.poll_classes == {"normal": 1.0, "fast": 0.5}
    assert loaded.points_of("fast") == (power,)


def test_the_line_of_the_point_is_named() -> None:
    text = profile(
        """
[[point]]
name = "a"
address = 0

[[point]]
name = "b"
address = 1
type = "f33"
"""
    )
    message = error_of(text)
    line = text.splitlines().index('name = "b"') + 1
    assert message.startswith(f"meter.toml:{line}: point b.type: unknown type 'f33'")
    assert "known: bool, u16" in message


@pytest.mark.parametrize(
    ("body", "expected"),
    [
        (
            '[[point]]\nname = "a"\naddress = 65535\ntype = "f32"',
            "point a.address: must be 0..65534",
        ),
        ('[[point]]\nname = "a"\naddress = -1', "point a.address: must be 0..65535"),
        (
            '[[point]]\nname = "a"\naddress = 0\ntype = "f32"\n[[point]]\nname = "b"\naddress = 1',
            "point b.address: overlaps a (holding_registers 0..1)",
        ),
        (
            '[[point]]\nname = "a"\naddress = 0\nscale_factor = "a_sf"',
            "point a.scale_factor: no point named 'a_sf'",
        ),
        (
            '[[point]]\nname = "a"\naddress = 0\nscale_factor = "s"\n'
            '[[point]]\nname = "s"\naddress = 1\ntype = "f32"',
            "point a.scale_factor: s must be an integer register point",
        ),
        (
            '[[point]]\nname = "a"\ntable = "input_registers"\naddress = 0\naccess = "rw"',
            "point a.access: must be r: a master cannot write input_registers",
        ),
        ('[[point]]\nname = "a"\naddress = 0\ncolour = 1', "point a.colour: unknown key"),
        ('[[point]]\nname = "a"\naddress = 0\npoll = "fsat"', "point a.poll: unknown poll class"),
        ('[[point]]\nname = "a"\naddress = 0\ntype = "string"', "point a.size: missing"),
        ('[[point]]\nname = "a"\naddress = 0\nmin = 5\nmax = 1', "point a.min: 5 is above max 1"),
        ('[[point]]\nname = "a"\naddress = 0\nvalue = 70000', "point a.value:"),
        ('[[point]]\nname = "a"\naddress = 0\nvalues = { 1 = "x" }', "point a.values: is only"),
        ('[[point]]\nname = "a"\ntable = "coils"\naddress = 0\ntype = "u16"', "must be bool"),
        ('[[point]]\nname = "a"\naddress = 0\n[[point]]\nname = "a"\naddress = 1', "used by two"),
        ('[[point]]\nname = "9a"\naddress = 0', "point[0].name: must be a name"),
        ('[[point]]\nname = "a"', "point a.address: missing"),
        (
            '[[hole]]\nstart = 0\ncount = 4\n[[point]]\nname = "a"\naddress = 2',
            "point a.address: lies in a hole (holding_registers 0..3)",
        ),
        (
            '[defaults]\nmax_block = 200\n[[point]]\nname = "a"\naddress = 0',
            "max_block: must be 1..125",
        ),
        ('[defaults]\nlayout = "ABDC"\n[[point]]\nname = "a"\naddress = 0', "must be one of ABCD"),
        ('[poll]\nfast = 0\n[[point]]\nname = "a"\naddress = 0', "poll.fast: must be seconds > 0"),
        (
            '[device.identify]\nprobe = [{ point = "b", equals = [1] }]\n'
            '[[point]]\nname = "a"\naddress = 0',
            "device.identify.probe[0].point: no point named 'b'",
        ),
        ("", "point: missing"),
        ('[[point]]\nname = "a"\naddress = 0\nvalue = "x"\ntype = "string"\nsize = 0', "size"),
    ],
)
def test_bad_input_names_the_key(body: str, expected: str) -> None:
    assert expected in error_of(profile(body))


def test_a_missing_device_and_a_syntax_error_are_named() -> None:
    assert "meter.toml: device: missing" in error_of('[[point]]\nname = "a"\naddress = 0')
    assert "meter.toml: (syntax):" in error_of("[device\n")


@pytest.mark.parametrize(
    "load", [load_profile, aiortu.slave.load_config, aiortu.bridge.load_config, load_rules]
)
def test_a_file_that_cannot_be_read_is_named_with_why(
    load: Callable[[Path], object], tmp_path: Path
) -> None:
    # Every description file says it the same way: once, in words, without errno's repr.
    with pytest.raises(ConfigError) as missing:
        load(tmp_path / "nowhere.toml")
    assert str(missing.value) == (
        f"{tmp_path / 'nowhere.toml'}: (file): cannot be read (No such file or directory)"
    )
    binary = tmp_path / "binary.toml"
    binary.write_bytes(b"\xff\xfe")
    with pytest.raises(ConfigError, match=r"binary\.toml: \(file\): cannot be read \('utf-8'"):
        load(binary)


def test_one_based_addresses_are_shifted_and_bounded() -> None:
    text = profile('[defaults]\nbase = 1\n[[point]]\nname = "a"\naddress = 0')
    assert "point a.address: must be 1..65536" in error_of(text)
    loaded = parse_profile(profile('[defaults]\nbase = 1\n[[point]]\nname = "a"\naddress = 65536'))
    assert loaded.points[0].address == 65535


def test_enums_bitfields_and_strings() -> None:
    loaded = parse_profile(
        profile(
            """
[[point]]
name = "state"
address = 0
type = "enum"
values = { 0 = "off", 1 = "on" }
value = "on"

[[point]]
name = "alarms"
address = 1
type = "bitfield"
size = 2
bits = { 0 = "over_voltage", 17 = "fault" }
value = ["fault"]

[[point]]
name = "serial"
address = 3
type = "string"
size = 4
value = "AB12"
"""
        )
    )
    state, alarms, serial = loaded.points
    assert state.values == {0: "off", 1: "on"}
    assert state.initial == "on"
    assert (alarms.size, alarms.bits[17], alarms.initial) == (2, "fault", ("fault",))
    assert (serial.size, serial.stop, serial.initial) == (4, 7, "AB12")


def test_unknown_enum_name_and_bit_out_of_range() -> None:
    enum = '[[point]]\nname = "s"\naddress = 0\ntype = "enum"\nvalues = { 0 = "off" }\n'
    assert "point s.value: value 'on' is not one of off" in error_of(profile(enum + 'value = "on"'))
    flags = '[[point]]\nname = "f"\naddress = 0\ntype = "bitfield"\nbits = { 16 = "x" }\n'
    assert "point f.bits.16: must be a number 0..15" in error_of(profile(flags))


def test_a_text_its_encoding_cannot_hold_is_refused_not_mangled() -> None:
    text = profile('[[point]]\nname = "s"\naddress = 0\ntype = "string"\nsize = 2\nvalue = "€1"')
    assert "point s.value: text '€1' has characters ascii cannot encode" in error_of(text)
    latin = text.replace('value = "€1"', 'encoding = "latin-1"\nvalue = "é1"')
    assert parse_profile(latin).points[0].initial == "é1"


def test_find_profile_takes_a_file_before_a_shipped_name(tmp_path: Path) -> None:
    from aiortu.core.model import find_profile, shipped_profiles

    shipped = shipped_profiles()
    assert list(shipped) == sorted(shipped)
    assert "eastron-sdm630" in shipped
    assert find_profile("eastron-sdm630", tmp_path) == shipped["eastron-sdm630"]
    (tmp_path / "eastron-sdm630").write_text("", encoding="utf-8")
    assert find_profile("eastron-sdm630", tmp_path) == tmp_path / "eastron-sdm630"
    assert find_profile("nosuch", tmp_path) is None
    # Without a base the file is given back as named, for the messages that name it.
    assert find_profile(str(tmp_path / "eastron-sdm630")) == str(tmp_path / "eastron-sdm630")

"""Home Assistant `modbus:` sections and evcc meter templates converted to profiles."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import pytest
import yaml

from aiortu.core.model import (
    Access,
    Layout,
    PointType,
    Table,
    profile_from_evcc,
    profiles_from_home_assistant,
    render_evcc,
)
from aiortu.errors import ConfigError

EXAMPLES = Path(__file__).parents[3] / "examples" / "imports"


def ha_example() -> dict[tuple[str, int], Any]:
    document = yaml.safe_load((EXAMPLES / "home-assistant-modbus.yaml").read_text())
    return profiles_from_home_assistant(document, "configuration.yaml")


def test_every_entity_of_the_example_becomes_a_point_of_its_unit() -> None:
    profiles = ha_example()
    assert sorted(profiles) == [("heating", 1), ("heating", 2), ("heating", 3)]
    heat_pump = profiles[("heating", 1)]
    outside = heat_pump.point("outside_temperature")
    assert (outside.table, outside.address, outside.type, outside.scale) == (
        Table.INPUT_REGISTERS,
        0,
        PointType.I16,
        0.1,
    )
    assert outside.unit == "°C"
    assert outside.meta == {
        "name": "Outside temperature",
        "device_class": "temperature",
        "state_class": "measurement",
        "precision": 1,
    }
    hours = heat_pump.point("compressor_hours")
    assert (hours.type, hours.layout, hours.poll) == (PointType.U32, Layout.CDAB, "every_300s")
    assert heat_pump.poll_classes["every_300s"] == 300.0
    version = heat_pump.point("software_version")
    assert (version.type, version.size) == (PointType.STRING, 4)
    pump = heat_pump.point("heating_circuit_pump")
    assert (pump.table, pump.type, pump.access) == (Table.COILS, PointType.BOOL, Access.RW)
    holiday = heat_pump.point("holiday_mode")
    assert (holiday.values, holiday.access) == ({1: "off", 2: "on"}, Access.RW)
    assert heat_pump.point("holiday_mode_state").values == {1: "off", 2: "on"}
    target = heat_pump.point("living_room_target_temperature")
    assert (target.address, target.minimum, target.maximum, target.access) == (
        40,
        15.0,
        28.0,
        Access.RW,
    )
    assert heat_pump.point("living_room_hvac_mode").values == {0: "off", 1: "heat", 3: "auto"}
    meter = profiles[("heating", 2)]
    assert [p.address for p in meter.points if p.name.startswith("phase_currents")] == [6, 8, 10]
    inverter = profiles[("heating", 3)].point("inverter_temperature")
    assert (inverter.layout, inverter.offset, inverter.table) == (
        Layout.BADC,
        -40.0,
        Table.HOLDING_REGISTERS,
    )


HUB = {"name": "hub", "type": "tcp", "host": "x"}


@pytest.mark.parametrize(
    ("entity", "expected"),
    [
        (
            {"name": "T", "address": 1, "data_type": "float16"},
            "configuration.yaml: hub.sensors[0] (T).data_type: 'float16' has no profile type",
        ),
        (
            {"name": "T", "address": 1, "data_type": "custom", "structure": ">2h"},
            "hub.sensors[0] (T).data_type: 'custom' has no profile type",
        ),
        ({"name": "T"}, "hub.sensors[0] (T).address: missing"),
        ({"name": "T", "address": 70000}, "hub.sensors[0] (T).address: must be an integer"),
        ({"name": "T", "address": 1, "swap": "dword"}, "hub.sensors[0] (T).swap: must be one of"),
        (
            {"name": "T", "address": 1, "input_type": "coil"},
            "hub.sensors[0] (T).input_type: must be one of holding, input",
        ),
        ({"name": "T", "address": 1, "data_type": "string"}, "hub.sensors[0] (T).count: missing"),
        ({"name": "T", "address": 1, "scan_interval": 0}, "(T).scan_interval: must be seconds"),
    ],
)
def test_what_a_profile_cannot_say_is_named(entity: dict[str, Any], expected: str) -> None:
    with pytest.raises(ConfigError) as caught:
        profiles_from_home_assistant({"modbus": [HUB | {"sensors": [entity]}]})
    assert expected in str(caught.value)


def test_overlapping_entities_are_refused_by_the_profile_rules() -> None:
    sensors = [
        {"name": "A", "address": 0, "data_type": "int32"},
        {"name": "B", "address": 1},
    ]
    with pytest.raises(ConfigError, match=r"point b\.address: overlaps a"):
        profiles_from_home_assistant({"modbus": [HUB | {"sensors": sensors}]})


def evcc_example() -> dict[str, Any]:
    loaded: dict[str, Any] = yaml.safe_load((EXAMPLES / "evcc-meter.yaml").read_text())
    return loaded


@pytest.mark.parametrize(
    ("params", "names"),
    [
        (
            {"usage": "grid"},
            [
                "power",
                "energy",
                "returnenergy",
                "current_l1",
                "current_l2",
                "current_l3",
                "voltage_l1",
                "voltage_l2",
                "voltage_l3",
            ],
        ),
        (
            {"usage": "pv"},
            ["power", "energy", "returnenergy", "current_l1", "current_l2", "current_l3"],
        ),
        ({"usage": "pv", "phases": "false"}, ["power", "energy", "returnenergy"]),
    ],
)
def test_the_evcc_template_renders_for_its_parameters(
    params: dict[str, str], names: list[str]
) -> None:
    result = profile_from_evcc(evcc_example(), yaml.safe_load, params=params)
    assert [p.name for p in result.profile.points] == names
    assert result.skipped == ("soc: no Modbus register (source 'const')",)
    power = result.profile.point("power")
    assert (power.table, power.address, power.type, power.unit) == (
        Table.INPUT_REGISTERS,
        0x34,
        PointType.F32,
        "W",
    )
    assert power.scale == (-1.0 if params["usage"] == "pv" else None)
    if "voltage_l1" in names:
        voltage = result.profile.point("voltage_l1")
        assert (voltage.type, voltage.layout, voltage.scale) == (PointType.I32, Layout.CDAB, 0.01)
    assert (result.profile.device.manufacturer, result.profile.device.model) == ("ACME", "EM-3")


def test_the_template_defaults_are_the_first_choice_and_the_default() -> None:
    names = [p.name for p in profile_from_evcc(evcc_example(), yaml.safe_load).profile.points]
    assert "voltage_l1" in names  # usage grid
    assert "current_l1" in names  # phases true


@pytest.mark.parametrize(
    ("render", "expected"),
    [
        ('{{ if eq .usage "grid" }}a', "render: {{ if }} without {{ end }}"),
        ("a{{ end }}", "render: {{ end }} without {{ if }}"),
        ('{{ printf "%d" 3 }}', "render: cannot evaluate the action {{ printf"),
        ("{{ if gt .x 3 }}a{{ end }}", "render: cannot evaluate the condition {{ if gt .x 3 }}"),
    ],
)
def test_template_actions_it_cannot_evaluate_are_named(render: str, expected: str) -> None:
    with pytest.raises(ConfigError) as caught:
        render_evcc(render, {"usage": "grid"}, "t.yaml")
    assert f"t.yaml: {expected}" in str(caught.value)


def test_trim_markers_and_nested_branches() -> None:
    text = (
        'a\n  {{- if eq .u "x" }}\nb{{ if .f }}c{{ else }}d{{ end }}\n'
        '{{- else if ne .u "y" }}\ne\n{{- else }}\nf\n{{- end }}\ng'
    )
    assert render_evcc(text, {"u": "x", "f": "true"}) == "a\nbc\ng"
    assert render_evcc(text, {"u": "x", "f": "false"}) == "a\nbd\ng"
    assert render_evcc(text, {"u": "z"}) == "a\ne\ng"
    assert render_evcc(text, {"u": "y"}) == "a\nf\ng"


@pytest.mark.parametrize(
    ("register", "expected"),
    [
        ({"address": 1, "type": "input", "decode": "float16"}, "power.register.decode: unknown"),
        ({"address": -1}, "power.register.address: must be 0..65535"),
        ({"address": 1, "type": "analog"}, "power.register.type: must be one of"),
    ],
)
def test_bad_registers_are_named(register: dict[str, Any], expected: str) -> None:
    template = {
        "template": "t",
        "render": yaml.safe_dump(
            {"type": "custom", "power": {"source": "modbus", "register": register}}
        ),
    }
    with pytest.raises(ConfigError) as caught:
        profile_from_evcc(template, yaml.safe_load, source="t.yaml")
    assert f"t.yaml: {expected}" in str(caught.value)


def test_a_template_of_evccs_built_in_models_has_no_register_map() -> None:
    template = {"template": "t", "render": "type: mbmd\nmodel: sdm\npower: Power\n"}
    with pytest.raises(ConfigError, match=r"t.yaml: render: renders no register map \(a 'mbmd'"):
        profile_from_evcc(template, yaml.safe_load, source="t.yaml")


@pytest.mark.parametrize(
    ("decode", "kind", "size", "missing"),
    [
        ("int16", PointType.I16, 1, -0x8000),
        ("uint16", PointType.U16, 1, 0xFFFF),
        ("int32", PointType.I32, 2, -0x80000000),
        ("uint32", PointType.U32, 2, 0xFFFFFFFF),
        ("int64", PointType.I64, 4, -0x8000000000000000),
        ("uint64", PointType.U64, 4, 0xFFFFFFFFFFFFFFFF),
        ("float32", PointType.F32, 2, None),
        ("float64", PointType.F64, 4, None),
    ],
)
def test_every_evcc_decode_and_its_not_available_value(
    decode: str, kind: PointType, size: int, missing: int | None
) -> None:
    """evcc's `...nan` decodes mark a value as missing: the type's lowest value when signed,
    its highest when unsigned; an `s` swaps the words."""
    for suffix, layout, not_available in [
        ("", Layout.ABCD, None),
        ("s", Layout.CDAB, None),
        ("nan", Layout.ABCD, missing),
        ("snan", Layout.CDAB, missing),
    ]:
        register = {"address": 7, "type": "input", "decode": decode + suffix}
        template = {
            "template": "t",
            "render": yaml.safe_dump(
                {"type": "custom", "power": {"source": "modbus", "register": register}}
            ),
        }
        point = profile_from_evcc(template, yaml.safe_load).profile.point("power")
        assert (point.type, point.size, point.layout, point.not_available) == (
            kind,
            size,
            layout,
            not_available,
        ), decode + suffix

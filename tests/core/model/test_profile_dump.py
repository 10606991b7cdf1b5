"""Profiles written back as TOML load as the same profile, and satisfy the schema."""

from __future__ import annotations

import json
import tomllib
from pathlib import Path

import jsonschema
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from aiortu.core.model import (
    SCHEMA_PATH,
    Access,
    DeviceInfo,
    Layout,
    PointType,
    Profile,
    ProfilePoint,
    Table,
    dump_profile,
    load_profile,
    parse_profile,
)

ROOT = Path(__file__).parents[3]
FILES = sorted((ROOT / "src/aiortu/core/model/profiles").glob("*.toml"))
FILES += sorted((ROOT / "examples/profiles").glob("*.toml"))
VALIDATOR = jsonschema.Draft202012Validator(json.loads(SCHEMA_PATH.read_text()))


@pytest.mark.parametrize("path", FILES, ids=lambda p: p.name)
def test_a_dumped_profile_loads_as_itself(path: Path) -> None:
    profile = load_profile(path)
    text = dump_profile(profile, "written back")
    assert text.startswith("# written back\n")
    VALIDATOR.validate(tomllib.loads(text))
    assert parse_profile(text, profile.source) == profile


NAMES = st.from_regex(r"[A-Za-z_][A-Za-z0-9_.-]{0,8}", fullmatch=True)
TEXT = st.text(st.characters(blacklist_categories=("Cs",)), max_size=12)


@st.composite
def points(draw: st.DrawFn) -> list[ProfilePoint]:
    made, address = [], 0
    for name in draw(st.lists(NAMES, min_size=1, max_size=8, unique=True)):
        kind = draw(st.sampled_from([PointType.U16, PointType.I32, PointType.F32, PointType.ENUM]))
        size = 2 if kind in (PointType.I32, PointType.F32) else 1
        values = {0: "off", 1: draw(TEXT.filter(bool))} if kind is PointType.ENUM else {}
        made.append(
            ProfilePoint(
                name,
                Table.HOLDING_REGISTERS,
                address,
                kind,
                size,
                layout=draw(st.sampled_from(list(Layout))),
                scale=draw(st.none() | st.floats(0.001, 1000)) if kind.is_number else None,
                unit=draw(TEXT),
                description=draw(TEXT),
                access=draw(st.sampled_from(list(Access))),
                values=values,
                meta={"note": draw(TEXT)},
            )
        )
        address += size + draw(st.integers(0, 5))
    return made


@settings(max_examples=100, deadline=None)
@given(made=points(), model=TEXT.filter(bool))
def test_any_profile_round_trips(made: list[ProfilePoint], model: str) -> None:
    profile = Profile("p.toml", DeviceInfo("ACME", model), tuple(made))
    assert parse_profile(dump_profile(profile), "p.toml") == profile

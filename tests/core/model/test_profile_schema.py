"""The published JSON Schema: valid JSON Schema, satisfied by every shipped profile and the
examples, and refusing what the loader refuses where a schema can say it."""

from __future__ import annotations

import json
import tomllib
from pathlib import Path

import jsonschema
import pytest

from aiortu.core.model import SCHEMA_PATH, parse_profile
from aiortu.errors import ConfigError

ROOT = Path(__file__).parents[3]
PROFILES = sorted((ROOT / "src/aiortu/core/model/profiles").glob("*.toml"))
PROFILES += sorted((ROOT / "examples/profiles").glob("*.toml"))
SCHEMA = json.loads(SCHEMA_PATH.read_text(encoding="utf-8"))
VALIDATOR = jsonschema.Draft202012Validator(SCHEMA)


def test_the_schema_is_a_valid_schema() -> None:
    jsonschema.Draft202012Validator.check_schema(SCHEMA)


@pytest.mark.parametrize("path", PROFILES, ids=lambda p: p.name)
def test_every_shipped_profile_satisfies_the_schema_and_the_loader(path: Path) -> None:
    text = path.read_text(encoding="utf-8")
    VALIDATOR.validate(tomllib.loads(text))
    parse_profile(text, path.name)


HEAD = '[device]\nmanufacturer = "A"\nmodel = "B"\n'


@pytest.mark.parametrize(
    "body",
    [
        '[[point]]\nname = "a"\naddress = 0\ntype = "f33"',
        '[[point]]\nname = "a"\naddress = 70000',
        '[[point]]\nname = "a"\naddress = 0\ncolour = "red"',
        '[[point]]\nname = "a"\naddress = 0\naccess = "w"',
        '[[point]]\nname = "9a"\naddress = 0',
        '[[point]]\nname = "a"',
        '[defaults]\nmax_block = 126\n[[point]]\nname = "a"\naddress = 0',
        '[defaults]\nbase = 2\n[[point]]\nname = "a"\naddress = 0',
        '[poll]\nfast = 0\n[[point]]\nname = "a"\naddress = 0',
        '[[point]]\nname = "a"\naddress = 0\nvalues = { x = "on" }',
        '[device.identify.objects]\ncolour = "red"\n[[point]]\nname = "a"\naddress = 0',
    ],
)
def test_what_the_schema_refuses_the_loader_refuses(body: str) -> None:
    text = HEAD + body
    assert not VALIDATOR.is_valid(tomllib.loads(text))
    with pytest.raises(ConfigError):
        parse_profile(text, "bad.toml")

"""The format reference of `docs/profile-reference.md`, written from the profile's JSON Schema,
so the page and the schema editors check against cannot drift apart."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

__all__ = ("SCHEMA_PATH", "schema_reference")

SCHEMA_PATH = Path(__file__).with_name("profile.schema.json")
"""The JSON Schema of the profile format, shipped with the package."""

# The sections of a profile, in the order the page shows them: (heading, TOML, schema path).
_SECTIONS = (
    ("The file", "top level", ()),
    ("Device", "[device]", ("$defs", "device")),
    ("Identification", "[device.identify]", ("$defs", "identify")),
    ("Probes", "[[device.identify.probe]]", ("$defs", "probe")),
    ("Defaults", "[defaults]", ("$defs", "defaults")),
    ("Holes", "[[hole]]", ("$defs", "hole")),
    ("Points", "[[point]]", ("$defs", "point")),
)


def _type_of(spec: dict[str, Any], schema: dict[str, Any]) -> str:
    if "$ref" in spec:
        name = spec["$ref"].rsplit("/", 1)[-1]
        target = schema["$defs"][name]
        if "enum" in target:
            return " \\| ".join(f"`{v}`" for v in target["enum"])
        return f"{name}" if "properties" in target else _type_of(target, schema)
    if "enum" in spec:
        return " \\| ".join(f"`{json.dumps(v)}`" for v in spec["enum"])
    kind = spec.get("type", "any")
    kinds = kind if isinstance(kind, list) else [kind]
    shown = " or ".join(kinds)
    low, high = spec.get("minimum"), spec.get("maximum")
    if low is not None or high is not None:
        shown += f" ({'' if low is None else low}..{'' if high is None else high})"
    if "exclusiveMinimum" in spec:
        shown += f" (> {spec['exclusiveMinimum']})"
    return shown


def _section(heading: str, toml: str, node: dict[str, Any], schema: dict[str, Any]) -> list[str]:
    required = set(node.get("required", ()))
    lines = [f"## {heading}", "", f"`{toml}`: {node['description']}", ""]
    lines += ["| key | type | required | meaning |", "|---|---|---|---|"]
    for key, spec in node["properties"].items():
        description = spec.get("description") or schema["$defs"].get(
            spec.get("$ref", "#").rsplit("/", 1)[-1], {}
        ).get("description", "")
        mark = "yes" if key in required else ""
        lines.append(f"| `{key}` | {_type_of(spec, schema)} | {mark} | {description} |")
    return [*lines, ""]


def schema_reference(schema_path: Path = SCHEMA_PATH) -> str:
    """The Markdown format reference of the profile schema at `schema_path`."""
    schema = json.loads(schema_path.read_text(encoding="utf-8"))
    lines = [
        "# Profile format reference",
        "",
        "<!-- Written by `aiortu profile reference` from the package's profile.schema.json;",
        "     a test checks that this page is what it writes. -->",
        "",
        "The schema itself ships in the package as `aiortu/core/model/profile.schema.json`;",
        "point an editor at it (Taplo and Even Better TOML read a first line `#:schema PATH`).",
        "",
    ]
    for heading, toml, path in _SECTIONS:
        node = schema
        for part in path:
            node = node[part]
        lines += _section(heading, toml, node, schema)
    return "\n".join(lines).rstrip() + "\n"

"""An evcc meter template as a profile: the Modbus register map of its `render`.

evcc describes meters as templates: parameters (`usage`, ...) and a `render` text, a Go
template that becomes the meter's configuration. A template with a register map renders, for
each value evcc reads (`power`, `energy`, `currents`, ...), a `source: modbus` plugin with a
`register` (address, type, decode) and a `scale`. The converter renders the template for the
parameters given (the `if`/`else`/`end` actions on parameters, `include` dropped), parses the
result with the YAML parser it is handed (this module needs none), and makes one point per
register. Values without a register (evcc's built-in meter models, constants) are listed as
skipped, not guessed at; anything else it cannot read is an error naming the file and the key.
"""

from __future__ import annotations

import re
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from typing import Any

from aiortu.core.errors import ConfigError
from aiortu.core.model._addressing import Table
from aiortu.core.model._import_ha import checked
from aiortu.core.model._profile import (
    FIXED_WIDTHS,
    DeviceInfo,
    PointType,
    Profile,
    ProfilePoint,
)
from aiortu.core.model._values import Layout

__all__ = ("EvccImport", "profile_from_evcc", "render_evcc")

# Each decode's type, and its not-available value (`...nan`).
_DECODES: dict[str, tuple[PointType, int | None]] = {
    "int16": (PointType.I16, -0x8000),
    "uint16": (PointType.U16, 0xFFFF),
    "int32": (PointType.I32, -0x80000000),
    "uint32": (PointType.U32, 0xFFFFFFFF),
    "int64": (PointType.I64, -0x8000000000000000),
    "uint64": (PointType.U64, 0xFFFFFFFFFFFFFFFF),
    "float32": (PointType.F32, None),
    "float64": (PointType.F64, None),
}
_TABLES = {
    "holding": Table.HOLDING_REGISTERS,
    "input": Table.INPUT_REGISTERS,
    "coil": Table.COILS,
    "discrete": Table.DISCRETE_INPUTS,
}
_UNITS = {
    "power": "W",
    "powers": "W",
    "energy": "kWh",
    "returnenergy": "kWh",
    "currents": "A",
    "voltages": "V",
    "soc": "%",
}
_ACTION = re.compile(r"\{\{(-?)\s*(.*?)\s*(-?)\}\}", re.S)
_COMPARE = re.compile(r'(eq|ne)\s+\.(\w+)\s+"([^"]*)"')


@dataclass(frozen=True, slots=True)
class EvccImport:
    """What a template gave: the `profile`, and the values `skipped` (no register map), each
    with why."""

    profile: Profile
    skipped: tuple[str, ...]


def _condition(text: str, params: Mapping[str, str], fail: Callable[[str], ConfigError]) -> bool:
    text = text.strip()
    if text.startswith(("or ", "and ")):
        parts = re.findall(r"\(([^()]*)\)", text)
        results = [_condition(p, params, fail) for p in parts]
        return any(results) if text.startswith("or ") else all(results)
    if text.startswith("not "):
        return not _condition(text[4:].strip("() "), params, fail)
    compare = _COMPARE.fullmatch(text)
    if compare:
        op, name, value = compare.groups()
        return (params.get(name, "") == value) == (op == "eq")
    if re.fullmatch(r"\.\w+", text):
        return params.get(text[1:], "") not in ("", "false", "0")
    raise fail(f"cannot evaluate the condition {{{{ if {text} }}}}")


def render_evcc(render: str, params: Mapping[str, str], source: str = "template") -> str:
    """`render` with its actions evaluated for `params`: `if`/`else if`/`else`/`end` on
    parameters, `include` dropped, `.name` replaced by the parameter's value."""

    def fail(problem: str) -> ConfigError:
        return ConfigError(source, "render", problem)

    out: list[str] = []
    stack: list[tuple[bool, bool]] = []  # (this branch is on, an earlier branch was taken)
    position = 0
    on = True
    for match in _ACTION.finditer(render):
        text = render[position : match.start()]
        if match.group(1):
            text = text.rstrip(" \t\n")
        if on:
            out.append(text)
        position = match.end()
        if match.group(3):
            while position < len(render) and render[position] in " \t\n":
                position += 1
        action = match.group(2)
        word = action.split(" ", 1)[0]
        if word == "if":
            stack.append((on, False))
            taken = on and _condition(action[3:], params, fail)
            stack[-1] = (stack[-1][0], taken)
            on = taken
        elif word == "else":
            if not stack:
                raise fail("{{ else }} without {{ if }}")
            outer, taken = stack[-1]
            rest = action[4:].strip()
            now = (
                outer
                and not taken
                and (not rest.startswith("if ") or _condition(rest[3:], params, fail))
            )
            stack[-1] = (outer, taken or now)
            on = now
        elif word == "end":
            if not stack:
                raise fail("{{ end }} without {{ if }}")
            on, _ = stack.pop()
        elif word == "include" or action.startswith("/*"):
            pass
        elif re.fullmatch(r"\.\w+", action):
            if on:
                out.append(params.get(action[1:], ""))
        else:
            raise fail(f"cannot evaluate the action {{{{ {action} }}}}")
    if stack:
        raise fail("{{ if }} without {{ end }}")
    out.append(render[position:])
    return "".join(out)


def _defaults(template: Mapping[str, Any]) -> dict[str, str]:
    params: dict[str, str] = {}
    for param in template.get("params", ()):
        if not isinstance(param, Mapping) or "name" not in param:
            continue
        choices = param.get("choice") or param.get("choices") or []
        default = param.get("default", choices[0] if choices else "")
        params[str(param["name"])] = (
            str(default).lower() if isinstance(default, bool) else str(default)
        )
    return params


def _point(name: str, key: str, plugin: Mapping[str, Any], source: str) -> ProfilePoint:
    register = plugin["register"]
    if not isinstance(register, Mapping):
        raise ConfigError(source, f"{key}.register", "must be a mapping")
    address = register.get("address")
    if isinstance(address, bool) or not isinstance(address, int) or not 0 <= address <= 0xFFFF:
        raise ConfigError(source, f"{key}.register.address", f"must be 0..65535, not {address!r}")
    table = _TABLES.get(str(register.get("type", "holding")))
    if table is None:
        raise ConfigError(source, f"{key}.register.type", f"must be one of {', '.join(_TABLES)}")
    decode = str(register.get("decode", "int16" if not table.is_bit else "bool"))
    scale = plugin.get("scale")
    if scale is not None and (isinstance(scale, bool) or not isinstance(scale, int | float)):
        raise ConfigError(source, f"{key}.scale", f"must be a number, not {scale!r}")
    meta = {"evcc": key}
    if table.is_bit:
        return ProfilePoint(name, table, address, PointType.BOOL, 1, meta=meta)
    base = decode.removesuffix("nan").removesuffix("s")
    if base not in _DECODES:
        raise ConfigError(source, f"{key}.register.decode", f"unknown decode {decode!r}")
    kind, missing = _DECODES[base]
    swapped = decode.removesuffix("nan").endswith("s")
    return ProfilePoint(
        name,
        table,
        address,
        kind,
        FIXED_WIDTHS[kind],
        layout=Layout.CDAB if swapped else Layout.ABCD,
        scale=None if scale is None else float(scale),
        not_available=missing if decode.endswith("nan") else None,
        unit=_UNITS.get(key.partition("[")[0], ""),
        meta=meta,
    )


def profile_from_evcc(
    template: Mapping[str, Any],
    parse_yaml: Callable[[str], object],
    *,
    params: Mapping[str, str] | None = None,
    source: str = "template.yaml",
) -> EvccImport:
    """The profile of an evcc meter `template` (the parsed YAML), rendered for `params` (the
    template's defaults otherwise, the first choice of each); `parse_yaml` parses the
    rendered text (`yaml.safe_load`)."""
    render = template.get("render")
    if not isinstance(render, str):
        raise ConfigError(source, "render", "missing: not an evcc template")
    values = _defaults(template) | dict(params or {})
    rendered = parse_yaml(render_evcc(render, values, source))
    if not isinstance(rendered, Mapping):
        raise ConfigError(source, "render", "does not render to a mapping")
    points: list[ProfilePoint] = []
    skipped: list[str] = []
    for key, plugin in rendered.items():
        items = plugin if isinstance(plugin, list) else [plugin]
        for index, item in enumerate(items):
            where = f"{key}[{index}]" if isinstance(plugin, list) else str(key)
            name = (
                f"{str(key).removesuffix('s')}_l{index + 1}"
                if isinstance(plugin, list)
                else str(key)
            )
            if not isinstance(item, Mapping):
                if key not in ("type", "model", "uri", "id", "device", "comset", "baudrate"):
                    skipped.append(f"{where}: {item!r} is not a register (evcc's built-in model)")
                continue
            if item.get("source") != "modbus" or "register" not in item:
                skipped.append(f"{where}: no Modbus register (source {item.get('source')!r})")
                continue
            points.append(_point(name, where, item, source))
    if not points:
        kind = rendered.get("type", "?")
        raise ConfigError(source, "render", f"renders no register map (a {kind!r} meter)")
    product = (template.get("products") or [{}])[0]
    brand = str(product.get("brand", "evcc")) if isinstance(product, Mapping) else "evcc"
    description = product.get("description", {}) if isinstance(product, Mapping) else {}
    model = str(description.get("generic", template.get("template", "meter")))
    usage = values.get("usage", "")
    device = DeviceInfo(
        brand,
        model,
        f"imported from the evcc template {template.get('template', source)}"
        + (f" (usage {usage})" if usage else ""),
    )
    profile = checked(Profile(source, device, tuple(points)))
    return EvccImport(profile, tuple(skipped))

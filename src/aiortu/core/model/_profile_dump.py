"""A profile written back as TOML, in the format [`load_profile`][aiortu.core.model.load_profile]
reads: what the imports and the SunSpec walk produce, for a user to keep and edit.

Only what differs from the defaults is written, so a loaded and dumped profile reads as a
hand-written one; loading the text gives an equal profile back (a test holds it).
"""

from __future__ import annotations

import json
import math
import re
from collections.abc import Iterable, Mapping

from aiortu.core.model._profile import (
    DEFAULT_POLL_CLASS,
    Access,
    PlanLimits,
    PointType,
    Profile,
    ProfilePoint,
)
from aiortu.core.model._values import Layout

__all__ = ("dump_profile",)

_BARE_KEY = re.compile(r"[A-Za-z0-9_-]+")


def _key(name: str) -> str:
    return name if _BARE_KEY.fullmatch(name) else _value(name)


def _value(value: object) -> str:
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, int):
        return str(value)
    if isinstance(value, float):
        if math.isnan(value):
            return "nan"
        if math.isinf(value):
            return "inf" if value > 0 else "-inf"
        return repr(value)
    if isinstance(value, str):
        # JSON's escapes are TOML's; TOML also forbids a raw DEL, which JSON leaves as it is.
        return json.dumps(value, ensure_ascii=False).replace("\x7f", "\\u007f")
    if isinstance(value, list | tuple):
        return "[" + ", ".join(_value(v) for v in value) + "]"
    if isinstance(value, Mapping):
        items = ", ".join(f"{_key(str(k))} = {_value(v)}" for k, v in value.items())
        return "{ " + items + " }" if items else "{}"
    raise TypeError(f"no TOML for {type(value).__name__}")


def _lines(pairs: Iterable[tuple[str, object]]) -> list[str]:
    return [f"{_key(k)} = {_value(v)}" for k, v in pairs if v is not None]


def _point(point: ProfilePoint) -> list[str]:
    kind = point.type
    sized = kind is PointType.STRING or (
        kind in (PointType.BITFIELD, PointType.ENUM) and point.size > 1
    )
    text = kind is PointType.STRING
    pairs: list[tuple[str, object]] = [
        ("name", point.name),
        ("table", point.table.value),
        ("address", point.address),
        ("type", kind.value),
        ("size", point.size if sized else None),
        ("layout", None if point.layout is Layout.ABCD else point.layout.value),
        ("encoding", point.encoding if text and point.encoding != "ascii" else None),
        ("scale", point.scale),
        ("offset", point.offset),
        ("scale_factor", point.scale_factor),
        ("not_available", point.not_available),
        ("unit", point.unit or None),
        ("description", point.description or None),
        ("access", "rw" if point.access is Access.RW else None),
        ("min", point.minimum),
        ("max", point.maximum),
        ("poll", None if point.poll == DEFAULT_POLL_CLASS else point.poll),
        ("values", {str(k): v for k, v in point.values.items()} or None),
        ("bits", {str(k): v for k, v in point.bits.items()} or None),
        ("value", list(point.initial) if isinstance(point.initial, tuple) else point.initial),
        ("meta", dict(point.meta) or None),
    ]
    if point.table.is_bit:
        pairs = [(k, v) for k, v in pairs if k != "type"]
    return ["[[point]]", *_lines(pairs)]


def dump_profile(profile: Profile, comment: str = "") -> str:
    """`profile` as TOML text; `comment` (lines) goes first, as `#` comments."""
    lines = [f"# {line}".rstrip() for line in comment.splitlines()]
    device = profile.device
    lines += ["", "[device]"] if lines else ["[device]"]
    lines += _lines(
        [
            ("manufacturer", device.manufacturer),
            ("model", device.model),
            ("description", device.description or None),
            ("url", device.url or None),
        ]
    )
    identify = device.identify
    if not identify.empty:
        lines += ["", "[device.identify]"]
        if identify.objects:
            lines += _lines([("objects", dict(identify.objects))])
        if identify.probes:
            probes = [{"point": p.point, "equals": list(p.equals)} for p in identify.probes]
            lines += _lines([("probe", probes)])
    limits = profile.limits
    defaults = PlanLimits()
    changed = [
        (name, getattr(limits, name))
        for name in ("max_block", "max_gap", "max_bit_block", "max_bit_gap")
        if getattr(limits, name) != getattr(defaults, name)
    ]
    if changed:
        lines += ["", "[defaults]", *_lines(changed)]
    classes = {k: v for k, v in profile.poll_classes.items() if (k, v) != (DEFAULT_POLL_CLASS, 1.0)}
    if classes:
        lines += ["", "[poll]", *_lines(classes.items())]
    for hole in profile.holes:
        lines += [
            "",
            "[[hole]]",
            *_lines([("table", hole.table.value), ("start", hole.start), ("count", hole.count)]),
        ]
    for point in profile.points:
        lines += ["", *_point(point)]
    return "\n".join(lines) + "\n"

"""Reading a profile from TOML: every key checked, every error naming the file, the line, the
point and the key.

The checks follow `profile.schema.json` (shipped beside this module, for editors) and add the
ones a schema cannot say: addresses inside the address space, points that overlap each other or
a hole, a scale factor that names no integer point, limits a type cannot hold.
"""

from __future__ import annotations

import itertools
import re
import tomllib
from collections.abc import Mapping
from dataclasses import replace
from pathlib import Path
from typing import Any

from aiortu.core.errors import ConfigError, InvalidValue
from aiortu.core.model._addressing import Table
from aiortu.core.model._point_codec import check_value, encode_point
from aiortu.core.model._profile import (
    DEFAULT_POLL_CLASS,
    FIXED_WIDTHS,
    Access,
    DeviceInfo,
    Hole,
    Identification,
    PlanLimits,
    PointType,
    Probe,
    Profile,
    ProfilePoint,
)
from aiortu.core.model._toml_reader import TomlReader
from aiortu.core.model._values import Layout

__all__ = ("find_profile", "load_profile", "parse_profile", "shipped_profiles")

_TOP = frozenset({"device", "defaults", "poll", "hole", "point"})
_DEVICE = frozenset({"manufacturer", "model", "description", "url", "identify"})
_IDENTIFY = frozenset({"objects", "probe"})
_OBJECTS = frozenset(
    {
        "vendor_name",
        "product_code",
        "revision",
        "vendor_url",
        "product_name",
        "model_name",
        "user_application_name",
    }
)
_DEFAULTS = frozenset(
    {"table", "layout", "base", "max_block", "max_gap", "max_bit_block", "max_bit_gap", "poll"}
)
_POINT = frozenset(
    {
        "name",
        "table",
        "address",
        "type",
        "size",
        "layout",
        "encoding",
        "scale",
        "offset",
        "scale_factor",
        "not_available",
        "unit",
        "description",
        "access",
        "min",
        "max",
        "poll",
        "values",
        "bits",
        "value",
        "meta",
    }
)
_ALIASES = {
    "uint16": "u16",
    "int16": "i16",
    "uint32": "u32",
    "int32": "i32",
    "uint64": "u64",
    "int64": "i64",
    "float32": "f32",
    "float64": "f64",
}
_NAME = re.compile(r"[A-Za-z_][A-Za-z0-9_.-]*")
_ADDRESSES = 0x10000
_SHIPPED = Path(__file__).parent / "profiles"


def shipped_profiles() -> dict[str, Path]:
    """The profiles aiortu ships, by name (the file name without `.toml`), in name order."""
    return {path.stem: path for path in sorted(_SHIPPED.glob("*.toml"))}


def find_profile(name: str, base: Path | None = None) -> str | Path | None:
    """The file of profile `name`: the file `name` (relative to `base`) where there is one,
    as named, else the shipped profile of that name (see `shipped_profiles`); None when
    neither."""
    path = Path(name) if base is None else base / name
    if path.exists():
        return name if base is None else path
    return shipped_profiles().get(name)


def load_profile(path: str | Path) -> Profile:
    """The profile in the TOML file at `path`.

    Raises [`ConfigError`][aiortu.errors.ConfigError] (`FILE:LINE: KEY: PROBLEM`) for
    anything wrong in it, or a file that cannot be read.
    """
    return parse_profile(TomlReader.read(path), str(path))


def parse_profile(text: str, source: str = "<string>") -> Profile:
    """The profile in TOML `text`; `source` names it in messages (see
    [`load_profile`][aiortu.core.model.load_profile])."""
    try:
        document = tomllib.loads(text)
    except tomllib.TOMLDecodeError as error:
        raise ConfigError(source, "(syntax)", str(error)) from None
    return _Loader(source, text).profile(document)


def _span(table: Table, start: int, stop: int) -> str:
    return f"{table} {start}..{stop - 1}"


_kind = TomlReader.kind


class _Loader(TomlReader):
    """Walks the parsed TOML; each error names the file, the line and the key path."""

    def __init__(self, source: str, text: str) -> None:
        super().__init__(source)
        self.lines = text.splitlines()  # `where` is the line of the entry being read, when found

    # -- errors and plain values ----------------------------------------------------

    def line_of(self, header: str, name: str | None) -> str:
        """`:LINE` of the `name = "..."` of an entry (or of its first `[[header]]`)."""
        pattern = (
            rf'^\s*name\s*=\s*["\']{re.escape(name)}["\']' if name else rf"^\s*\[\[{header}\]\]"
        )
        for number, line in enumerate(self.lines, 1):
            if re.match(pattern, line):
                return f":{number}"
        return ""

    def text(self, found: Mapping[str, object], name: str, key: str, default: str | None) -> str:
        value = found.get(name, default)
        if value is None:
            raise self.fail(f"{key}.{name}", "missing")
        if not isinstance(value, str) or (default is None and not value):
            raise self.fail(f"{key}.{name}", f"must be a non-empty string, not {_kind(value)}")
        return value

    def name(self, value: object, key: str) -> str:
        if not isinstance(value, str) or not _NAME.fullmatch(value):
            shown = repr(value) if isinstance(value, str) else _kind(value)
            raise self.fail(
                key, f"must be a name (a letter or _, then letters, digits, _ - .), not {shown}"
            )
        return value

    def integer(self, value: object, key: str, allowed: range) -> int:
        if not isinstance(value, int) or isinstance(value, bool):
            raise self.fail(key, f"must be an integer, not {_kind(value)}")
        if value not in allowed:
            raise self.fail(key, f"must be {allowed.start}..{allowed.stop - 1}, not {value}")
        return value

    def limit(self, defaults: dict[str, Any], name: str, default: int, allowed: range) -> int:
        return self.integer(defaults.get(name, default), f"defaults.{name}", allowed)

    def number(self, value: object, key: str) -> float:
        if not isinstance(value, int | float) or isinstance(value, bool):
            raise self.fail(key, f"must be a number, not {_kind(value)}")
        return float(value)

    def choice(self, value: object, key: str, choices: tuple[str, ...]) -> str:
        if value not in choices:
            shown = repr(value) if isinstance(value, str) else _kind(value)
            raise self.fail(key, f"must be one of {', '.join(choices)}, not {shown}")
        return str(value)

    # -- the document ---------------------------------------------------------------

    def profile(self, document: dict[str, Any]) -> Profile:
        self.known(document, _TOP, "")
        device = self.device(
            self.table(document.get("device"), "device")
            if "device" in document
            else self.missing("device")
        )
        defaults = self.table(document.get("defaults", {}), "defaults")
        self.known(defaults, _DEFAULTS, "defaults")
        table = Table(
            self.choice(defaults.get("table", "holding_registers"), "defaults.table", tuple(Table))
        )
        layout = Layout(
            self.choice(defaults.get("layout", "ABCD"), "defaults.layout", tuple(Layout))
        )
        base = self.integer(defaults.get("base", 0), "defaults.base", range(2))
        limits = PlanLimits(
            self.limit(defaults, "max_block", 125, range(1, 126)),
            self.limit(defaults, "max_gap", 10, range(_ADDRESSES)),
            self.limit(defaults, "max_bit_block", 2000, range(1, 2001)),
            self.limit(defaults, "max_bit_gap", 160, range(_ADDRESSES)),
        )
        classes = self.poll_classes(document.get("poll", {}))
        poll = self.name(defaults.get("poll", DEFAULT_POLL_CLASS), "defaults.poll")
        if poll not in classes:
            raise self.fail(
                "defaults.poll", f"unknown poll class {poll!r} (known: {', '.join(classes)})"
            )
        if "point" not in document:
            self.missing("point")
        context = _Context(table, layout, base, poll, classes)
        points = [
            self.point(entry, i, context)
            for i, entry in enumerate(self.tables(document["point"], "point"))
        ]
        self.where = ""
        if not points:
            raise self.fail("point", "must have at least one [[point]]")
        holes = [
            self.hole(entry, i, table, base)
            for i, entry in enumerate(self.tables(document.get("hole", []), "hole"))
        ]
        self.check_points(points, holes)
        self.check_widths(points, limits)
        self.check_probes(device, {p.name: p for p in points})
        return Profile(self.source, device, tuple(points), tuple(holes), classes, limits)

    def missing(self, key: str) -> dict[str, Any]:
        raise self.fail(key, "missing")

    def device(self, entry: dict[str, Any]) -> DeviceInfo:
        self.known(entry, _DEVICE, "device")
        identify = self.table(entry.get("identify", {}), "device.identify")
        self.known(identify, _IDENTIFY, "device.identify")
        objects = self.table(identify.get("objects", {}), "device.identify.objects")
        self.known(objects, _OBJECTS, "device.identify.objects")
        for name in objects:
            self.text(objects, name, "device.identify.objects", None)
        probes = []
        for i, probe in enumerate(self.tables(identify.get("probe", []), "device.identify.probe")):
            key = f"device.identify.probe[{i}]"
            self.known(probe, frozenset({"point", "equals"}), key)
            equals = probe.get("equals")
            if (
                not isinstance(equals, list)
                or not equals
                or not all(isinstance(v, int | str | bool) for v in equals)
            ):
                raise self.fail(
                    f"{key}.equals", "must be a non-empty array of integers, strings or booleans"
                )
            probes.append(Probe(self.name(probe.get("point"), f"{key}.point"), tuple(equals)))
        return DeviceInfo(
            self.text(entry, "manufacturer", "device", None),
            self.text(entry, "model", "device", None),
            self.text(entry, "description", "device", ""),
            self.text(entry, "url", "device", ""),
            Identification(dict(objects), tuple(probes)),
        )

    def poll_classes(self, value: object) -> dict[str, float]:
        classes = {DEFAULT_POLL_CLASS: 1.0}
        for name, interval in self.table(value, "poll").items():
            self.name(name, f"poll.{name}")
            seconds = self.number(interval, f"poll.{name}")
            if not seconds > 0:
                raise self.fail(f"poll.{name}", f"must be seconds > 0, not {interval}")
            classes[name] = seconds
        return classes

    def hole(self, entry: dict[str, Any], index: int, table: Table, base: int) -> Hole:
        key = f"hole[{index}]"
        self.where = self.line_of("hole", None) if index == 0 else ""
        self.known(entry, frozenset({"table", "start", "count"}), key)
        hole_table = Table(self.choice(entry.get("table", table), f"{key}.table", tuple(Table)))
        start = (
            self.integer(entry.get("start"), f"{key}.start", range(base, _ADDRESSES + base)) - base
        )
        count = self.integer(entry.get("count"), f"{key}.count", range(1, _ADDRESSES - start + 1))
        return Hole(hole_table, start, count)

    def point(self, entry: dict[str, Any], index: int, context: _Context) -> ProfilePoint:
        raw_name = entry.get("name")
        self.where = self.line_of("point", raw_name if isinstance(raw_name, str) else None)
        name = self.name(raw_name, f"point[{index}].name")
        key = f"point {name}"
        self.known(entry, _POINT, key)
        return _PointReader(self, entry, key, context).point(name)

    def check_points(self, points: list[ProfilePoint], holes: list[Hole]) -> None:
        seen: dict[str, ProfilePoint] = {}
        for point in points:
            if point.name in seen:
                self.where = ""
                raise self.fail(f"point {point.name}.name", "used by two points")
            seen[point.name] = point
        for point in points:
            self.where = self.line_of("point", point.name)
            if point.scale_factor is not None:
                factor = seen.get(point.scale_factor)
                if factor is None:
                    raise self.fail(
                        f"point {point.name}.scale_factor", f"no point named {point.scale_factor!r}"
                    )
                if not factor.type.is_integer or factor.table.is_bit:
                    raise self.fail(
                        f"point {point.name}.scale_factor",
                        f"{factor.name} must be an integer register point, not {factor.type}",
                    )
        by_table = sorted(points, key=lambda p: (p.table, p.address))
        for before, after in itertools.pairwise(by_table):
            if before.table is after.table and after.address < before.stop:
                self.where = self.line_of("point", after.name)
                raise self.fail(
                    f"point {after.name}.address",
                    f"overlaps {before.name} ({_span(before.table, before.address, before.stop)})",
                )
        for hole in holes:
            for point in points:
                if (
                    point.table is hole.table
                    and point.address < hole.stop
                    and hole.start < point.stop
                ):
                    self.where = self.line_of("point", point.name)
                    raise self.fail(
                        f"point {point.name}.address",
                        f"lies in a hole ({_span(hole.table, hole.start, hole.stop)})",
                    )

    def check_widths(self, points: list[ProfilePoint], limits: PlanLimits) -> None:
        for point in points:
            largest, _ = limits.for_table(point.table)
            if point.size > largest:
                self.where = self.line_of("point", point.name)
                problem = f"{point.size} registers do not fit in one read (max_block = {largest})"
                raise self.fail(f"point {point.name}.size", problem)

    def check_probes(self, device: DeviceInfo, points: dict[str, ProfilePoint]) -> None:
        self.where = ""
        for i, probe in enumerate(device.identify.probes):
            if probe.point not in points:
                raise self.fail(
                    f"device.identify.probe[{i}].point", f"no point named {probe.point!r}"
                )


class _Context:
    """The defaults a point falls back on."""

    def __init__(
        self, table: Table, layout: Layout, base: int, poll: str, classes: Mapping[str, float]
    ) -> None:
        self.table, self.layout, self.base, self.poll, self.classes = (
            table,
            layout,
            base,
            poll,
            classes,
        )


class _PointReader:
    """The keys of one `[[point]]`."""

    def __init__(self, loader: _Loader, entry: dict[str, Any], key: str, context: _Context) -> None:
        self.loader, self.entry, self.key, self.context = loader, entry, key, context

    def fail(self, name: str, problem: str) -> ConfigError:
        return self.loader.fail(f"{self.key}.{name}", problem)

    def optional_number(self, name: str) -> float | None:
        value = self.entry.get(name)
        return None if value is None else self.loader.number(value, f"{self.key}.{name}")

    def point(self, name: str) -> ProfilePoint:
        loader, entry, context = self.loader, self.entry, self.context
        table = Table(
            loader.choice(entry.get("table", context.table), f"{self.key}.table", tuple(Table))
        )
        kind = self.kind(table)
        size = self.size(kind, table)
        address = self.address(size)
        access = Access(
            loader.choice(entry.get("access", "r"), f"{self.key}.access", tuple(Access))
        )
        if access is Access.RW and not table.writable:
            raise self.fail("access", f"must be r: a master cannot write {table}")
        poll = loader.name(entry.get("poll", context.poll), f"{self.key}.poll")
        if poll not in context.classes:
            raise self.fail(
                "poll", f"unknown poll class {poll!r} (known: {', '.join(context.classes)})"
            )
        point = ProfilePoint(
            name,
            table,
            address,
            kind,
            size,
            layout=self.layout(),
            encoding=self.encoding(kind),
            scale=self.optional_number("scale"),
            offset=self.optional_number("offset"),
            scale_factor=self.scale_factor(),
            not_available=self.not_available(kind, size),
            unit=loader.text(entry, "unit", self.key, ""),
            description=loader.text(entry, "description", self.key, ""),
            access=access,
            minimum=self.optional_number("min"),
            maximum=self.optional_number("max"),
            poll=poll,
            values=self.names("values", kind is PointType.ENUM, range(1 << (16 * size))),
            bits=self.names("bits", kind is PointType.BITFIELD, range(16 * size)),
            meta=loader.table(entry.get("meta", {}), f"{self.key}.meta"),
        )
        self.check_scaling(point)
        if "value" in entry:
            point = self.with_initial(point, entry["value"])
        return point

    def layout(self) -> Layout:
        given = self.entry.get("layout", self.context.layout)
        return Layout(self.loader.choice(given, f"{self.key}.layout", tuple(Layout)))

    def scale_factor(self) -> str | None:
        if "scale_factor" not in self.entry:
            return None
        return self.loader.name(self.entry["scale_factor"], f"{self.key}.scale_factor")

    def kind(self, table: Table) -> PointType:
        default = "bool" if table.is_bit else "u16"
        given = self.entry.get("type", default)
        if not isinstance(given, str) or _ALIASES.get(given, given) not in tuple(PointType):
            known = ", ".join(PointType)
            shown = repr(given) if isinstance(given, str) else _kind(given)
            raise self.fail("type", f"unknown type {shown} (known: {known})")
        kind = PointType(_ALIASES.get(given, given))
        if table.is_bit and kind is not PointType.BOOL:
            raise self.fail("type", f"must be bool in {table}, not {given}")
        return kind

    def size(self, kind: PointType, table: Table) -> int:
        given = self.entry.get("size")
        if table.is_bit or kind in FIXED_WIDTHS or kind is PointType.BOOL:
            if given is not None:
                raise self.fail("size", f"is only for string, bitfield and enum points, not {kind}")
            return FIXED_WIDTHS.get(kind, 1)
        if kind is PointType.STRING:
            if given is None:
                raise self.fail("size", "missing: a string needs its number of registers")
            return self.loader.integer(given, f"{self.key}.size", range(1, 126))
        return self.loader.integer(1 if given is None else given, f"{self.key}.size", range(1, 3))

    def address(self, size: int) -> int:
        base = self.context.base
        given = self.entry.get("address")
        if given is None:
            raise self.fail("address", "missing")
        last = _ADDRESSES - size + base
        return self.loader.integer(given, f"{self.key}.address", range(base, last + 1)) - base

    def encoding(self, kind: PointType) -> str:
        encoding = self.loader.text(self.entry, "encoding", self.key, "ascii")
        if "encoding" in self.entry and kind is not PointType.STRING:
            raise self.fail("encoding", f"is only for string points, not {kind}")
        try:
            "".encode(encoding)
        except LookupError:
            raise self.fail("encoding", f"unknown text encoding {encoding!r}") from None
        return encoding

    def not_available(self, kind: PointType, size: int) -> int | None:
        if "not_available" not in self.entry:
            return None
        value = self.entry["not_available"]
        if kind is PointType.STRING:
            self.loader.integer(value, f"{self.key}.not_available", range(1))
            return 0  # all NULs
        if not kind.is_integer:
            raise self.fail("not_available", f"is only for integer and string points, not {kind}")
        signed = kind.value.startswith("i")
        bits = 16 * size
        allowed = range(-(1 << (bits - 1)), 1 << (bits - 1)) if signed else range(1 << bits)
        return self.loader.integer(value, f"{self.key}.not_available", allowed)

    def names(self, name: str, wanted: bool, allowed: range) -> dict[int, str]:
        if name not in self.entry:
            return {}
        if not wanted:
            raise self.fail(
                name, f"is only for {'enum' if name == 'values' else 'bitfield'} points"
            )
        found = self.loader.table(self.entry[name], f"{self.key}.{name}")
        names: dict[int, str] = {}
        for number, label in found.items():
            if not number.isdigit() or int(number) not in allowed:
                raise self.fail(
                    f"{name}.{number}", f"must be a number {allowed.start}..{allowed.stop - 1}"
                )
            if not isinstance(label, str) or not label:
                raise self.fail(
                    f"{name}.{number}", f"must be a non-empty string, not {_kind(label)}"
                )
            names[int(number)] = label
        return names

    def check_scaling(self, point: ProfilePoint) -> None:
        for name in ("scale", "offset", "scale_factor", "min", "max"):
            if name in self.entry and not point.type.is_number:
                raise self.fail(name, f"is only for numeric points, not {point.type}")
        if point.scale == 0:
            raise self.fail("scale", "must not be 0")
        if (
            point.minimum is not None
            and point.maximum is not None
            and point.minimum > point.maximum
        ):
            raise self.fail("min", f"{point.minimum:g} is above max {point.maximum:g}")

    def with_initial(self, point: ProfilePoint, value: object) -> ProfilePoint:
        try:
            checked = check_value(point, value)
            encode_point(point, checked, 0)
        except InvalidValue as error:
            problem = str(error).removeprefix(f"point {point.name}: ")
            raise self.fail("value", problem) from None
        # A profile's own starting value need not respect the write limits.
        return replace(point, initial=checked)

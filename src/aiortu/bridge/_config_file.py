"""The bridge's configuration file: TOML read into a
[`BridgeConfig`][aiortu.bridge.BridgeConfig] and checked before anything is opened.

Every mistake is a [`ConfigError`][aiortu.errors.ConfigError] naming the file, the key and
the problem in one line (`bridge.toml: line[0].device[2].profile: unknown profile 'sdm603'
(a file, or one of: eastron-sdm630, sunspec-inverter)`). A topic of the layout too long for
MQTT, or a broker the bridge cannot use, is a [`BrokerError`][aiortu.bridge.BrokerError]
(exit 1, not 2). See `docs/bridge.md`.
"""

from __future__ import annotations

import re
import tomllib
from pathlib import Path
from typing import Any

from aiortu.bridge._broker import Broker, BrokerError, parse_broker_url
from aiortu.bridge._config import (
    LAYOUTS,
    VIRTUAL_PORT,
    BridgeConfig,
    DeviceConfig,
    LineConfig,
    TopicLayout,
)
from aiortu.bridge._layouts import make_layout
from aiortu.bridge._packets import MAX_STRING_BYTES
from aiortu.bridge._state import device_states
from aiortu.core.model import Profile, TomlReader, find_profile, load_profile, shipped_profiles
from aiortu.errors import ConfigError

__all__ = ("load_config", "parse_config")

_NAME = re.compile(r"[A-Za-z0-9_-]+")
_LINE_OPTIONS: dict[str, type | tuple[type, ...]] = {
    "baudrate": int, "parity": str, "stopbits": (int, float), "bytesize": int,
    "timeout": (int, float), "retries": int, "offline_after": int, "probe_interval": (int, float),
}  # fmt: skip
_LINE_FILES = {"cert_file": "certfile", "key_file": "keyfile", "ca_file": "cafile"}
"""A `tls://` line's certificate files, named as the broker's are, and the options of
[`open_master`][aiortu.open_master] they become."""


def load_config(path: str | Path) -> BridgeConfig:
    """The configuration in the TOML file at `path` (see the module docstring)."""
    return parse_config(TomlReader.read(path), str(path), Path(path).parent)


def parse_config(text: str, source: str = "<string>", base: Path | None = None) -> BridgeConfig:
    """The configuration in TOML `text`; `source` names it in errors, and profile files are
    found relative to `base` (the current directory when None)."""
    try:
        document = tomllib.loads(text)
    except tomllib.TOMLDecodeError as error:
        raise ConfigError(source, "(syntax)", str(error)) from None
    reader = _Reader(source, base or Path())
    return reader.config(document)


class _Reader:
    def __init__(self, source: str, base: Path) -> None:
        self.source = source
        self.base = base
        self.profiles: dict[str, Profile] = {}

    def fail(self, key: str, problem: str) -> ConfigError:
        return ConfigError(self.source, key, problem)

    def table(self, data: object, key: str, known: set[str]) -> dict[str, Any]:
        if not isinstance(data, dict):
            raise self.fail(key, "must be a table")
        unknown = sorted(set(data) - known)
        if unknown:
            raise self.fail(
                f"{key}.{unknown[0]}", f"unknown key (known: {', '.join(sorted(known))})"
            )
        return data

    def config(self, document: dict[str, Any]) -> BridgeConfig:
        self.table(document, "(top)", {"broker", "topics", "buffer", "line"})
        topics = self.topics(document.get("topics", {}))
        broker = self.broker(document.get("broker"), topics.node)
        buffer = self.table(document.get("buffer", {}), "buffer", {"max_messages", "max_bytes"})
        lines = document.get("line")
        if not isinstance(lines, list) or not lines:
            raise self.fail("line", "at least one [[line]] with its devices is needed")
        config = BridgeConfig(
            broker, tuple(self.line(entry, f"line[{n}]") for n, entry in enumerate(lines)),
            topics,
            self.integer(buffer, "max_messages", "buffer", 100_000),
            self.integer(buffer, "max_bytes", "buffer", 64 * 1024 * 1024),
        )  # fmt: skip
        seen: set[str] = set()
        for n, device in enumerate(config.devices()):
            if device.name in seen:
                raise self.fail(f"device[{n}].name", f"{device.name!r} names two devices")
            seen.add(device.name)
        self.topic_lengths(config)
        return config

    def topic_lengths(self, config: BridgeConfig) -> None:
        """Every topic the layout will use (its own list) fits in an MQTT string; else the
        broker session could never send it, and would fail again at each reconnect."""
        for listed in make_layout(config.topics).every_topic(device_states(config)):
            size = len(listed.topic.encode())
            if size > MAX_STRING_BYTES:
                whose = f"device {_short(listed.device)}" if listed.device else "the bridge"
                if listed.point:
                    whose += f", point {_short(listed.point)}"
                raise BrokerError(
                    f"{self.source}: the topic of {whose} is {size:,} bytes, more than the "
                    f"{MAX_STRING_BYTES:,} an MQTT topic holds: shorten the names it is made of"
                )

    def integer(self, data: dict[str, Any], key: str, where: str, default: int) -> int:
        value = data.get(key, default)
        if isinstance(value, bool) or not isinstance(value, int) or value < 1:
            raise self.fail(f"{where}.{key}", f"must be an integer >= 1, not {value!r}")
        return value

    def topics(self, data: object) -> TopicLayout:
        keys = {"layout", "prefix", "discovery_prefix", "retain", "qos", "node", "group"}
        table = self.table(data, "topics", keys)
        layout = TopicLayout(**table)
        if layout.layout not in LAYOUTS:
            raise self.fail("topics.layout", f"must be one of {', '.join(LAYOUTS)}")
        if not isinstance(layout.retain, bool):
            raise self.fail("topics.retain", f"must be true or false, not {layout.retain!r}")
        if layout.qos not in (0, 1) or isinstance(layout.qos, bool):
            raise self.fail("topics.qos", f"must be 0 or 1, not {layout.qos!r}")
        for key in ("prefix", "discovery_prefix", "node", "group"):
            value = getattr(layout, key)
            if not isinstance(value, str) or not value or any(c in value for c in "#+"):
                raise self.fail(f"topics.{key}", "must be a topic name without + or #")
        if not _NAME.fullmatch(layout.node):
            raise self.fail("topics.node", "must be letters, digits, _ and - only")
        return layout

    def broker(self, data: object, node: str) -> Broker:
        keys = {"url", "username", "password", "client_id", "keepalive", "ca_file", "cert_file",
                "key_file", "insecure"}  # fmt: skip
        table = self.table(data if data is not None else {}, "broker", keys)
        if "url" not in table:
            raise self.fail("broker.url", "is required (mqtt://host:port or mqtts://host:port)")
        options = {k: v for k, v in table.items() if k != "url"}
        for key in ("ca_file", "cert_file", "key_file"):
            if key in options:
                options[key] = str(self.base / options[key])
        options.setdefault("client_id", f"aiortu-{node}")
        try:
            return parse_broker_url(table["url"], **options)
        except BrokerError as error:
            # A broker the bridge cannot use is its own kind of failure (exit 1, not 2).
            raise BrokerError(f"{self.source}: {error}") from None

    def line(self, data: object, key: str) -> LineConfig:
        table = self.table(data, key, {"port", "device", "framing", *_LINE_OPTIONS, *_LINE_FILES})
        port = table.get("port")
        if not isinstance(port, str) or not port:
            raise self.fail(
                f"{key}.port",
                "is required: a serial device, tcp://, udp://, tls://, rtu+tcp://, ascii+tcp:// "
                "or virtual",
            )
        options = self.line_transport(table, key, port)
        for name, kinds in _LINE_OPTIONS.items():
            if name in table:
                value = table[name]
                if isinstance(value, bool) or not isinstance(value, kinds):
                    raise self.fail(f"{key}.{name}", f"has the wrong type: {value!r}")
                options[name] = value
        devices = table.get("device")
        if not isinstance(devices, list) or not devices:
            raise self.fail(f"{key}.device", "at least one [[line.device]] is needed")
        return LineConfig(
            port, tuple(self.device(d, f"{key}.device[{n}]") for n, d in enumerate(devices)),
            options,
        )  # fmt: skip

    def line_transport(self, table: dict[str, Any], key: str, port: str) -> dict[str, Any]:
        """The options of a line's transport: `framing = "ascii"` on a serial port or
        `rtu+tcp://`, and the certificate files a `tls://` port needs (relative to the file)."""
        scheme = port.partition("://")[0].lower() if "://" in port else ""
        options: dict[str, Any] = {}
        framing = table.get("framing", "rtu")
        if framing not in ("rtu", "ascii"):
            raise self.fail(f"{key}.framing", f'must be "rtu" or "ascii", not {framing!r}')
        if framing == "ascii":
            if scheme not in ("", "rtu+tcp", "ascii+tcp") or port == VIRTUAL_PORT:
                raise self.fail(f"{key}.framing", '"ascii" is for a serial port or rtu+tcp://')
            options["framing"] = framing
        return options | self.line_files(table, key, scheme)

    def line_files(self, table: dict[str, Any], key: str, scheme: str) -> dict[str, str]:
        """A `tls://` line's certificate files as the master's options, each required there,
        refused elsewhere, and found relative to the configuration."""
        files: dict[str, str] = {}
        for name, option in _LINE_FILES.items():
            value = table.get(name)
            if value is None and scheme == "tls":
                raise self.fail(
                    f"{key}.{name}", "is required for a tls:// port (Modbus/TCP Security)"
                )
            if value is not None and scheme != "tls":
                raise self.fail(f"{key}.{name}", "is for a tls:// port only")
            if value is not None:
                if not isinstance(value, str) or not value:
                    raise self.fail(f"{key}.{name}", f"must be a file name, not {value!r}")
                files[option] = str(self.base / value)
        for name, option in _LINE_FILES.items():
            # Said here under its key; the master would name it by its option, once running.
            if option in files and not Path(files[option]).is_file():
                raise self.fail(f"{key}.{name}", f"no such file: {files[option]}")
        return files

    def device(self, data: object, key: str) -> DeviceConfig:
        table = self.table(
            data, key, {"name", "unit", "profile", "publish", "every_poll", "points"}
        )
        unit = table.get("unit")
        if isinstance(unit, bool) or not isinstance(unit, int) or not 1 <= unit <= 247:
            raise self.fail(f"{key}.unit", f"must be a unit address 1..247, not {unit!r}")
        profile = self.profile(table.get("profile"), f"{key}.profile")
        name = table.get("name", f"{_slug(profile.device.model)}-{unit}")
        if not isinstance(name, str) or not _NAME.fullmatch(name):
            raise self.fail(f"{key}.name", f"{name!r} must be letters, digits, _ and - only")
        publish = table.get("publish", "change")
        if publish not in ("change", "every"):
            raise self.fail(f"{key}.publish", f'must be "change" or "every", not {publish!r}')
        points = table.get("points")
        every = table.get("every_poll", [])
        for option, names in (("points", points or []), ("every_poll", every)):
            if not isinstance(names, list) or (option == "points" and points == []):
                raise self.fail(f"{key}.{option}", "must be a list of point names (none: omit it)")
            for n, point in enumerate(names):
                if not any(p.name == point for p in profile.points):
                    raise self.fail(
                        f"{key}.{option}[{n}]",
                        f"profile {profile.device.model!r} has no point named {point!r}",
                    )
        return DeviceConfig(
            name, unit, profile, publish, frozenset(every),
            None if points is None else tuple(points),
        )  # fmt: skip

    def profile(self, name: object, key: str) -> Profile:
        if not isinstance(name, str) or not name:
            raise self.fail(key, "is required: a profile file or a shipped profile's name")
        if name not in self.profiles:
            path = find_profile(name, self.base)
            if path is None:
                known = ", ".join(shipped_profiles())
                raise self.fail(key, f"unknown profile {name!r} (a file, or one of: {known})")
            self.profiles[name] = load_profile(path)
        return self.profiles[name]


def _short(name: str) -> str:
    """`name` quoted, cut to its first 40 characters."""
    return repr(name) if len(name) <= 40 else repr(name[:40] + "...")


def _slug(text: str) -> str:
    return re.sub(r"[^a-z0-9]+", "-", text.lower()).strip("-") or "device"

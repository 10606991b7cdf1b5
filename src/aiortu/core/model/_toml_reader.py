"""Walking a parsed TOML document: the checks every description file needs, each failure a
[`ConfigError`][aiortu.errors.ConfigError] that names the file and the key path."""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path
from typing import Any

from aiortu.core.errors import ConfigError

__all__ = ("TomlReader",)


class TomlReader:
    """Checks the tables and keys of a parsed TOML document from `source` (a file name, shown
    in errors). `where` (empty, or `:LINE`) follows the source in errors when a subclass knows
    the line of the entry being read."""

    def __init__(self, source: str) -> None:
        self.source = source
        self.where = ""

    @staticmethod
    def kind(value: object) -> str:
        """What `value` is, as an error says it: `a boolean`, `an array`, ..."""
        names = {bool: "a boolean", int: "an integer", float: "a number", str: "a string"}
        names |= {list: "an array", dict: "a table"}
        return names.get(type(value), type(value).__name__)

    @staticmethod
    def read(path: str | Path) -> str:
        """The text of the UTF-8 file at `path`; a [`ConfigError`][aiortu.errors.ConfigError]
        saying why when it cannot be read (`FILE: (file): cannot be read (No such file or
        directory)`)."""
        try:
            return Path(path).read_bytes().decode()
        except (OSError, UnicodeDecodeError) as error:
            why = error.strerror if isinstance(error, OSError) and error.strerror else error
            raise ConfigError(str(path), "(file)", f"cannot be read ({why})") from None

    def fail(self, key: str, problem: str) -> ConfigError:
        """The error for `problem` at `key` (to raise)."""
        return ConfigError(f"{self.source}{self.where}", key, problem)

    def table(self, value: object, key: str) -> dict[str, Any]:
        """`value` if it is a table."""
        if not isinstance(value, dict):
            raise self.fail(key, f"must be a table, not {self.kind(value)}")
        return value

    def tables(self, value: object, key: str) -> list[dict[str, Any]]:
        """`value` if it is an array of tables (`[[key]]`)."""
        if not isinstance(value, list):
            raise self.fail(key, f"must be an array of tables ([[{key}]]), not {self.kind(value)}")
        return [self.table(item, f"{key}[{index}]") for index, item in enumerate(value)]

    def known(self, found: Mapping[str, object], allowed: frozenset[str], key: str) -> None:
        """Refuse a key of `found` (the table at `key`, empty at the top) not in `allowed`."""
        for name in found:
            if name not in allowed:
                where = f"{key}.{name}" if key else name
                raise self.fail(where, f"unknown key (known: {', '.join(sorted(allowed))})")

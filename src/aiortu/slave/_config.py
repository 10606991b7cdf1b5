"""Device descriptions in TOML, for `aiortu serve --config`: units and their data stores.

The format (every key but `unit` is optional):

    [[slave]]
    unit = 17                          # or units = [17, 18]: several units, one store
    exception_status = 0x6D            # what 07 answers
    read_only_exception = 2            # what a write into a read-only range gets

    [[slave.coils]]                    # a block; several per table are allowed
    start = 0x130
    count = 37
    values = [1, 0, 1, 1]              # initial values from start; the rest are 0
    read_only = true                   # the whole block refuses writes

    [[slave.holding_registers]]        # also discrete_inputs, input_registers
    start = 0x160
    values = [0x022B, 0x0001]          # count defaults to len(values)

    [slave.aliases]                    # a table that shares another's blocks
    input_registers = "holding_registers"

    [[slave.read_only]]                # read-only ranges inside blocks
    table = "holding_registers"
    start = 0x160
    count = 2

    [[slave.fifo]]                     # FIFO queues for 18
    address = 0x04DE
    values = [440, 25]

    [[slave.files]]                    # file records for 14 and 15
    file = 1
    records = 100                      # or values = [...]

    [slave.device_identification]      # objects for 2B/0E, by name or by id
    vendor_name = "aiortu"
    product_code = "SIM-1"
    revision = "1.0"
    objects = { "0x80" = "private" }

    [slave.server_id]                  # what 11 answers
    id = [0x11]                        # bytes, or a string
    run = true
    data = "simulated"

    [modbus_tcp]                       # only when served as a Modbus TCP server
    serial_line_codes = true           # answer 07, 08, 0B, 0C and 11 (default false)
    unit_aliases = { "255" = 1, "0" = 1 }   # unit id -> a unit described above

[`load_config`][aiortu.slave.load_config] reads a file and returns the units; any problem raises
[`ConfigError`][aiortu.errors.ConfigError], whose message is one line naming the file, the key path
(`slave[0].coils[1].count`) and the problem.
"""

from __future__ import annotations

import tomllib
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from aiortu.core.codes import UNIT_ADDRESSES, DeviceIdObject, ExceptionCode
from aiortu.core.model import ServerId, Table, TomlReader
from aiortu.errors import ConfigError, InvalidValue
from aiortu.slave._store import Block, MemoryStore

__all__ = ("ConfigError", "DeviceConfig", "load_config", "parse_config")

_TABLES = tuple(table.value for table in Table)
_EXCEPTION_CODES = tuple(sorted(int(code) for code in ExceptionCode))
_SLAVE_KEYS = frozenset(
    {
        "unit",
        "units",
        "exception_status",
        "read_only_exception",
        "aliases",
        "read_only",
        "fifo",
        "files",
        "device_identification",
        "server_id",
        *_TABLES,
    }
)
_OBJECT_NAMES = {
    "vendor_name": DeviceIdObject.VENDOR_NAME,
    "product_code": DeviceIdObject.PRODUCT_CODE,
    "revision": DeviceIdObject.MAJOR_MINOR_REVISION,
    "major_minor_revision": DeviceIdObject.MAJOR_MINOR_REVISION,
    "vendor_url": DeviceIdObject.VENDOR_URL,
    "product_name": DeviceIdObject.PRODUCT_NAME,
    "model_name": DeviceIdObject.MODEL_NAME,
    "user_application_name": DeviceIdObject.USER_APPLICATION_NAME,
}


@dataclass(frozen=True, slots=True)
class DeviceConfig:
    """What a description file holds: the store of each unit, and the settings of its
    `[modbus_tcp]` table for a [`ModbusTcpServer`][aiortu.slave.ModbusTcpServer]."""

    units: Mapping[int, MemoryStore]
    modbus_tcp: Mapping[str, Any] = field(default_factory=dict)
    """`serial_line_codes` and `unit_aliases` as the file gives them, the server's keyword
    arguments (empty without a `[modbus_tcp]` table)."""


class _Reader(TomlReader):
    """Walks the parsed TOML, raising ConfigError with the key path."""

    def integer(self, found: Mapping[str, object], name: str, key: str, allowed: range) -> int:
        if name not in found:
            raise self.fail(f"{key}.{name}", "missing")
        return self.int_value(found[name], f"{key}.{name}", allowed)

    def int_value(self, value: object, key: str, allowed: range) -> int:
        if not isinstance(value, int) or isinstance(value, bool):
            raise self.fail(key, f"must be an integer, not {_kind(value)}")
        if value not in allowed:
            raise self.fail(key, f"must be {allowed.start}..{allowed.stop - 1}, not {value}")
        return value

    def ints(self, value: object, key: str, allowed: range) -> list[int]:
        if not isinstance(value, list):
            raise self.fail(key, f"must be an array of integers, not {_kind(value)}")
        return [self.int_value(item, f"{key}[{i}]", allowed) for i, item in enumerate(value)]

    def data(self, value: object, key: str) -> bytes:
        if isinstance(value, str):
            return value.encode()
        return bytes(self.ints(value, key, range(0x100)))


_kind = TomlReader.kind


def load_config(path: str | Path) -> DeviceConfig:
    """Read the device description at `path`; raise [`ConfigError`][aiortu.errors.ConfigError] if it
    is wrong."""
    return parse_config(TomlReader.read(path), str(path))


def parse_config(text: str, source: str = "<string>") -> DeviceConfig:
    """Parse a device description from `text`; `source` names it in errors."""
    reader = _Reader(source)
    try:
        document = tomllib.loads(text)
    except tomllib.TOMLDecodeError as error:
        raise ConfigError(source, "(syntax)", str(error)) from None
    reader.known(document, frozenset({"slave", "modbus_tcp"}), "(top)")
    if "slave" not in document:
        raise reader.fail("slave", "missing: describe at least one [[slave]]")
    units: dict[int, MemoryStore] = {}
    for index, entry in enumerate(reader.tables(document["slave"], "slave")):
        key = f"slave[{index}]"
        store = _store(reader, entry, key)
        for unit in _units(reader, entry, key):
            if unit in units:
                raise reader.fail(f"{key}.unit", f"unit {unit} is described twice")
            units[unit] = store
    return DeviceConfig(units, _modbus_tcp(reader, document.get("modbus_tcp", {}), units))


def _modbus_tcp(reader: _Reader, value: object, units: Mapping[int, MemoryStore]) -> dict[str, Any]:
    """The Modbus TCP server's settings of the `[modbus_tcp]` table."""
    found = reader.table(value, "modbus_tcp")
    reader.known(found, frozenset({"serial_line_codes", "unit_aliases"}), "modbus_tcp")
    settings: dict[str, Any] = {}
    if "serial_line_codes" in found:
        codes = found["serial_line_codes"]
        if not isinstance(codes, bool):
            raise reader.fail("modbus_tcp.serial_line_codes", f"must be true or false, not {codes}")
        settings["serial_line_codes"] = codes
    if "unit_aliases" in found:
        aliases: dict[int, int] = {}
        for alias, unit in reader.table(found["unit_aliases"], "modbus_tcp.unit_aliases").items():
            key = f"modbus_tcp.unit_aliases.{alias}"
            try:
                unit_id = int(alias, 0)
            except ValueError:
                unit_id = -1
            if unit_id not in range(256):
                raise reader.fail(key, f"must be a unit id 0..255, not {alias}")
            aliases[unit_id] = reader.int_value(unit, key, UNIT_ADDRESSES)
            if aliases[unit_id] not in units:
                described = ", ".join(map(str, sorted(units)))
                raise reader.fail(key, f"unit {unit} is not described (units: {described})")
        settings["unit_aliases"] = aliases
    return settings


def _units(reader: _Reader, entry: dict[str, Any], key: str) -> list[int]:
    if "unit" in entry and "units" in entry:
        raise reader.fail(f"{key}.units", "give unit or units, not both")
    if "units" in entry:
        found = reader.ints(entry["units"], f"{key}.units", UNIT_ADDRESSES)
        if not found:
            raise reader.fail(f"{key}.units", "must name at least one unit")
        return found
    return [reader.integer(entry, "unit", key, UNIT_ADDRESSES)]


def _store(reader: _Reader, entry: dict[str, Any], key: str) -> MemoryStore:
    reader.known(entry, _SLAVE_KEYS, key)
    tables: dict[str, Any] = {}
    read_only: dict[Table | str, list[range]] = {table: [] for table in Table}
    for name in _TABLES:
        blocks = []
        for index, block_entry in enumerate(reader.tables(entry.get(name, []), f"{key}.{name}")):
            block_key = f"{key}.{name}[{index}]"
            block = _block(reader, block_entry, block_key, Table(name))
            blocks.append(block)
            if block_entry.get("read_only", False) is True:
                read_only[Table(name)].append(range(block.start, block.stop))
        tables[name] = blocks
    aliases = reader.table(entry.get("aliases", {}), f"{key}.aliases")
    reader.known(aliases, frozenset(_TABLES), f"{key}.aliases")
    for name, target in aliases.items():
        if target not in _TABLES:
            raise reader.fail(f"{key}.aliases.{name}", f"must name a table ({', '.join(_TABLES)})")
        if tables[name]:
            raise reader.fail(f"{key}.aliases.{name}", "the table has blocks of its own")
        tables[name] = Table(target)
    for table, ranges in _read_only_ranges(reader, entry, key, tables).items():
        read_only[table].extend(ranges)
    options = _options(reader, entry, key)
    try:
        return MemoryStore(
            **tables,
            read_only=read_only,
            fifo_queues=_fifo_queues(reader, entry, key),
            files=_files(reader, entry, key),
            **options,
        )
    except InvalidValue as error:
        raise reader.fail(key, str(error)) from None


def _read_only_ranges(
    reader: _Reader, entry: dict[str, Any], key: str, tables: Mapping[str, Any]
) -> dict[Table, list[range]]:
    """The `[[slave.read_only]]` ranges by table; each must lie inside the table's blocks
    (elsewhere every address answers 02 anyway: such a range is a mistake)."""
    found: dict[Table, list[range]] = {table: [] for table in Table}
    for index, item in enumerate(reader.tables(entry.get("read_only", []), f"{key}.read_only")):
        item_key = f"{key}.read_only[{index}]"
        reader.known(item, frozenset({"table", "start", "count"}), item_key)
        if item.get("table") not in _TABLES:
            raise reader.fail(f"{item_key}.table", f"must name a table ({', '.join(_TABLES)})")
        start = reader.integer(item, "start", item_key, range(0x10000))
        count = reader.integer(item, "count", item_key, range(1, 0x10001 - start))
        blocks = tables[item["table"]]
        for _ in _TABLES:  # an alias: the other table's blocks
            if isinstance(blocks, Table):
                blocks = tables[blocks.value]
        outside = _first_outside(range(start, start + count), blocks)
        if outside is not None:
            raise reader.fail(
                item_key,
                f"address {outside} of the range is outside every {item['table']} block; "
                "a read-only range must lie inside the table's blocks",
            )
        found[Table(item["table"])].append(range(start, start + count))
    return found


def _first_outside(addresses: range, blocks: list[Block] | Table) -> int | None:
    """The first of `addresses` that no block covers, or None."""
    address = addresses.start
    if isinstance(blocks, Table):
        return address  # a circle of aliases: MemoryStore says what is wrong
    for block in sorted(blocks, key=lambda block: block.start):
        if block.start <= address < block.stop:
            address = block.stop
        if address >= addresses.stop:
            return None
    return address


def _fifo_queues(reader: _Reader, entry: dict[str, Any], key: str) -> dict[int, list[int]]:
    fifo: dict[int, list[int]] = {}
    for index, item in enumerate(reader.tables(entry.get("fifo", []), f"{key}.fifo")):
        item_key = f"{key}.fifo[{index}]"
        reader.known(item, frozenset({"address", "values"}), item_key)
        address = reader.integer(item, "address", item_key, range(0x10000))
        if address in fifo:
            raise reader.fail(
                f"{item_key}.address", f"FIFO queue {address} is described twice in this slave"
            )
        fifo[address] = reader.ints(item.get("values", []), f"{item_key}.values", range(0x10000))
    return fifo


def _files(reader: _Reader, entry: dict[str, Any], key: str) -> dict[int, int | list[int]]:
    files: dict[int, int | list[int]] = {}
    for index, item in enumerate(reader.tables(entry.get("files", []), f"{key}.files")):
        item_key = f"{key}.files[{index}]"
        number, records = _file(reader, item, item_key)
        if number in files:
            raise reader.fail(f"{item_key}.file", f"file {number} is described twice in this slave")
        files[number] = records
    return files


def _options(reader: _Reader, entry: dict[str, Any], key: str) -> dict[str, Any]:
    options: dict[str, Any] = {}
    if "exception_status" in entry:
        options["exception_status"] = reader.integer(entry, "exception_status", key, range(0x100))
    if "read_only_exception" in entry:
        code = reader.integer(entry, "read_only_exception", key, range(0x100))
        if code not in _EXCEPTION_CODES:
            allowed = ", ".join(map(str, _EXCEPTION_CODES))
            raise reader.fail(
                f"{key}.read_only_exception",
                f"must be one of the spec's exception codes ({allowed}), not {code}",
            )
        options["read_only_exception"] = ExceptionCode(code)
    if "device_identification" in entry:
        options["device_identification"] = _objects(reader, entry["device_identification"], key)
    if "server_id" in entry:
        options["server_id"] = _server_id(reader, entry["server_id"], f"{key}.server_id")
    return options


def _block(reader: _Reader, entry: dict[str, Any], key: str, table: Table) -> Block:
    reader.known(entry, frozenset({"start", "count", "values", "read_only"}), key)
    start = reader.integer(entry, "start", key, range(0x10000))
    limit = 2 if table.is_bit else 0x10000
    values = reader.ints(entry.get("values", []), f"{key}.values", range(limit))
    if "count" in entry:
        count = reader.integer(entry, "count", key, range(1, 0x10001 - start))
    elif values:
        count = len(values)
    else:
        raise reader.fail(f"{key}.count", "missing (give count, values or both)")
    if len(values) > count:
        raise reader.fail(f"{key}.values", f"has {len(values)} values, more than count {count}")
    if count > 0x10000 - start:
        raise reader.fail(f"{key}.values", f"runs past address 65535 from start {start}")
    if not isinstance(entry.get("read_only", False), bool):
        raise reader.fail(
            f"{key}.read_only", f"must be true or false, not {_kind(entry['read_only'])}"
        )
    return Block(start, count, values)


def _file(reader: _Reader, item: dict[str, Any], key: str) -> tuple[int, int | list[int]]:
    """The file number and its records (a count, or the values)."""
    reader.known(item, frozenset({"file", "records", "values"}), key)
    number = reader.integer(item, "file", key, range(1, 0x10000))
    if "values" in item:
        values = reader.ints(item["values"], f"{key}.values", range(0x10000))
        if not 1 <= len(values) <= 10000:
            raise reader.fail(f"{key}.values", "must hold 1..10000 records")
        return number, values
    return number, reader.integer(item, "records", key, range(1, 10001))


def _objects(reader: _Reader, value: object, key: str) -> dict[int, bytes]:
    found = reader.table(value, f"{key}.device_identification")
    objects: dict[int, bytes] = {}
    for name, item in found.items():
        item_key = f"{key}.device_identification.{name}"
        if name == "objects":
            for id_text, data in reader.table(item, item_key).items():
                try:
                    object_id = int(id_text, 0)
                except ValueError:
                    raise reader.fail(f"{item_key}.{id_text}", "must be an object id") from None
                reader.int_value(object_id, f"{item_key}.{id_text}", range(0x100))
                objects[object_id] = reader.data(data, f"{item_key}.{id_text}")
        elif name in _OBJECT_NAMES:
            objects[_OBJECT_NAMES[name]] = reader.data(item, item_key)
        else:
            known = ", ".join(sorted({*_OBJECT_NAMES, "objects"}))
            raise reader.fail(item_key, f"unknown object (known: {known})")
    for object_id, data in objects.items():
        if len(data) > 244:
            raise reader.fail(
                f"{key}.device_identification", f"object {object_id} is over 244 bytes"
            )
    return objects


def _server_id(reader: _Reader, value: object, key: str) -> ServerId:
    found = reader.table(value, key)
    reader.known(found, frozenset({"id", "run", "data"}), key)
    if "id" not in found:
        raise reader.fail(f"{key}.id", "missing")
    run = found.get("run", True)
    if not isinstance(run, bool):
        raise reader.fail(f"{key}.run", f"must be true or false, not {_kind(run)}")
    try:
        return ServerId(
            reader.data(found["id"], f"{key}.id"),
            run,
            reader.data(found.get("data", ""), f"{key}.data"),
        )
    except InvalidValue as error:
        raise reader.fail(key, str(error)) from None

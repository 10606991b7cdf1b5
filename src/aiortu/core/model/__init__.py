"""The data model: tables and addresses, typed values, polling plans, the store's
protocols and device identification; and devices as data, sans-IO: profiles, their loading and
checking, read planning, value coding, SunSpec's model definitions and the imports.

A [`Profile`][aiortu.core.model.Profile] describes a device (see `docs/profiles.md`);
[`load_profile`][aiortu.core.model.load_profile] reads one from TOML, checking it against the
rules of `profile.schema.json` (shipped in this package, at
[`SCHEMA_PATH`][aiortu.core.model.SCHEMA_PATH]) and the ones a schema cannot say.
[`ReadPlan`][aiortu.core.model.ReadPlan] turns points into reads and replies into
values. Nothing here does I/O but reading the files it is asked to read.
"""

from __future__ import annotations

from aiortu._public import publish
from aiortu.core.model._addressing import (
    ADDRESS_RANGE,
    NUMBER_RANGE,
    Reference,
    Table,
    data_model_number,
    format_reference,
    parse_reference,
    protocol_address,
)
from aiortu.core.model._data_model import (
    AsyncDataStore,
    DataStore,
    ServerId,
    SupportsDeviceIdentification,
    SupportsExceptionStatus,
    SupportsFifoQueues,
    SupportsFileRecords,
    SupportsServerId,
)
from aiortu.core.model._device_identity import (
    CATEGORY_END,
    answer_device_identification,
    conformity_level,
)
from aiortu.core.model._import_evcc import EvccImport, profile_from_evcc, render_evcc
from aiortu.core.model._import_ha import profiles_from_home_assistant
from aiortu.core.model._point_codec import (
    check_value,
    check_write,
    decode_point,
    encode_point,
    raw_of,
    scaled,
)
from aiortu.core.model._poll_plan import (
    MAX_READ_BITS,
    MAX_READ_REGISTERS,
    PlannedRead,
    Point,
    PointSlice,
    plan_reads,
)
from aiortu.core.model._profile import (
    DEFAULT_POLL_CLASS,
    OBJECT_IDS,
    Access,
    DeviceInfo,
    Hole,
    Identification,
    PlanLimits,
    PointType,
    Probe,
    Profile,
    ProfilePoint,
    Value,
)
from aiortu.core.model._profile_dump import dump_profile
from aiortu.core.model._profile_load import (
    find_profile,
    load_profile,
    parse_profile,
    shipped_profiles,
)
from aiortu.core.model._read_plan import BlockRead, Raw, ReadPlan, describe, plan_blocks
from aiortu.core.model._schema_doc import SCHEMA_PATH, schema_reference
from aiortu.core.model._sunspec import (
    END_ID,
    MARKER,
    MARKER_BASES,
    SunSpecModels,
    model_length,
    model_points,
    sunspec_layout,
)
from aiortu.core.model._toml_reader import TomlReader
from aiortu.core.model._values import (
    Layout,
    ValueType,
    as_layout,
    as_value_type,
    bits_to_bytes,
    bytes_to_bits,
    check_encoding,
    decode_value,
    encode_value,
    float32_to_registers,
    float64_to_registers,
    int16_to_register,
    int32_to_registers,
    int64_to_registers,
    register_count,
    register_to_int16,
    registers_to_float32,
    registers_to_float64,
    registers_to_int32,
    registers_to_int64,
    registers_to_string,
    registers_to_uint32,
    registers_to_uint64,
    string_to_registers,
    uint32_to_registers,
    uint64_to_registers,
)

__all__ = (
    "ADDRESS_RANGE",
    "Access",
    "AsyncDataStore",
    "BlockRead",
    "CATEGORY_END",
    "DEFAULT_POLL_CLASS",
    "DataStore",
    "DeviceInfo",
    "END_ID",
    "EvccImport",
    "Hole",
    "Identification",
    "Layout",
    "MARKER",
    "MARKER_BASES",
    "MAX_READ_BITS",
    "MAX_READ_REGISTERS",
    "NUMBER_RANGE",
    "OBJECT_IDS",
    "PlanLimits",
    "PlannedRead",
    "Point",
    "PointSlice",
    "PointType",
    "Probe",
    "Profile",
    "ProfilePoint",
    "Raw",
    "ReadPlan",
    "Reference",
    "SCHEMA_PATH",
    "ServerId",
    "SunSpecModels",
    "SupportsDeviceIdentification",
    "SupportsExceptionStatus",
    "SupportsFifoQueues",
    "SupportsFileRecords",
    "SupportsServerId",
    "Table",
    "TomlReader",
    "Value",
    "ValueType",
    "answer_device_identification",
    "as_layout",
    "as_value_type",
    "bits_to_bytes",
    "bytes_to_bits",
    "check_encoding",
    "check_value",
    "check_write",
    "conformity_level",
    "data_model_number",
    "decode_point",
    "decode_value",
    "describe",
    "dump_profile",
    "encode_point",
    "encode_value",
    "find_profile",
    "float32_to_registers",
    "float64_to_registers",
    "format_reference",
    "int16_to_register",
    "int32_to_registers",
    "int64_to_registers",
    "load_profile",
    "model_length",
    "model_points",
    "parse_profile",
    "parse_reference",
    "plan_blocks",
    "plan_reads",
    "profile_from_evcc",
    "profiles_from_home_assistant",
    "protocol_address",
    "raw_of",
    "register_count",
    "register_to_int16",
    "registers_to_float32",
    "registers_to_float64",
    "registers_to_int32",
    "registers_to_int64",
    "registers_to_string",
    "registers_to_uint32",
    "registers_to_uint64",
    "render_evcc",
    "scaled",
    "schema_reference",
    "shipped_profiles",
    "string_to_registers",
    "sunspec_layout",
    "uint32_to_registers",
    "uint64_to_registers",
)

publish(__name__, __all__, globals())

"""Devices as data, sans-IO: profiles, their loading and checking, read planning and value
coding.

A [`Profile`][aiortu.core.model.Profile] describes a device (see `docs/profiles.md`);
[`load_profile`][aiortu.core.model.load_profile] reads one from TOML, checking it against the
rules of `profile.schema.json` (shipped in this package, at
[`SCHEMA_PATH`][aiortu.core.model.SCHEMA_PATH]) and the ones a schema cannot say.
[`ReadPlan`][aiortu.core.model.ReadPlan] turns points into reads and replies into
values. Nothing here does I/O.
"""

from __future__ import annotations

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
from aiortu.core.model._profile import (
    DEFAULT_POLL_CLASS,
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
from aiortu.core.model._profile_load import load_profile, parse_profile
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

__all__ = (
    "DEFAULT_POLL_CLASS",
    "END_ID",
    "MARKER",
    "MARKER_BASES",
    "SCHEMA_PATH",
    "Access",
    "BlockRead",
    "DeviceInfo",
    "EvccImport",
    "Hole",
    "Identification",
    "PlanLimits",
    "PointType",
    "Probe",
    "Profile",
    "ProfilePoint",
    "Raw",
    "ReadPlan",
    "SunSpecModels",
    "Value",
    "check_value",
    "check_write",
    "decode_point",
    "describe",
    "dump_profile",
    "encode_point",
    "load_profile",
    "model_length",
    "model_points",
    "parse_profile",
    "plan_blocks",
    "profile_from_evcc",
    "profiles_from_home_assistant",
    "raw_of",
    "render_evcc",
    "scaled",
    "schema_reference",
    "sunspec_layout",
)

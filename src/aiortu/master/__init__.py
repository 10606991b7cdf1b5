"""The async Modbus RTU master: one line, one transaction at a time, shared by any number
of coroutines; handles bound to one unit; a poller that reads points in cycles.

[`Master`][aiortu.master.Master] takes any `anyio.abc.ByteStream`;
[`open_master`][aiortu.master.open_master] opens one from a port name or URL first. See
`docs/master.md`.
"""

from __future__ import annotations

import importlib
from typing import TYPE_CHECKING, Any

from aiortu._public import publish
from aiortu.errors import UnitOffline, UnitSkipped
from aiortu.master._client import Master, open_master
from aiortu.master._config import MasterConfig, ReconnectPolicy, TimingPolicy
from aiortu.master._connection import LineConnection, StreamOpener
from aiortu.master._handles import BroadcastHandle, BroadcastMethod, UnitHandle
from aiortu.master._records import FileRecordLike, RecordRequestLike
from aiortu.master._seam import Seam
from aiortu.master._stats import HealthPolicy, UnitState, UnitStats

if TYPE_CHECKING:
    from aiortu.master._device import Device, Reading
    from aiortu.master._identify import ProfileMatch, match_profiles
    from aiortu.master._poller import CycleReport, CycleStats, Point, Poller, Sample, UnitHealth
    from aiortu.master._profile_poller import ProfilePoller
    from aiortu.master._sunspec import FoundModel, SunSpecDevice, walk_sunspec

__all__ = (
    "BroadcastHandle",
    "BroadcastMethod",
    "CycleReport",
    "CycleStats",
    "Device",
    "FileRecordLike",
    "FoundModel",
    "HealthPolicy",
    "LineConnection",
    "Master",
    "MasterConfig",
    "Point",
    "Poller",
    "ProfileMatch",
    "ProfilePoller",
    "Reading",
    "ReconnectPolicy",
    "RecordRequestLike",
    "Sample",
    "Seam",
    "StreamOpener",
    "SunSpecDevice",
    "TimingPolicy",
    "UnitHandle",
    "UnitHealth",
    "UnitOffline",
    "UnitSkipped",
    "UnitState",
    "UnitStats",
    "match_profiles",
    "open_master",
    "walk_sunspec",
)

_ON_FIRST_USE = {
    **dict.fromkeys(("Device", "Reading"), "aiortu.master._device"),
    **dict.fromkeys(("ProfileMatch", "match_profiles"), "aiortu.master._identify"),
    **dict.fromkeys(
        ("CycleReport", "CycleStats", "Point", "Poller", "Sample", "UnitHealth"),
        "aiortu.master._poller",
    ),
    "ProfilePoller": "aiortu.master._profile_poller",
    **dict.fromkeys(("FoundModel", "SunSpecDevice", "walk_sunspec"), "aiortu.master._sunspec"),
}
"""Imported on first use: a command that reads once needs no poller, no device profiles."""


def __getattr__(name: str) -> Any:
    module = _ON_FIRST_USE.get(name)
    if module is None:
        raise AttributeError(f"module 'aiortu.master' has no attribute {name!r}")
    value = getattr(importlib.import_module(module), name)
    globals()[name] = value
    publish(__name__, (name,), globals())
    return value


publish(__name__, __all__, globals())

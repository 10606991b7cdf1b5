"""The async Modbus RTU master: one line, one transaction at a time, shared by any number
of coroutines; handles bound to one unit; a poller that reads points in cycles.

[`Master`][aiortu.master.Master] takes any `anyio.abc.ByteStream`;
[`open_master`][aiortu.master.open_master] opens one from a port name or URL first. See
`docs/master.md`.
"""

from __future__ import annotations

import importlib
from typing import TYPE_CHECKING, Any

from aiortu.errors import UnitOffline, UnitSkipped
from aiortu.master._calls import FileRecordLike, RecordRequestLike
from aiortu.master._client import Master, open_master
from aiortu.master._connection import LineConnection, ReconnectPolicy, StreamOpener
from aiortu.master._handles import BroadcastHandle, UnitHandle
from aiortu.master._stats import HealthPolicy, UnitState, UnitStats

if TYPE_CHECKING:
    from aiortu.master._poller import CycleReport, CycleStats, Point, Poller, Sample, UnitHealth

__all__ = (
    "BroadcastHandle",
    "CycleReport",
    "CycleStats",
    "FileRecordLike",
    "HealthPolicy",
    "LineConnection",
    "Master",
    "Point",
    "Poller",
    "ReconnectPolicy",
    "RecordRequestLike",
    "Sample",
    "StreamOpener",
    "UnitHandle",
    "UnitHealth",
    "UnitOffline",
    "UnitSkipped",
    "UnitState",
    "UnitStats",
    "open_master",
)

_POLLER_NAMES = frozenset({"CycleReport", "CycleStats", "Point", "Poller", "Sample", "UnitHealth"})
"""Imported on first use: a command that reads once needs no poller (nor its planner)."""


def __getattr__(name: str) -> Any:
    if name not in _POLLER_NAMES:
        raise AttributeError(f"module 'aiortu.master' has no attribute {name!r}")
    value = getattr(importlib.import_module("aiortu.master._poller"), name)
    globals()[name] = value
    return value

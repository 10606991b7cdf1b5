"""The async Modbus RTU master: one line, one transaction at a time, shared by any number
of coroutines; handles bound to one unit; a poller that reads points in cycles.

[`Master`][aiortu.master.Master] takes any `anyio.abc.ByteStream`;
[`open_master`][aiortu.master.open_master] opens one from a port name or URL first. See
`docs/master.md`.
"""

from __future__ import annotations

from aiortu.errors import UnitOffline, UnitSkipped
from aiortu.master._calls import FileRecordLike, RecordRequestLike
from aiortu.master._client import Master, open_master
from aiortu.master._config import MasterConfig, ReconnectPolicy, TimingPolicy
from aiortu.master._connection import LineConnection, StreamOpener
from aiortu.master._handles import BroadcastHandle, UnitHandle
from aiortu.master._poller import CycleReport, CycleStats, Point, Poller, Sample, UnitHealth
from aiortu.master._seam import Seam
from aiortu.master._stats import HealthPolicy, UnitState, UnitStats

__all__ = (
    "BroadcastHandle",
    "CycleReport",
    "CycleStats",
    "FileRecordLike",
    "HealthPolicy",
    "LineConnection",
    "Master",
    "MasterConfig",
    "Point",
    "Poller",
    "ReconnectPolicy",
    "RecordRequestLike",
    "Sample",
    "Seam",
    "StreamOpener",
    "TimingPolicy",
    "UnitHandle",
    "UnitHealth",
    "UnitOffline",
    "UnitSkipped",
    "UnitState",
    "UnitStats",
    "open_master",
)

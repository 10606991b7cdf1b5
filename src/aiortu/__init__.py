"""aiortu: an asyncio Modbus RTU master/slave framework.

See the README and `docs/` for the guides; the names they use are re-exported here. The packages
[`aiortu.master`][aiortu.master], [`aiortu.blocking`][aiortu.blocking] (the same API
without async), [`aiortu.slave`][aiortu.slave],
[`aiortu.gateway`][aiortu.gateway], [`aiortu.testing`][aiortu.testing],
[`aiortu.transport`][aiortu.transport], [`aiortu.line`][aiortu.line] and
[`aiortu.core`][aiortu.core] hold the rest.
"""

from __future__ import annotations

import importlib
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from aiortu.core.codes import ExceptionCode, FunctionCode
    from aiortu.core.model import Profile, load_profile
    from aiortu.core.pdu import ExceptionPDU, RawPDU, Request, Response
    from aiortu.core.serial import LineSettings
    from aiortu.errors import (
        ConfigError,
        ConnectionLost,
        CRCError,
        ExceptionResponse,
        FrameError,
        InvalidRequest,
        InvalidValue,
        MalformedPDU,
        ModbusError,
        PortError,
        ResponseTimeout,
        UnitOffline,
        UnitSkipped,
    )
    from aiortu.gateway import gateway
    from aiortu.master import (
        BroadcastHandle,
        Device,
        HealthPolicy,
        Master,
        MasterConfig,
        Point,
        Poller,
        ProfilePoller,
        Reading,
        ReconnectPolicy,
        Sample,
        UnitHandle,
        UnitStats,
        open_master,
        walk_sunspec,
    )
    from aiortu.slave import (
        AsyncDataStore,
        Block,
        Change,
        DataStore,
        MemoryStore,
        ProfileStore,
        Reply,
        RequestContext,
        Slave,
        load_config,
        serve,
    )

_LAZY: dict[str, str] = {
    "AsyncDataStore": "aiortu.slave",
    "Block": "aiortu.slave",
    "BroadcastHandle": "aiortu.master",
    "CRCError": "aiortu.errors",
    "Change": "aiortu.slave",
    "ConfigError": "aiortu.errors",
    "ConnectionLost": "aiortu.errors",
    "DataStore": "aiortu.slave",
    "Device": "aiortu.master",
    "ExceptionCode": "aiortu.core.codes",
    "ExceptionPDU": "aiortu.core.pdu",
    "ExceptionResponse": "aiortu.errors",
    "FrameError": "aiortu.errors",
    "FunctionCode": "aiortu.core.codes",
    "HealthPolicy": "aiortu.master",
    "InvalidRequest": "aiortu.errors",
    "InvalidValue": "aiortu.errors",
    "LineSettings": "aiortu.core.serial",
    "MalformedPDU": "aiortu.errors",
    "Master": "aiortu.master",
    "MasterConfig": "aiortu.master",
    "MemoryStore": "aiortu.slave",
    "Profile": "aiortu.core.model",
    "ProfilePoller": "aiortu.master",
    "ProfileStore": "aiortu.slave",
    "Reading": "aiortu.master",
    "ModbusError": "aiortu.errors",
    "Point": "aiortu.master",
    "Poller": "aiortu.master",
    "PortError": "aiortu.errors",
    "RawPDU": "aiortu.core.pdu",
    "ReconnectPolicy": "aiortu.master",
    "Reply": "aiortu.slave",
    "Request": "aiortu.core.pdu",
    "RequestContext": "aiortu.slave",
    "Response": "aiortu.core.pdu",
    "ResponseTimeout": "aiortu.errors",
    "Sample": "aiortu.master",
    "Slave": "aiortu.slave",
    "UnitHandle": "aiortu.master",
    "UnitOffline": "aiortu.errors",
    "UnitSkipped": "aiortu.errors",
    "UnitStats": "aiortu.master",
    "gateway": "aiortu.gateway",
    "load_config": "aiortu.slave",
    "load_profile": "aiortu.core.model",
    "walk_sunspec": "aiortu.master",
    "open_master": "aiortu.master",
    "serve": "aiortu.slave",
}
"""Where each public name lives: imported on first use, so that `import aiortu` (and
the `aiortu` command's `--help`) does not pay for the whole package."""

__version__ = "0.1.0"

__all__ = (
    "AsyncDataStore",
    "Block",
    "BroadcastHandle",
    "CRCError",
    "Change",
    "ConfigError",
    "ConnectionLost",
    "DataStore",
    "Device",
    "ExceptionCode",
    "ExceptionPDU",
    "ExceptionResponse",
    "FrameError",
    "FunctionCode",
    "HealthPolicy",
    "InvalidRequest",
    "InvalidValue",
    "LineSettings",
    "MalformedPDU",
    "Master",
    "MasterConfig",
    "MemoryStore",
    "ModbusError",
    "Point",
    "Poller",
    "PortError",
    "Profile",
    "ProfilePoller",
    "ProfileStore",
    "RawPDU",
    "Reading",
    "ReconnectPolicy",
    "Reply",
    "Request",
    "RequestContext",
    "Response",
    "ResponseTimeout",
    "Sample",
    "Slave",
    "UnitHandle",
    "UnitOffline",
    "UnitSkipped",
    "UnitStats",
    "__version__",
    "gateway",
    "load_config",
    "load_profile",
    "open_master",
    "serve",
    "walk_sunspec",
)


def __getattr__(name: str) -> Any:
    module = _LAZY.get(name)
    if module is None:
        raise AttributeError(f"module 'aiortu' has no attribute {name!r}")
    value = getattr(importlib.import_module(module), name)
    globals()[name] = value
    return value


def __dir__() -> list[str]:
    return sorted({*globals(), *_LAZY})

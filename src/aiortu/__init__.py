"""aiortu: an asyncio Modbus RTU master/slave framework.

See the README and `docs/` for the guides; the names they use are re-exported here. The packages
[`aiortu.master`][aiortu.master], [`aiortu.slave`][aiortu.slave],
[`aiortu.testing`][aiortu.testing], [`aiortu.transport`][aiortu.transport],
[`aiortu.line`][aiortu.line] and [`aiortu.core`][aiortu.core] hold the rest.
"""

from __future__ import annotations

from aiortu.core.codes import ExceptionCode, FunctionCode
from aiortu.core.pdu import ExceptionPDU, RawPDU, Request, Response
from aiortu.core.timing import LineSettings
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
from aiortu.master import (
    BroadcastHandle,
    HealthPolicy,
    Master,
    Point,
    Poller,
    ReconnectPolicy,
    Sample,
    UnitHandle,
    UnitStats,
    open_master,
)
from aiortu.slave import (
    AsyncDataStore,
    Block,
    Change,
    DataStore,
    MemoryStore,
    Reply,
    RequestContext,
    Slave,
    load_config,
    serve,
)

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
    "MemoryStore",
    "ModbusError",
    "Point",
    "Poller",
    "PortError",
    "RawPDU",
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
    "load_config",
    "open_master",
    "serve",
)

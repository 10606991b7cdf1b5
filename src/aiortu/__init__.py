"""aiortu: an asyncio Modbus RTU master/slave framework.

See the README and ``docs/`` for the guides; the public names are re-exported here.
"""

from __future__ import annotations

from aiortu.core.codes import ExceptionCode, FunctionCode
from aiortu.core.timing import LineSettings
from aiortu.errors import (
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
)
from aiortu.master import Master, open_master
from aiortu.poller import Point, Poller
from aiortu.slave import Slave, serve
from aiortu.store import DataStore, MemoryStore

__version__ = "0.1.0"

__all__ = (
    "CRCError",
    "ConnectionLost",
    "DataStore",
    "ExceptionCode",
    "ExceptionResponse",
    "FrameError",
    "FunctionCode",
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
    "ResponseTimeout",
    "Slave",
    "__version__",
    "open_master",
    "serve",
)

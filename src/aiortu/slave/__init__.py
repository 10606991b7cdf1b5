"""The Modbus RTU slave: one or many unit addresses on one line, served from data stores
by handlers per function code, with routes, hooks and a device description file.

[`Slave`][aiortu.slave.Slave] takes any `anyio.abc.ByteStream`; [`serve`][aiortu.slave.serve] opens
a port or a URL first, or listens on a `tcp://` (Modbus TCP,
[`ModbusTcpServer`][aiortu.slave.ModbusTcpServer]) or `rtu+tcp://`
([`RtuOverTcpServer`][aiortu.slave.RtuOverTcpServer]) URL. See `docs/slave.md`.
"""

from __future__ import annotations

from aiortu._public import publish
from aiortu.slave._config import ConfigError, DeviceConfig, load_config, parse_config
from aiortu.slave._dispatch import TraceCallback
from aiortu.slave._handlers import (
    BUILTIN_HANDLERS,
    Answer,
    Handler,
    HandlerResult,
    Reply,
    RequestContext,
)
from aiortu.slave._profile_store import ProfileStore
from aiortu.slave._routes import RangeAccess, RangeHandler, RoutedStore
from aiortu.slave._rtu_over_tcp import RtuOverTcpServer
from aiortu.slave._serve import Server, serve
from aiortu.slave._slave import AfterHook, BeforeHook, Slave
from aiortu.slave._store import (
    AsyncDataStore,
    Block,
    Change,
    ChangeFeed,
    DataStore,
    MemoryStore,
    ServerId,
    SupportsDeviceIdentification,
    SupportsExceptionStatus,
    SupportsFifoQueues,
    SupportsFileRecords,
    SupportsServerId,
    Table,
)
from aiortu.slave._tcp_server import ModbusTcpServer, TcpServerCounters
from aiortu.slave._tls_server import ModbusTlsServer
from aiortu.slave._udp_server import ModbusUdpServer

__all__ = (
    "BUILTIN_HANDLERS",
    "AfterHook",
    "Answer",
    "AsyncDataStore",
    "BeforeHook",
    "Block",
    "Change",
    "ChangeFeed",
    "ConfigError",
    "DataStore",
    "DeviceConfig",
    "Handler",
    "HandlerResult",
    "MemoryStore",
    "ModbusTcpServer",
    "ModbusTlsServer",
    "ModbusUdpServer",
    "ProfileStore",
    "RangeAccess",
    "RangeHandler",
    "Reply",
    "RequestContext",
    "RoutedStore",
    "RtuOverTcpServer",
    "Server",
    "ServerId",
    "Slave",
    "SupportsDeviceIdentification",
    "SupportsExceptionStatus",
    "SupportsFifoQueues",
    "SupportsFileRecords",
    "SupportsServerId",
    "Table",
    "TcpServerCounters",
    "TraceCallback",
    "load_config",
    "parse_config",
    "serve",
)

publish(__name__, __all__, globals())

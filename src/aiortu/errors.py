"""The exceptions aiortu raises, and who causes each of them.

Every error aiortu raises on purpose is a [`ModbusError`][aiortu.errors.ModbusError], so one
`except` clause catches them all. Below it, the tree says who is at fault, which is what the caller
needs to decide whether to fix their code, retry, or look at the wiring:

    ModbusError                      anything aiortu raises on purpose
    ├── InvalidValue                 (the caller) a field or setting out of its allowed range
    │   └── InvalidRequest           (the caller) a request that must not be sent; nothing was sent
    ├── ExceptionResponse            (the peer)   the device answered with a Modbus exception code
    ├── ResponseTimeout              (peer or line) no valid reply in time; a TimeoutError
    │   ├── UnitOffline              (the peer)   an offline unit, failing fast: nothing sent
    │   └── UnitSkipped              (the peer)   the poller skipped an offline unit's read
    ├── FrameError                   (peer or line) bytes that are not a valid frame
    │   ├── CRCError                 (the line)   the CRC does not match: noise, wrong settings
    │   ├── LRCError                 (the line)   an ASCII frame's LRC does not match
    │   └── MalformedPDU             (the peer)   the CRC is good but the content breaks the spec
    ├── ConnectionLost               (the line)   the byte stream closed or failed under us
    ├── ConfigError                  (the caller) a device description file is wrong
    └── PortError                    (the environment) a port that cannot be opened as asked
        ├── PortNotFound             no such device or host
        ├── PortBusy                 another program holds the port
        ├── PortPermissionDenied     the user may not open the port
        └── UnsupportedSettings      the port or the OS refuses the line settings

A Modbus exception response is not a transport failure:
[`ExceptionResponse`][aiortu.errors.ExceptionResponse] carries the device's
[`code`][aiortu.errors.ExceptionResponse], a value the caller can inspect and act on, while the
other branches say the exchange itself failed.

The classes are defined in `aiortu.core.errors`, because the sans-IO core raises
them too and the core imports nothing from the rest of the package; this module is where
users import them from.
"""

from __future__ import annotations

from aiortu._public import publish
from aiortu.core.errors import (
    ConfigError,
    ConnectionLost,
    CRCError,
    ExceptionResponse,
    FrameError,
    InvalidRequest,
    InvalidValue,
    LRCError,
    MalformedPDU,
    ModbusError,
    PortBusy,
    PortError,
    PortNotFound,
    PortPermissionDenied,
    ResponseTimeout,
    UnitOffline,
    UnitSkipped,
    UnsupportedSettings,
)

__all__ = (
    "CRCError",
    "ConfigError",
    "ConnectionLost",
    "ExceptionResponse",
    "FrameError",
    "InvalidValue",
    "InvalidRequest",
    "LRCError",
    "MalformedPDU",
    "ModbusError",
    "PortBusy",
    "PortError",
    "PortNotFound",
    "PortPermissionDenied",
    "ResponseTimeout",
    "UnitOffline",
    "UnitSkipped",
    "UnsupportedSettings",
)

publish(__name__, __all__, globals())

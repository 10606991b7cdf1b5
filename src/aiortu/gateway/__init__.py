"""The line server: network clients share one serial line through its master's engine.

[`gateway`][aiortu.gateway.gateway] opens a line (or takes a running
[`Master`][aiortu.master.Master]), or several lines routed by unit ranges
([`GatewayLine`][aiortu.gateway.GatewayLine]), listens on `tcp://` (Modbus TCP), `rtu+tcp://`
(RTU frames over TCP), `tls://` (Modbus/TCP Security) and `unix:PATH` URLs and serves every
client through the one engine of its unit's line; [`Gateway`][aiortu.gateway.Gateway] is the
server itself. Requests are forwarded at frame level: a function code aiortu knows is sent as
its request class, so the engine checks the reply against the request (a register read as its
bytes, [`RawRegisterRead`][aiortu.core.pdu.RawRegisterRead], with the same checks); any other
code (user-defined ones included) goes out byte for byte. See `docs/gateway.md`.
"""

from __future__ import annotations

import sys
import types
from typing import Any

from aiortu._public import publish
from aiortu.gateway._lines import GatewayLine
from aiortu.gateway._open import (
    DEFAULT_RETRIES,
    DEFAULT_TIMEOUT,
    REPEATED_CODES,
    Listen,
    gateway,
)
from aiortu.gateway._server import (
    DEFAULT_IDLE_TIMEOUT,
    DEFAULT_MAX_CONNECTIONS,
    DEFAULT_MAX_IN_FLIGHT,
    Gateway,
    GatewayCounters,
)
from aiortu.gateway._stats import (
    DEFAULT_CLIENT_STATISTICS,
    OTHER_CLIENTS,
    ClientStatistics,
    GatewayStatistics,
    LineStatistics,
    UnitStatistics,
)

__all__ = (
    "DEFAULT_CLIENT_STATISTICS",
    "OTHER_CLIENTS",
    "REPEATED_CODES",
    "ClientStatistics",
    "DEFAULT_IDLE_TIMEOUT",
    "DEFAULT_MAX_CONNECTIONS",
    "DEFAULT_MAX_IN_FLIGHT",
    "DEFAULT_RETRIES",
    "DEFAULT_TIMEOUT",
    "Gateway",
    "GatewayCounters",
    "GatewayLine",
    "GatewayStatistics",
    "LineStatistics",
    "Listen",
    "UnitStatistics",
    "gateway",
)


class _CallableModule(types.ModuleType):
    """This package, callable as [`gateway`][aiortu.gateway.gateway]: `aiortu.gateway(...)`
    names the function, and stays callable once `import aiortu.gateway` made it the package."""

    def __call__(self, *args: Any, **kwargs: Any) -> Any:
        return gateway(*args, **kwargs)


sys.modules[__name__].__class__ = _CallableModule

publish(__name__, __all__, globals())

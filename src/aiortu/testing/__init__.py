"""Test benches for Modbus RTU: virtual serial lines, in memory and over pseudo-terminals.

- [`VirtualBus`][aiortu.testing.VirtualBus] / [`virtual_pair`][aiortu.testing.virtual_pair]:
  in-memory RS-485 buses of `anyio.abc.ByteStream` endpoints, with baud-rate pacing, adapter
  chunking, collisions and a trace of the wire.
- [`PtyBus`][aiortu.testing.PtyBus]: the same over pseudo-terminals, so that any program can open a
  port.
- [`MockLine`][aiortu.testing.MockLine]: a fake line at the level of requests, answered by a
  function: a [`Master`][aiortu.master.Master] on it needs no bytes and no timing.
- [`FaultPlan`][aiortu.testing.FaultPlan] / [`FaultInjector`][aiortu.testing.FaultInjector]:
  reproducible noise on a line.
- The pytest fixtures in [`aiortu.testing.pytest_plugin`][aiortu.testing.pytest_plugin] (loaded
  automatically).

See `docs/testing.md`.
"""

from __future__ import annotations

from aiortu._public import publish
from aiortu.testing._faults import FaultedChunk, FaultInjector, FaultPlan, FaultStats
from aiortu.testing._mock_line import MockHandler, MockLine
from aiortu.testing._pty_bus import PtyBus, make_raw
from aiortu.testing._virtual_bus import TraceEntry, VirtualBus, VirtualEndpoint, virtual_pair

__all__ = (
    "FaultInjector",
    "FaultPlan",
    "FaultStats",
    "FaultedChunk",
    "MockHandler",
    "MockLine",
    "PtyBus",
    "TraceEntry",
    "VirtualBus",
    "VirtualEndpoint",
    "make_raw",
    "virtual_pair",
)

publish(__name__, __all__, globals())

"""One serial line: a byte stream pumped through the receiver with a clock.

The master and the slave are built on [`Link`][aiortu.line.Link]; users rarely need it directly,
except to watch a line (`role=Role.MONITOR`). [`WakeTimer`][aiortu.line.WakeTimer] ends a wait at
its time rather than on the event loop's next whole millisecond.
[`native_waits`][aiortu.line.native_waits] gives the running backend's cheapest wake-ups and
callbacks (the asyncio loop's own, anyio's elsewhere), [`loop_clock`][aiortu.line.loop_clock] its
cheapest clock.
"""

from __future__ import annotations

from aiortu._public import publish
from aiortu.line._link import Link, LinkEvent, LinkListener
from aiortu.line._native import NativeWaits, Waiter, loop_clock, native_waits
from aiortu.line._push_reader import ReplyTap
from aiortu.line._wake_timer import WakeTimer, create_wake_timer

__all__ = (
    "Link",
    "LinkEvent",
    "LinkListener",
    "NativeWaits",
    "ReplyTap",
    "WakeTimer",
    "Waiter",
    "create_wake_timer",
    "loop_clock",
    "native_waits",
)

publish(__name__, __all__, globals())

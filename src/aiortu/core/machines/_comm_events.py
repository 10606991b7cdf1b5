"""The comm event log and event counter of a serial line slave (0B and 0C).

The spec defines one event byte per thing that happened on the slave's serial port,
kept newest first, at most 64 of them:

=====================  ==========================================================
receive event          bit 7 set; bit 1 communication error, bit 4 character
                       overrun, bit 5 in listen-only mode, bit 6 broadcast received
send event             bit 6 set, bit 7 clear; bit 0 read exception sent (01..03),
                       bit 1 server abort exception sent (04), bit 2 server busy
                       exception sent (05, 06), bit 3 program NAK sent (07),
                       bit 4 write timeout, bit 5 in listen-only mode
entered listen-only    0x04
communication restart  0x00
=====================  ==========================================================

The event counter counts successful message completions: not exception responses, and
not the requests that fetch the counter or the log (0B, 0C), so that a master polling
the counter sees it move only for other traffic.
"""

from __future__ import annotations

from collections import deque
from typing import Final

__all__ = (
    "EVENT_ENTERED_LISTEN_ONLY",
    "EVENT_RESTART",
    "MAX_EVENTS",
    "CommEventLog",
    "receive_event",
    "send_event",
)

MAX_EVENTS: Final = 64
"""The most event bytes the log keeps (and Get Comm Event Log returns)."""

EVENT_RESTART: Final = 0x00
"""The event byte of a communication restart (08 sub-function 01)."""

EVENT_ENTERED_LISTEN_ONLY: Final = 0x04
"""The event byte of entering listen-only mode (08 sub-function 04)."""

_RECEIVE: Final = 0x80
_RECEIVE_COMMUNICATION_ERROR: Final = 0x02
_RECEIVE_OVERRUN: Final = 0x10
_LISTEN_ONLY: Final = 0x20
_RECEIVE_BROADCAST: Final = 0x40
_SEND: Final = 0x40
_SEND_BITS_BY_EXCEPTION: Final = {1: 0x01, 2: 0x01, 3: 0x01, 4: 0x02, 5: 0x04, 6: 0x04, 7: 0x08}


def receive_event(
    *,
    broadcast: bool = False,
    listen_only: bool = False,
    overrun: bool = False,
    communication_error: bool = False,
) -> int:
    """The event byte the spec stores when a request arrives (before it is processed)."""
    event = _RECEIVE
    if communication_error:
        event |= _RECEIVE_COMMUNICATION_ERROR
    if overrun:
        event |= _RECEIVE_OVERRUN
    if listen_only:
        event |= _LISTEN_ONLY
    if broadcast:
        event |= _RECEIVE_BROADCAST
    return event


def send_event(exception_code: int | None = None, *, listen_only: bool = False) -> int:
    """The event byte the spec stores when a request has been processed.

    `exception_code` is the exception answered, if any (`None` for a normal reply or
    none at all).
    """
    event = _SEND
    if exception_code is not None:
        event |= _SEND_BITS_BY_EXCEPTION.get(exception_code, 0)
    if listen_only:
        event |= _LISTEN_ONLY
    return event


class CommEventLog:
    """The event bytes (newest first, at most 64) and the comm event counter of a slave."""

    __slots__ = ("_events", "event_count")

    def __init__(self) -> None:
        self._events: deque[int] = deque(maxlen=MAX_EVENTS)
        self.event_count = 0
        """Successful message completions since the start, a restart or a clear (0B)."""

    def add(self, event: int) -> None:
        """Store one event byte; the oldest is dropped beyond 64."""
        self._events.appendleft(event & 0xFF)

    def completed(self) -> None:
        """Count one successful message completion (wraps at 65536)."""
        self.event_count = (self.event_count + 1) & 0xFFFF

    def events(self) -> bytes:
        """The event bytes, newest first."""
        return bytes(self._events)

    def clear_events(self) -> None:
        """Forget the event bytes (a restart with 0xFF00)."""
        self._events.clear()

    def __len__(self) -> int:
        return len(self._events)

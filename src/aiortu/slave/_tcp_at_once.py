"""The Modbus TCP server's answer-at-once: a request answered in the read callback that got it.

A request normally goes the general route: the connection's task wakes, reads the bytes, frames
them and takes each request through `ModbusTcpServer._respond` (the lock, the machine, the
handler, the hooks), then writes the reply. Where the connection is a
[`PushServerStream`][aiortu.transport.PushServerStream] (asyncio), its read callback offers each
chunk that comes while the task waits with nothing unread, and while the client reads its
replies, to this module's tap, which answers it at once, with no task wake-up, when:

- the chunk is exactly one well-formed MBAP request, and the connection's framing holds nothing
  of an earlier one (it comes first, through the general route);
- the client's role may send it (Modbus/TCP Security; a refusal is the general route's to log);
- the slave's answer-at-once allows it and its fast path answers (`AnswerAtOnce.may_answer`
  and `AnswerAtOnce.answer` in `_answer_at_once.py`, the one predicate of every carrier: a
  register or bit read or a register write to a `MemoryStore`, the machine IDLE, so that no
  request of another connection is under way, and not listen-only, no trace, no hooks).

Anything else goes to the task as usual. `tests/slave/test_tcp_at_once.py` runs random request
sequences with the shortcut on and off and compares the replies, the stores and the counters.
"""

from __future__ import annotations

import asyncio
from collections.abc import Callable, Mapping
from typing import Protocol

from aiortu.core.mbap import Adu, decode_adu, encode_adu
from aiortu.errors import FrameError
from aiortu.slave._answer_at_once import AnswerAtOnce
from aiortu.transport import Framing, PushServerStream

__all__ = ("ConnectionTap", "Permits")

Permits = Callable[[Adu], bool]
"""Whether a connection's client may send a request (Modbus/TCP Security's rules for its
role); a request it may not takes the general route, which refuses it."""


class _Counters(Protocol):
    requests: int


class _Server(Protocol):
    """What the tap reads of its server, each time (a user may change them)."""

    @property
    def counters(self) -> _Counters: ...
    @property
    def unit_aliases(self) -> Mapping[int, int]: ...


class ConnectionTap:
    """One connection's tap (see the module docstring): `stream` with its `framing` and its
    client's `permits` (None: any request), answered by the server's `at_once`.
    `last_answer` is the loop time of the last request answered, for the idle timeout."""

    __slots__ = (
        "_at_once",
        "_framing",
        "_loop",
        "_permits",
        "_server",
        "_stream",
        "last_answer",
    )

    def __init__(
        self,
        at_once: AnswerAtOnce,
        server: _Server,
        stream: PushServerStream,
        framing: Framing,
        permits: Permits | None,
    ) -> None:
        self._at_once = at_once
        self._server = server
        self._stream = stream
        self._framing = framing
        self._permits = permits
        self._loop = asyncio.get_running_loop()
        self.last_answer = -1.0
        """When the last request was answered at once (the loop's clock; -1: never)."""

    def __call__(self, chunk: bytes) -> bool:
        """Answer `chunk` at once and return True, or return False with nothing done."""
        if self._framing.buffered:
            return False  # part of an earlier request is held: it comes first
        try:
            adu = decode_adu(chunk)
        except FrameError:
            return False  # not exactly one well-formed ADU: the framing takes it
        permits = self._permits
        if permits is not None and not permits(adu):
            return False
        server = self._server
        stream = self._stream

        def send(unit: int, reply: bytes) -> bool:
            written = stream.write_now(encode_adu(adu.transaction_id, adu.unit, reply))
            assert written, "the stream offers a chunk only while it can write"
            return True

        unit = server.unit_aliases.get(adu.unit, adu.unit)
        if self._at_once.answer(unit, adu.pdu, send) is not True:
            return False  # not answered (a reply left waiting cannot happen: send sends)
        server.counters.requests += 1
        self.last_answer = self._loop.time()
        return True

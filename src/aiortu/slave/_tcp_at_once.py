"""The Modbus TCP server's answer-at-once: a request answered in the read callback that got it.

A request normally goes the general route: the connection's task wakes, reads the bytes, frames
them and takes each request through `ModbusTcpServer._respond` (the lock, the machine, the
handler, the hooks), then writes the reply. Where the connection is a
[`PushServerStream`][aiortu.transport.PushServerStream] (asyncio), its read callback offers each
chunk that comes while the task waits with nothing unread to this module's tap, which answers it
at once, with no task wake-up, where `TcpAnswerAtOnce.may_answer` (the one predicate: every
condition is a named line there) allows it:

- the chunk is exactly one well-formed MBAP request, nothing of an earlier one held;
- the request's unit, function code and store have a fast path of the slave's answer-at-once
  (`FAST_PATHS` in `_answer_at_once.py`: register and bit reads, register
  writes, on the built-in `MemoryStore`), and its role may send it (Modbus/TCP Security);
- nothing else is under way: the machine is IDLE (no request of another connection holds the
  server) and not in listen-only mode, and no trace or hook wants to see it.

A fast path gives up (`None`) before changing anything on anything it does not answer in full;
the chunk then goes to the task as usual. A normal reply is counted in one step
([`answered_at_once`][aiortu.core.machines.SlaveMachine.answered_at_once]), an exception from the
store in the machine's steps, with the same counters and log entries as the general route.
`tests/slave/test_tcp_at_once.py` runs random request sequences with the shortcut on and off and
compares the replies, the stores and the counters.
"""

from __future__ import annotations

import asyncio
from collections.abc import Callable, Mapping, Sized
from typing import Protocol

from aiortu.core.machines import SlaveMachine, SlaveState
from aiortu.core.mbap import Adu, decode_adu
from aiortu.core.model import AsyncDataStore, DataStore
from aiortu.core.pdu import encode_exception
from aiortu.errors import ExceptionResponse, FrameError
from aiortu.slave._answer_at_once import FastPath, fast_paths_for, memory_stores
from aiortu.slave._handlers import Handler
from aiortu.slave._store import MemoryStore
from aiortu.transport import Framing, PushServerStream

__all__ = ("ConnectionTap", "Permits", "TcpAnswerAtOnce")

Permits = Callable[[Adu], bool]
"""Whether a connection's client may send a request (Modbus/TCP Security's rules for its
role); a request it may not takes the general route, which refuses it."""

_MBAP_HEADER = 7


class _Counters(Protocol):
    requests: int


class _Server(Protocol):
    """What the shortcut reads of its server, each time (a user may change them)."""

    @property
    def machine(self) -> SlaveMachine: ...
    @property
    def counters(self) -> _Counters: ...
    @property
    def unit_aliases(self) -> Mapping[int, int]: ...
    @property
    def trace(self) -> Callable[[str, bytes], object] | None: ...


class TcpAnswerAtOnce:
    """The Modbus TCP server's shortcut (see the module docstring), for every connection of
    `server`: the hook lists `before` and `after` are the server's own objects (the predicate
    sees every change), and `encode` is its reply framing's."""

    def __init__(
        self,
        server: _Server,
        *,
        before: Sized,
        after: Sized,
        encode: Callable[[Adu, bytes], bytes],
    ) -> None:
        self._server = server
        self._before = before
        self._after = after
        self._encode = encode
        self._fast_paths: dict[int, FastPath] = {}
        self._stores: dict[int, MemoryStore] = {}
        self.enabled = True
        """Off, every request takes the general route (the differential test compares)."""
        self.answered = 0
        """How many requests were answered at once."""

    def configure(
        self,
        handlers: Mapping[int, Handler],
        stores: Mapping[int, DataStore | AsyncDataStore],
    ) -> None:
        """Take the server's `handlers` and `stores` (routes applied): the fast paths that stand
        in for a built-in handler, the units whose store they can serve."""
        self._fast_paths = fast_paths_for(handlers)
        self._stores = memory_stores(stores)

    def may_answer(self, adu: Adu, unit: int, framing: Framing, permits: Permits | None) -> bool:
        """Whether `adu`, a whole request for `unit` (aliases applied), may be answered at once
        on a connection with `framing` and `permits`. Every condition of the shortcut is here."""
        machine = self._server.machine
        return (
            # Switched off: the general route only (the differential test compares both).
            self.enabled
            # Part of an earlier request is held: it comes first, through the general route.
            and not framing.buffered
            # No request is under way (a handler of another connection awaiting): the general
            # route takes the machine out of IDLE, under its lock, before its first await.
            and machine.state is SlaveState.IDLE
            # Listen-only mode: requests are monitored, never executed nor answered.
            and not machine.listen_only
            # A trace callback sees every request and reply, from the general route.
            and self._server.trace is None
            # Hooks run around every request: only the general route calls them.
            and not (self._before or self._after)
            # The built-in handler serves this function code, and has a fast path.
            and adu.pdu[0] in self._fast_paths
            # A unit of ours (never a broadcast: unit 0 not aliased) on the built-in
            # MemoryStore.
            and unit in self._stores
            # The client's role may send it (a refusal is the general route's to log).
            and (permits is None or permits(adu))
        )

    def answer(self, adu: Adu, framing: Framing, permits: Permits | None) -> bytes | None:
        """The reply ADU to `adu` if `may_answer` allows it and its fast path answers; None
        means nothing was done or counted: the general route takes it."""
        server = self._server
        unit = server.unit_aliases.get(adu.unit, adu.unit)
        if not self.may_answer(adu, unit, framing, permits):
            return None
        code = adu.pdu[0]
        machine = server.machine
        try:
            reply = self._fast_paths[code](self._stores[unit], adu.pdu)
        except ExceptionResponse as error:
            machine.frame_received(unit, code)
            machine.check_request(supported=True)
            machine.processing_failed(error.code)
            machine.reply_sent()
            reply = encode_exception(code, error.code)
        else:
            if reply is None:
                return None
            machine.answered_at_once(unit, code)
        self.answered += 1
        server.counters.requests += 1
        return self._encode(adu, reply)

    def tap(
        self, stream: PushServerStream, framing: Framing, permits: Permits | None
    ) -> ConnectionTap:
        """A tap for one connection: `stream`, with its `framing` and its client's `permits`."""
        return ConnectionTap(self, stream, framing, permits)


class ConnectionTap:
    """One connection's tap: a chunk that is one whole request, answered at once (see the
    module docstring); `last_answer` is the loop time of the last one, for the idle timeout."""

    __slots__ = ("_at_once", "_framing", "_loop", "_permits", "_stream", "last_answer")

    def __init__(
        self,
        at_once: TcpAnswerAtOnce,
        stream: PushServerStream,
        framing: Framing,
        permits: Permits | None,
    ) -> None:
        self._at_once = at_once
        self._stream = stream
        self._framing = framing
        self._permits = permits
        self._loop = asyncio.get_running_loop()
        self.last_answer = -1.0
        """When the last request was answered at once (the loop's clock; -1: never)."""

    def __call__(self, chunk: bytes) -> bool:
        if len(chunk) <= _MBAP_HEADER or int.from_bytes(chunk[4:6], "big") != len(chunk) - 6:
            return False  # not exactly one ADU: the framing takes it
        try:
            adu = decode_adu(chunk)
        except FrameError:
            return False  # a malformed header: the general route closes the connection
        reply = self._at_once.answer(adu, self._framing, self._permits)
        if reply is None:
            return False
        written = self._stream.write_now(reply)
        assert written, "the stream offers a chunk only while it can write"
        self.last_answer = self._loop.time()
        return True

"""The slave's answer-at-once: the commonest requests answered where they arrive.

A request normally goes the general route: on a serial line the link hands a
[`FrameReceived`][aiortu.core.rtu.FrameReceived] to the slave's listener, the listener queues
it, and the serve loop drives the table machine
([`SlaveMachine`][aiortu.core.machines.SlaveMachine]) through the handler, the hooks and
the reply; a Modbus UDP server's datagram waits for the server's task, which does the same.
That costs a task wake-up per request.

This module is the one shortcut around it. Where `AnswerAtOnce.may_answer` (the
one predicate: every condition is a named line there) allows it, a request is answered
in the callback that got it, with no task wake-up and no request or response object:

- from the link's read callback, for a whole 8-byte request (function codes 01 to 06)
  that arrived as one chunk on a stream that pushes its bytes (the serial port; see
  `Link.expect_requests`), and from the link's listener, for any other request while
  nothing is pending (`LineAnswerAtOnce`, the shortcut bound to a slave's link);
- from the event loop's datagram callback of a Modbus UDP server
  ([`ModbusUdpServer`][aiortu.slave.ModbusUdpServer], through
  [`DatagramServer`][aiortu.transport.DatagramServer]), for any request while none waits for
  the server's task.

A *fast path* (`FAST_PATHS`) maps the request's bytes to the reply's bytes for the built-in
[`MemoryStore`][aiortu.slave.MemoryStore]. It gives up (`None`) on anything but a well-formed
request and a store that answers, before changing anything; the request then takes the general
route, so the answers are the same either way. A normal reply that goes out at once (frame gap 0, or
already kept) is counted in one step
([`answered_at_once`][aiortu.core.machines.SlaveMachine.answered_at_once], the same counters
and log entries as the table's four steps); otherwise the machine is driven step by step and a reply
that must wait for the frame gap is left to the serve loop as a `Taken`.

`tests/slave/test_fast_path_differential.py` (serial lines) and
`tests/slave/test_udp_at_once.py` (Modbus UDP) run random request sequences with the shortcut on
and off and compare the bytes on the wire, the stores, the counters and the event log.
"""

from __future__ import annotations

import struct
from collections.abc import Callable, Mapping, Sized
from dataclasses import dataclass
from typing import Final

from aiortu.core.codes import FunctionCode
from aiortu.core.machines import SlaveMachine, SlaveState
from aiortu.core.model import AsyncDataStore, DataStore, Table
from aiortu.core.pdu import (
    MAX_READ_BITS,
    MAX_READ_REGISTERS,
    MAX_WRITE_REGISTERS,
    encode_exception,
    pack_bits,
)
from aiortu.core.rtu import FrameReceived, encode_frame
from aiortu.errors import ExceptionResponse
from aiortu.line import Link, LinkEvent
from aiortu.slave._handlers import BUILTIN_HANDLERS, Handler
from aiortu.slave._store import MemoryStore

__all__ = ("FAST_PATHS", "AnswerAtOnce", "FastPath", "LineAnswerAtOnce", "Send", "Taken")


@dataclass(slots=True)
class Taken:
    """A request answered at once whose `reply` PDU must wait for the frame gap: the
    machine has counted it (FORMATTING_REPLY or FORMATTING_ERROR); the serve loop sends it."""

    frame: bytes
    reply: bytes


Send = Callable[[int, bytes], bool]
"""`send(unit, reply)`: send the reply PDU for `unit` now if the carrier can (True), else
nothing (False: the reply must wait)."""


class AnswerAtOnce:
    """The server's shortcut (see the module docstring): its one predicate and its answer, for
    any carrier of requests.

    `machine` is the server's state machine; `pending` what waits for the general route (the
    serve loop's queue, the datagrams waiting for the server's task), `before` and `after` its
    hook lists (the same objects: the predicate sees every change).
    """

    __slots__ = (
        "_after",
        "_before",
        "_fast_paths",
        "_machine",
        "_pending",
        "_stores",
        "answered",
        "enabled",
        "trace_set",
    )

    def __init__(
        self,
        machine: SlaveMachine,
        pending: Sized,
        *,
        before: Sized,
        after: Sized,
    ) -> None:
        self._machine = machine
        self._pending = pending
        self._before = before
        self._after = after
        self._fast_paths: dict[int, FastPath] = {}
        self._stores: dict[int, MemoryStore] = {}
        self.enabled = True
        """Off, every request takes the general route (the differential tests compare)."""
        self.trace_set = False
        """Whether the server has a trace callback."""
        self.answered = 0
        """How many requests were answered at once."""

    def may_answer(self, unit: int, function_code: int) -> bool:
        """Whether a request with `function_code` for `unit` (after the server's unit aliases),
        well carried (a good CRC, a well-formed ADU), may be answered at once.

        Every condition of the shortcut is here; anything else takes the general route.
        """
        machine = self._machine
        return (
            # Switched off: the general route only (the differential tests compare both).
            self.enabled
            # Requests are answered in order: one left to the general route goes first.
            and not self._pending
            # A request under way (a handler awaiting, a reply waiting) finishes first.
            and machine.state is SlaveState.IDLE
            # Listen-only mode: requests are monitored, never executed nor answered.
            and not machine.listen_only
            # A trace callback sees every frame received and sent, from the general route.
            and not self.trace_set
            # Hooks run around every request: only the general route calls them.
            and not (self._before or self._after)
            # The built-in handler serves this function code (not a user's), and has a
            # fast path.
            and function_code in self._fast_paths
            # A unit of ours whose store is the built-in MemoryStore (not routed, not a
            # subclass, not async). Never a broadcast: it runs once per store, unanswered.
            and unit in self._stores
        )

    def configure(
        self,
        handlers: Mapping[int, Handler],
        stores: Mapping[int, DataStore | AsyncDataStore],
    ) -> None:
        """Take the server's `handlers` (by function code) and `stores` (by unit, routes
        applied): the fast paths that stand in for a built-in handler, the units whose
        store they can serve."""
        self._fast_paths = {
            code: fast
            for code, (handler, fast) in FAST_PATHS.items()
            if handlers.get(code) is handler
        }
        self._stores = {unit: store for unit, store in stores.items() if type(store) is MemoryStore}

    def answer(self, unit: int, pdu: bytes, send: Send) -> bytes | bool:
        """Answer the request `pdu` for `unit` if `may_answer` allows it and its fast path
        answers, the reply sent with `send`.

        `False`: nothing was done or counted, the general route takes it. `True`: answered
        and sent. Bytes: answered, counted up to FORMATTING_REPLY or FORMATTING_ERROR, and
        this reply PDU must wait (`send` could not send it now).
        """
        function_code = pdu[0]
        if not self.may_answer(unit, function_code):
            return False
        try:
            reply = self._fast_paths[function_code](self._stores[unit], pdu)
        except ExceptionResponse as error:
            self.answered += 1
            return self._reply_failed(unit, function_code, error.code, send)
        if reply is None:
            return False
        self.answered += 1
        machine = self._machine
        if send(unit, reply):
            machine.answered_at_once(unit, function_code)
            return True
        machine.frame_received(unit, function_code)
        machine.check_request(supported=True)
        machine.processed()
        return reply

    def _reply_failed(self, unit: int, function_code: int, code: int, send: Send) -> bytes | bool:
        """The fast path raised exception `code`, before changing anything."""
        machine = self._machine
        machine.frame_received(unit, function_code)
        machine.check_request(supported=True)
        machine.processing_failed(code)
        reply = encode_exception(function_code, code)
        if not send(unit, reply):
            return reply
        machine.reply_sent()
        return True


class LineAnswerAtOnce(AnswerAtOnce):
    """The shortcut on a serial line, bound to one slave's link.

    `queue` is the serve loop's queue; `serve_later` hands a `Taken` to the serve loop;
    `to_listener` hands a whole request the shortcut did not answer to the slave's listener,
    as the receiver would have, past the listener's own try of the shortcut (the predicate
    and the fast path run once per request).
    """

    __slots__ = ("_link", "_serve_later", "_to_listener")

    def __init__(
        self,
        machine: SlaveMachine,
        link: Link,
        queue: Sized,
        *,
        before: Sized,
        after: Sized,
        serve_later: Callable[[Taken], None],
        to_listener: Callable[[LinkEvent], None],
    ) -> None:
        super().__init__(machine, queue, before=before, after=after)
        self._link = link
        self._serve_later = serve_later
        self._to_listener = to_listener

    def attach(self) -> None:
        """Have the link hand whole 8-byte requests to `on_whole_request`."""
        if self.enabled:
            self._link.expect_requests(EIGHT_BYTE_REQUESTS, 8, self.on_whole_request)

    def detach(self) -> None:
        """Undo `attach`."""
        self._link.expect_requests((), 8, None)

    def on_whole_request(self, frame: bytes, end: float) -> None:
        """The link's read callback got `frame`, a whole request with a good CRC ending at
        `end`: answer it, or hand it to the listener as the receiver would have."""
        if not self.answer_frame(frame):
            start = end - (len(frame) - 1) * self._link.char_time
            self._to_listener(FrameReceived(frame, start, end))

    def answer_frame(self, frame: bytes) -> bool:
        """Answer the request `frame` at once where `answer` does; a reply that must wait for
        the frame gap goes to the serve loop. `False`: the general route takes it."""
        done = self.answer(frame[0], frame[1:-2], self._send_now)
        if type(done) is bytes:
            self._serve_later(Taken(frame, done))
            return True
        return done is True

    def _send_now(self, unit: int, reply: bytes) -> bool:
        return self._link.send_now(encode_frame(unit, reply)) is not None


# -- the fast paths for the built-in MemoryStore -------------------------------------------

FastPath = Callable[[MemoryStore, bytes], bytes | None]
"""`fast(store, pdu)`: the reply PDU, or `None` to leave the request to its handler.

It raises [`ExceptionResponse`][aiortu.errors.ExceptionResponse] only where the store does (an
unmapped address, a read-only range), before anything is written."""

_ADDRESS_SPACE = 0x10000
_HEADER = struct.Struct(">HH")
_WRITE_HEADER = struct.Struct(">HHB")
_WORDS = [struct.Struct(f">{count}H") for count in range(MAX_READ_REGISTERS + 1)]


def _fast_read_registers(table: Table) -> FastPath:
    def read(store: MemoryStore, pdu: bytes) -> bytes | None:
        if len(pdu) != 5:
            return None
        address, count = _HEADER.unpack_from(pdu, 1)
        if not 0 < count <= MAX_READ_REGISTERS or address + count > _ADDRESS_SPACE:
            return None
        values = store.read(table, address, count)
        try:
            packed: bytes = _WORDS[count].pack(*values)
        except struct.error:
            return None  # a value the application put out of range: the handler answers 04
        return bytes((pdu[0], 2 * count)) + packed

    return read


def _fast_read_bits(table: Table) -> FastPath:
    def read(store: MemoryStore, pdu: bytes) -> bytes | None:
        if len(pdu) != 5:
            return None
        address, count = _HEADER.unpack_from(pdu, 1)
        if not 0 < count <= MAX_READ_BITS or address + count > _ADDRESS_SPACE:
            return None
        packed = pack_bits(map(bool, store.read(table, address, count)))
        return bytes((pdu[0], len(packed))) + packed

    return read


def _fast_write_register(store: MemoryStore, pdu: bytes) -> bytes | None:
    if len(pdu) != 5:
        return None
    address, value = _HEADER.unpack_from(pdu, 1)
    store.write(Table.HOLDING_REGISTERS, address, (value,))
    return pdu  # the reply echoes the request


def _fast_write_registers(store: MemoryStore, pdu: bytes) -> bytes | None:
    if len(pdu) < 8:
        return None
    address, count, byte_count = _WRITE_HEADER.unpack_from(pdu, 1)
    if (
        not 0 < count <= MAX_WRITE_REGISTERS
        or byte_count != 2 * count
        or len(pdu) != 6 + byte_count
        or address + count > _ADDRESS_SPACE
    ):
        return None
    store.write(Table.HOLDING_REGISTERS, address, _WORDS[count].unpack_from(pdu, 6))
    return pdu[:5]


def _with_builtin(code: FunctionCode, fast: FastPath) -> tuple[Handler, FastPath]:
    return BUILTIN_HANDLERS[code], fast


FAST_PATHS: Final[Mapping[int, tuple[Handler, FastPath]]] = {
    FunctionCode.READ_COILS: _with_builtin(FunctionCode.READ_COILS, _fast_read_bits(Table.COILS)),
    FunctionCode.READ_DISCRETE_INPUTS: _with_builtin(
        FunctionCode.READ_DISCRETE_INPUTS, _fast_read_bits(Table.DISCRETE_INPUTS)
    ),
    FunctionCode.READ_HOLDING_REGISTERS: _with_builtin(
        FunctionCode.READ_HOLDING_REGISTERS, _fast_read_registers(Table.HOLDING_REGISTERS)
    ),
    FunctionCode.READ_INPUT_REGISTERS: _with_builtin(
        FunctionCode.READ_INPUT_REGISTERS, _fast_read_registers(Table.INPUT_REGISTERS)
    ),
    FunctionCode.WRITE_SINGLE_REGISTER: _with_builtin(
        FunctionCode.WRITE_SINGLE_REGISTER, _fast_write_register
    ),
    FunctionCode.WRITE_MULTIPLE_REGISTERS: _with_builtin(
        FunctionCode.WRITE_MULTIPLE_REGISTERS, _fast_write_registers
    ),
}
"""The fast path of each function code that has one, with the built-in handler it stands
in for (it runs only while that handler serves the code)."""

EIGHT_BYTE_REQUESTS: Final = frozenset(FAST_PATHS) & frozenset(range(0x01, 0x07))
"""Fast paths whose requests are always 8 bytes (01 to 06): the link hands those over
from its read callback."""

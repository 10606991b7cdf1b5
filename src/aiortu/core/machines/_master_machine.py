"""The master's state machine, written as a table: one transaction at a time, sans-IO.

The machine follows the master diagram of the serial line spec:

    IDLE                nothing in flight          -- a unicast sent -->      WAITING_REPLY
                                                   -- a broadcast sent -->    WAITING_TURNAROUND
    WAITING_TURNAROUND  slaves execute a broadcast -- the delay is over -->   IDLE
    WAITING_REPLY       the response timeout runs  -- a frame -->             PROCESSING_REPLY
                                                   -- bad bytes, timeout -->  PROCESSING_ERROR
    PROCESSING_REPLY    does the frame answer us?  -- yes -->                 IDLE
                                                   -- stale, other unit -->   WAITING_REPLY
                                                   -- an exception reply -->  PROCESSING_ERROR
                                                   -- ours, misshapen -->     PROCESSING_ERROR
    PROCESSING_ERROR    retry, give up, or go on   -- retry, give up -->      IDLE
                        waiting                    -- a frame error noted --> WAITING_REPLY
                                                   -- stale bad bytes -->     WAITING_REPLY

`TRANSITIONS` is that diagram as data: `(state, event) ->
(next state, action)`. A pair missing from it is a bug and raises
[`MasterMachineError`][aiortu.core.machines.MasterMachineError], never a silent no-op. The
documentation draws its diagram from the same table.

The machine owns the decisions of a transaction; the async master only moves bytes and
sleeps until [`MasterMachine.deadline`][aiortu.core.machines.MasterMachine.deadline]:

* The response timeout runs from the end of transmission (the time the caller passes to
  [`MasterMachine.sent`][aiortu.core.machines.MasterMachine.sent]), per attempt.
* A frame answers the request only when it began no sooner than the request could have
  been received and processed
  ([`Transaction.earliest_reply`][aiortu.core.machines.Transaction.earliest_reply];
  older frames are stale), comes from the unit asked, carries the request's function code
  or its exception form, decodes, and passes `request.check_response`. A stale frame, or
  one from another unit or with another function code, is skipped and the wait goes on:
  on a multi-drop line other units talk too. A frame from the unit asked with the
  request's function code that does not decode or does not answer the request (a byte
  count or an echo that differs) fails the attempt at once with
  [`MalformedPDU`][aiortu.errors.MalformedPDU]: nobody else on the line sends it, and the
  unit will not send a better one for this attempt. Except the late reply: a frame that
  answers the request of this unit's last attempt that timed out (its shape: function code,
  byte count or echo) is that request's reply come too late, skipped
  ([`SkipReason.LATE`][aiortu.core.machines.SkipReason]) while the wait goes on.
  The machine remembers one such request per unit, until the unit answers.
* Bytes that fail the CRC or the framing are noted; the wait goes on for a short grace
  (a good frame may follow in the same burst), and if nothing answers, the attempt fails
  with that frame error rather than a plain timeout.
* Retries follow a [`RetryPolicy`][aiortu.core.machines.RetryPolicy]: by default on
  timeouts and frame errors only, never on exception responses (a device that refused
  will refuse again).
* A register read that gets its usual reply changes nothing in the machine, so a driver may run it
  without the machine and hand it over only if something else happens
  ([`MasterMachine.usual_exchange`][aiortu.core.machines.MasterMachine.usual_exchange]; the
  async master's driver of that is [`aiortu.master`][aiortu.master]).

Every event goes through the table, each frame and each piece of bad bytes included: there is
no shortcut around it and no filter before it. Time comes in as arguments; the machine never
reads a clock.
"""

from __future__ import annotations

import enum
import struct
from collections.abc import Callable
from dataclasses import dataclass
from typing import Final

from aiortu.core.codes import BROADCAST_UNIT, EXCEPTION_BIT
from aiortu.core.errors import FrameError, MalformedPDU, ResponseTimeout
from aiortu.core.machines._master_transaction import (
    Failure,
    Outcome,
    OutcomeKind,
    SkipReason,
    Transaction,
)
from aiortu.core.pdu import (
    ExceptionPDU,
    RawPDU,
    RawRegisterRead,
    ReadHoldingRegistersRequest,
    ReadInputRegistersRequest,
    Request,
    Response,
    decode_response,
)
from aiortu.core.rtu import encode_frame

__all__ = (
    "DEFAULT_FRAME_ERROR_GRACE",
    "TRANSITIONS",
    "KnownRequest",
    "MasterEvent",
    "MasterMachine",
    "MasterMachineError",
    "MasterState",
    "TransitionObserver",
    "next_state",
)

DEFAULT_FRAME_ERROR_GRACE: Final = 0.05
"""Seconds the wait goes on after bad bytes, in case a good frame follows them."""


class MasterState(enum.Enum):
    """The states of the master, named after the spec."""

    __hash__ = object.__hash__  # singletons: identity hashing, in C (fast table lookups)

    IDLE = "IDLE"
    WAITING_REPLY = "WAITING_REPLY"
    WAITING_TURNAROUND = "WAITING_TURNAROUND"
    PROCESSING_REPLY = "PROCESSING_REPLY"
    PROCESSING_ERROR = "PROCESSING_ERROR"


class MasterEvent(enum.Enum):
    """What can happen to the master."""

    __hash__ = object.__hash__  # singletons: identity hashing, in C (fast table lookups)

    SEND_UNICAST = "send unicast"
    """A request that expects a reply has left the wire."""
    SEND_BROADCAST = "send broadcast"
    """A request that expects no reply (a broadcast, or diagnostics 04) has left the wire."""
    TURNAROUND_EXPIRED = "turnaround expired"
    """The turnaround delay after a request without reply is over."""
    REPLY_RECEIVED = "reply received"
    """A frame with a good CRC arrived while waiting."""
    REPLY_OK = "reply ok"
    """The frame answers the request."""
    REPLY_UNEXPECTED = "reply unexpected"
    """The frame is stale, from another unit, or does not answer the request."""
    REPLY_EXCEPTION = "reply exception"
    """The unit answered with an exception response."""
    REPLY_MALFORMED = "reply malformed"
    """The unit asked answered with the request's function code, but the reply does not
    decode or does not answer the request."""
    FRAME_ERROR = "frame error"
    """Bytes arrived that do not make a valid frame."""
    TIMEOUT = "timeout"
    """The response timeout (or the grace after a frame error) ran out."""
    CONNECTION_LOST = "connection lost"
    """The line under the master failed."""
    ERROR_NOTED = "error noted"
    """A frame error is remembered and the wait goes on."""
    ERROR_IGNORED = "error ignored"
    """The bad bytes ended before a reply could begin: not the reply, the wait goes on."""
    RETRY = "retry"
    """The request is sent again."""
    GIVE_UP = "give up"
    """The transaction ends with its error (or its exception response)."""


class MasterMachineError(RuntimeError):
    """An event arrived in a state whose table has no entry for it. Caused by a bug in aiortu."""


_WAIT = Outcome(OutcomeKind.WAIT)

_FRAME_CACHE_SIZE: Final = 256
"""Request frames a machine remembers (see
[`MasterMachine.frame`][aiortu.core.machines.MasterMachine.frame])."""


@dataclass(slots=True)
class _ArrivedFrame:
    unit: int
    pdu: bytes
    start: float


@dataclass(slots=True)
class _BadBytes:
    error: FrameError
    end: float


class KnownRequest:
    """What a machine remembers of a request to a unit (see
    [`MasterMachine.frame`][aiortu.core.machines.MasterMachine.frame]): its frame, the shape
    of its usual reply, and the last usual reply it decoded."""

    __slots__ = ("frame", "last_reply", "last_response", "reply_shape", "request")

    def __init__(self, request: Request, frame: bytes, reply_shape: tuple[bytes, int] | None):
        self.request = request
        self.frame = frame
        """The request's frame, CRC included."""
        self.reply_shape = reply_shape
        """The first bytes (unit, function code, byte count) and the length of the usual
        reply, where the request has one (a register read's); else None."""
        self.last_reply: bytes | None = None
        """The last usual reply (a whole frame whose CRC was found good), or None."""
        self.last_response: Response | None = None
        """The response [`last_reply`][aiortu.core.machines.KnownRequest.last_reply] holds."""


_REGISTER_READS: Final = frozenset((ReadHoldingRegistersRequest, ReadInputRegistersRequest))
_USUAL_READS: Final = _REGISTER_READS | {RawRegisterRead}
"""The requests with a usual reply: the register reads, decoded or kept as bytes."""


_WORDS: Final = tuple(struct.Struct(f">{count}H") for count in range(126))
"""The layouts of 0..125 big-endian 16-bit words, made once."""


def _raw_reply(frame: bytes) -> Response:
    """The reply PDU in `frame`, the usual reply to a
    [`RawRegisterRead`][aiortu.core.pdu.RawRegisterRead], as its bytes: built without
    RawPDU's checks, which a matched shape passes."""
    response = object.__new__(RawPDU)
    object.__setattr__(response, "function_code", frame[1])
    object.__setattr__(response, "data", frame[2:-2])
    return response


def _register_reply(request: ReadHoldingRegistersRequest, data: bytes, offset: int) -> Response:
    """The response to a register read whose words start at `offset` of `data`, built
    without decode_response's general checks: the caller has matched the length to the
    request's count, and 16-bit words are always in range."""
    response = object.__new__(request.response_class)
    object.__setattr__(response, "values", _WORDS[request.count].unpack_from(data, offset))
    return response


_S = MasterState
_E = MasterEvent

TRANSITIONS: Final[dict[tuple[MasterState, MasterEvent], tuple[MasterState, str]]] = {
    # (state, event): (next state, action)
    (_S.IDLE, _E.SEND_UNICAST): (_S.WAITING_REPLY, "start_response_timeout"),
    (_S.IDLE, _E.SEND_BROADCAST): (_S.WAITING_TURNAROUND, "start_turnaround"),
    (_S.IDLE, _E.CONNECTION_LOST): (_S.PROCESSING_ERROR, "note_connection_lost"),
    (_S.WAITING_TURNAROUND, _E.TURNAROUND_EXPIRED): (_S.IDLE, "finish_without_reply"),
    (_S.WAITING_TURNAROUND, _E.CONNECTION_LOST): (_S.PROCESSING_ERROR, "note_connection_lost"),
    # Nobody answers a broadcast: whatever arrives meanwhile is another conversation.
    (_S.WAITING_TURNAROUND, _E.REPLY_RECEIVED): (_S.WAITING_TURNAROUND, "skip_other_conversation"),
    (_S.WAITING_TURNAROUND, _E.FRAME_ERROR): (_S.WAITING_TURNAROUND, "ignore_bad_bytes"),
    (_S.WAITING_REPLY, _E.REPLY_RECEIVED): (_S.PROCESSING_REPLY, "examine_frame"),
    (_S.WAITING_REPLY, _E.FRAME_ERROR): (_S.PROCESSING_ERROR, "note_frame_error"),
    (_S.WAITING_REPLY, _E.TIMEOUT): (_S.PROCESSING_ERROR, "note_attempt_failed"),
    (_S.WAITING_REPLY, _E.CONNECTION_LOST): (_S.PROCESSING_ERROR, "note_connection_lost"),
    (_S.PROCESSING_REPLY, _E.REPLY_OK): (_S.IDLE, "finish_with_reply"),
    (_S.PROCESSING_REPLY, _E.REPLY_UNEXPECTED): (_S.WAITING_REPLY, "skip_frame"),
    (_S.PROCESSING_REPLY, _E.REPLY_EXCEPTION): (_S.PROCESSING_ERROR, "note_exception"),
    (_S.PROCESSING_REPLY, _E.REPLY_MALFORMED): (_S.PROCESSING_ERROR, "note_malformed_reply"),
    (_S.PROCESSING_ERROR, _E.ERROR_NOTED): (_S.WAITING_REPLY, "shorten_wait"),
    (_S.PROCESSING_ERROR, _E.ERROR_IGNORED): (_S.WAITING_REPLY, "ignore_bad_bytes"),
    (_S.PROCESSING_ERROR, _E.RETRY): (_S.IDLE, "prepare_retry"),
    (_S.PROCESSING_ERROR, _E.GIVE_UP): (_S.IDLE, "finish_with_failure"),
}
"""The master's transitions: `(state, event) -> (next state, action name)`."""


def next_state(state: MasterState, event: MasterEvent) -> MasterState:
    """The state `event` leads to from `state`; raises
    [`MasterMachineError`][aiortu.core.machines.MasterMachineError] if none."""
    entry = TRANSITIONS.get((state, event))
    if entry is None:
        raise MasterMachineError(f"no transition for event {event.name} in state {state.name}")
    return entry[0]


TransitionObserver = Callable[[MasterState, MasterEvent, MasterState], None]
"""Called with `(state, event, next state)` for every transition."""


class MasterMachine:
    """The state machine of a master on one line (see the module docstring).

    Drive it like this for each transaction:

    1. [`begin`][aiortu.core.machines.MasterMachine.begin] with a
       [`Transaction`][aiortu.core.machines.Transaction] (state IDLE).
    2. Send [`frame`][aiortu.core.machines.MasterMachine.frame], then
       [`sent`][aiortu.core.machines.MasterMachine.sent] with when it began to go out and when
       it had left the wire.
    3. Until the outcome is DONE or FAILED: feed
       [`frame_received`][aiortu.core.machines.MasterMachine.frame_received],
       [`frame_error`][aiortu.core.machines.MasterMachine.frame_error] and, once the clock
       passes [`deadline`][aiortu.core.machines.MasterMachine.deadline],
       [`expired`][aiortu.core.machines.MasterMachine.expired]. On RETRY, send
       [`frame`][aiortu.core.machines.MasterMachine.frame] again and call
       [`sent`][aiortu.core.machines.MasterMachine.sent].

    [`connection_lost`][aiortu.core.machines.MasterMachine.connection_lost] ends the
    transaction in any state but PROCESSING_*. `on_transition`, if given, is called with `(state,
    event, next state)` for every transition (for tracing and for the tests).
    """

    __slots__ = (
        "_actions",
        "_entry",
        "_frames",
        "_late",
        "_on_transition",
        "_outcome",
        "deadline",
        "frame_error_grace",
        "state",
        "transaction",
    )

    def __init__(
        self,
        *,
        frame_error_grace: float = DEFAULT_FRAME_ERROR_GRACE,
        on_transition: TransitionObserver | None = None,
    ) -> None:
        self.state = MasterState.IDLE
        """The current state."""
        self.transaction: Transaction | None = None
        """The transaction in progress (kept after it ends, until the next
        [`begin`][aiortu.core.machines.MasterMachine.begin])."""
        self.deadline: float | None = None
        """When to call [`expired`][aiortu.core.machines.MasterMachine.expired]: the end of
        the response timeout or turnaround."""
        self.frame_error_grace = frame_error_grace
        """Seconds the wait goes on after a frame error (never past the response timeout)."""
        self._on_transition = on_transition
        self._outcome = _WAIT
        self._frames: dict[tuple[int, int], KnownRequest] = {}
        self._entry: KnownRequest | None = None
        """What is remembered of the transaction in progress, once looked up."""
        self._late: dict[int, Request] = {}
        """By unit: the request of its last attempt that timed out, whose reply may still
        come, until the unit answers."""
        self._actions: dict[
            tuple[MasterState, MasterEvent], tuple[MasterState, Callable[[object], None]]
        ] = {
            key: (target, getattr(self, f"_{action}"))
            for key, (target, action) in TRANSITIONS.items()
        }

    # -- driving ---------------------------------------------------------------------

    def begin(self, transaction: Transaction) -> None:
        """Take `transaction` as the one in progress; the machine must be IDLE."""
        if self.state is not MasterState.IDLE:
            raise MasterMachineError(f"a transaction begins in state IDLE, not {self.state.name}")
        self.transaction = transaction
        self.deadline = None
        self._entry = None

    @property
    def frame(self) -> bytes:
        """The frame to send for the transaction in progress.

        Frames are remembered by unit and request object (requests are immutable), so a
        request sent again, as a master's poll loop does, is not encoded again.
        """
        return (self._entry or self._known()).frame

    def _known(self) -> KnownRequest:
        """What the machine remembers of the request in progress (see
        [`frame`][aiortu.core.machines.MasterMachine.frame])."""
        transaction = self._current
        known = self._entry = self._remember(transaction.unit, transaction.request)
        return known

    def _remember(self, unit: int, request: Request) -> KnownRequest:
        key = (unit, id(request))
        known = self._frames.get(key)
        if known is None or known.request is not request:
            shape = None
            if type(request) in _USUAL_READS and unit != BROADCAST_UNIT:
                assert isinstance(request, ReadHoldingRegistersRequest | RawRegisterRead)
                size = 2 * request.count
                shape = bytes((unit, request.function_code, size)), size + 5
            if len(self._frames) >= _FRAME_CACHE_SIZE:
                self._frames.clear()
            # Holding the request keeps its id unique.
            known = self._frames[key] = KnownRequest(
                request, encode_frame(unit, request.encode()), shape
            )
        return known

    def usual_exchange(self, unit: int, request: Request) -> KnownRequest | None:
        """What the machine remembers of `request` to `unit` (its frame, its usual reply's
        shape) where a transaction of it may run without the machine until something other
        than its usual reply happens; else None.

        A transaction that gets its usual reply leaves the machine as it found it: IDLE, after
        SEND_UNICAST, REPLY_RECEIVED and REPLY_OK, with nothing to remember. So a driver may send
        *frame* and wait for the reply of that shape (first bytes, length) without telling the
        machine. If that reply comes whole with a good CRC before the response timeout,
        [`usual_response`][aiortu.core.machines.MasterMachine.usual_response] makes it the
        response. On anything else (another frame, bad bytes, the timeout, the line lost), the
        driver calls [`begin`][aiortu.core.machines.MasterMachine.begin] and then
        [`sent`][aiortu.core.machines.MasterMachine.sent] with the times the frame went out,
        and goes on the usual way: the machine then knows everything it would have known.

        This applies where the machine is IDLE, has no transition observer (which must
        see every transition), awaits no late reply from `unit` (the table recognises it:
        see the module docstring), and the request has a usual reply (a register read's, decoded
        or a [`RawRegisterRead`][aiortu.core.pdu.RawRegisterRead]).
        """
        if self.state is not _S.IDLE or self._on_transition is not None or unit in self._late:
            return None
        known = self._frames.get((unit, id(request)))
        if known is None or known.request is not request:
            known = self._remember(unit, request)
        return known if known.reply_shape is not None else None

    @staticmethod
    def usual_response(known: KnownRequest, frame: bytes) -> Response:
        """The response in `frame`, the usual reply to `known`'s request (see
        [`usual_exchange`][aiortu.core.machines.MasterMachine.usual_exchange]): its shape is
        matched and its CRC checked. For a [`RawRegisterRead`][aiortu.core.pdu.RawRegisterRead]
        it is a [`RawPDU`][aiortu.core.pdu.RawPDU] of the reply's bytes, not decoded.

        A poll loop reads the same block again and again and often gets the same bytes back. A frame
        equal to `known.last_reply` (the last usual reply to that request)
        holds the same response, so it is not decoded again (and a link need not check its CRC
        again: see [`aiortu.line.Link.expect`][aiortu.line.Link.expect]). Responses are immutable,
        so sharing one is safe.
        """
        if frame == known.last_reply:
            response = known.last_response
            assert response is not None
            return response
        request = known.request
        if type(request) is RawRegisterRead:
            response = _raw_reply(frame)
        else:
            assert isinstance(request, ReadHoldingRegistersRequest)
            response = _register_reply(request, frame, 3)
        known.last_reply = frame
        known.last_response = response
        return response

    def sent(self, start: float, end: float) -> float:
        """The request began to go out at `start` and left the wire at `end`.

        Returns the deadline: `end` plus the response timeout, or plus the turnaround.
        """
        transaction = self._current
        transaction.attempts += 1
        transaction.attempt_start = start
        transaction.attempt_end = end
        delay = transaction.reply_delay
        # Causality: no reply can begin before the unit has the whole request and has
        # had its turnaround. Only where the line's wire times are real (see the field).
        # Without it the rule is weaker: the frame must end after the request began.
        transaction.earliest_reply = start if delay is None else end + delay
        transaction.frame_error = None
        if transaction.expects_reply:
            self._fire(_E.SEND_UNICAST, None)
        else:
            self._fire(_E.SEND_BROADCAST, None)
        assert self.deadline is not None
        return self.deadline

    def frame_received(self, unit: int, pdu: bytes, start: float, end: float) -> Outcome:
        """A frame with a good CRC arrived (`start`/`end`: its first and last byte)."""
        transaction = self.transaction
        if transaction is not None and transaction.reply_delay is None:
            start = end  # no real wire times: only the end is sure to follow the request
        return self._fire(_E.REPLY_RECEIVED, _ArrivedFrame(unit, pdu, start))

    def frame_error(self, error: FrameError, end: float) -> Outcome:
        """Bytes that ended at `end` made no valid frame; `error` says why."""
        return self._fire(_E.FRAME_ERROR, _BadBytes(error, end))

    def expired(self, now: float) -> Outcome:
        """The clock reached `now`; past
        [`deadline`][aiortu.core.machines.MasterMachine.deadline] this ends the wait."""
        if self.deadline is None or now < self.deadline:
            return _WAIT
        if self.state is MasterState.WAITING_TURNAROUND:
            return self._fire(_E.TURNAROUND_EXPIRED, None)
        return self._fire(_E.TIMEOUT, None)

    def connection_lost(self, error: Exception) -> Outcome:
        """The line failed with `error`; the transaction fails with it."""
        return self._fire(_E.CONNECTION_LOST, error)

    # -- the machine -----------------------------------------------------------------

    @property
    def _current(self) -> Transaction:
        if self.transaction is None:
            raise MasterMachineError("no transaction in progress")
        return self.transaction

    def _fire(self, event: MasterEvent, argument: object) -> Outcome:
        entry = self._actions.get((self.state, event))
        if entry is None:
            next_state(self.state, event)  # raises, with the message
        assert entry is not None
        target, action = entry
        if self._on_transition is not None:
            self._on_transition(self.state, event, target)
        self.state = target
        self._outcome = _WAIT
        action(argument)
        return self._outcome

    # -- actions ---------------------------------------------------------------------

    def _start_response_timeout(self, _: object) -> None:
        transaction = self.transaction
        assert transaction is not None
        self.deadline = transaction.attempt_end + transaction.timeout

    def _start_turnaround(self, _: object) -> None:
        transaction = self._current
        self.deadline = transaction.attempt_end + transaction.turnaround

    def _finish_without_reply(self, _: object) -> None:
        self.deadline = None
        self._outcome = Outcome(OutcomeKind.DONE)

    def _examine_frame(self, argument: object) -> None:
        assert isinstance(argument, _ArrivedFrame)
        unit, pdu, start = argument.unit, argument.pdu, argument.start
        transaction = self.transaction
        assert transaction is not None
        # The usual reply to a register read is built without the general checks.
        usual = self._usual_reply(unit, pdu, start)
        if usual is not None:
            self._fire(_E.REPLY_OK, usual)
            return
        request = transaction.request
        reason: SkipReason | None = None
        response: Response | ExceptionPDU | None = None
        if start < transaction.earliest_reply:
            reason = SkipReason.STALE
        elif unit != transaction.unit:
            # A broadcast awaits no reply; a request to unit 0 that does (over Modbus TCP,
            # where 0 is an ordinary id) takes unit 0's.
            reason = SkipReason.OTHER_UNIT
        elif not pdu or pdu[0] & ~EXCEPTION_BIT != request.function_code:
            reason = SkipReason.OTHER_FUNCTION
        else:
            try:
                # A request sent as raw bytes (a user-defined code, or one forwarded as
                # it came) takes any reply of its code as raw bytes too.
                if isinstance(request, RawPDU) and not pdu[0] & EXCEPTION_BIT:
                    response = RawPDU.decode(pdu)
                else:
                    response = decode_response(pdu)
                if not isinstance(response, ExceptionPDU):
                    request.check_response(response)
            except MalformedPDU as error:
                if self._is_late_reply(unit, pdu):
                    reason = SkipReason.LATE
                else:
                    self._fire(_E.REPLY_MALFORMED, error)
                    return
        if reason is not None:
            self._fire(_E.REPLY_UNEXPECTED, reason)
        elif isinstance(response, ExceptionPDU):
            self._fire(_E.REPLY_EXCEPTION, response)
        else:
            self._fire(_E.REPLY_OK, response)

    def _usual_reply(self, unit: int, pdu: bytes, start: float) -> Response | None:
        """The reply to a register read when `pdu` is one, from the unit asked, begun no
        sooner than a reply could (`start`): built without decode_response's general
        checks (its length is the request's count, and 16-bit words are always in
        range); else None."""
        transaction = self.transaction
        assert transaction is not None
        request = transaction.request
        if (
            type(request) in _REGISTER_READS
            and unit == transaction.unit != BROADCAST_UNIT
            and start >= transaction.earliest_reply
            and isinstance(request, ReadHoldingRegistersRequest)
            and pdu
            and pdu[0] == request.function_code
            and len(pdu) == 2 + 2 * request.count == pdu[1] + 2
        ):
            return _register_reply(request, pdu, 2)
        return None

    def _is_late_reply(self, unit: int, pdu: bytes) -> bool:
        """Whether `pdu`, which does not answer the request in progress, answers the
        request of `unit`'s last attempt that timed out: its reply come too late (then it
        is not awaited any more)."""
        late = self._late.get(unit)
        if late is None:
            return False
        try:
            response = decode_response(pdu)
            if isinstance(response, ExceptionPDU):
                return False
            late.check_response(response)
        except MalformedPDU:
            return False
        del self._late[unit]
        return True

    def _skip_frame(self, reason: object) -> None:
        assert isinstance(reason, SkipReason)
        self._outcome = Outcome(OutcomeKind.WAIT, skipped=reason)

    def _skip_other_conversation(self, argument: object) -> None:
        self._outcome = Outcome(OutcomeKind.WAIT, skipped=SkipReason.OTHER_UNIT)

    def _ignore_bad_bytes(self, _: object) -> None:
        pass  # the state says it all: the wait goes on

    def _finish_with_reply(self, response: object) -> None:
        assert isinstance(response, Response)
        self.deadline = None
        self._late.pop(self._current.unit, None)  # the unit answered: it is in step again
        self._outcome = Outcome(OutcomeKind.DONE, response=response)

    def _note_exception(self, response: object) -> None:
        assert isinstance(response, ExceptionPDU)
        self._late.pop(self._current.unit, None)
        if self._may_retry(response.exception_code):
            self._fire(_E.RETRY, None)
        else:
            self._fire(_E.GIVE_UP, Outcome(OutcomeKind.DONE, response=response))

    def _note_frame_error(self, argument: object) -> None:
        assert isinstance(argument, _BadBytes)
        transaction = self._current
        if argument.end < transaction.earliest_reply:
            # Bytes that ended before a reply could begin are not the reply.
            self._fire(_E.ERROR_IGNORED, None)
            return
        transaction.frame_error = argument.error
        self._fire(_E.ERROR_NOTED, argument.end)

    def _shorten_wait(self, end: object) -> None:
        assert isinstance(end, float | int)
        assert self.deadline is not None
        self.deadline = min(self.deadline, end + self.frame_error_grace)

    def _note_malformed_reply(self, error: object) -> None:
        assert isinstance(error, MalformedPDU)
        # The unit asked answered, wrongly: waiting longer brings nothing better.
        self._current.frame_error = error
        self._note_attempt_failed(None)

    def _note_attempt_failed(self, _: object) -> None:
        transaction = self._current
        failure = Failure.TIMEOUT if transaction.frame_error is None else Failure.FRAME_ERROR
        transaction.failures.append(failure)
        if failure is Failure.TIMEOUT and transaction.unit != BROADCAST_UNIT:
            self._late[transaction.unit] = transaction.request  # its reply may still come
        if self._may_retry(failure):
            self._fire(_E.RETRY, None)
            return
        error: Exception
        if transaction.frame_error is not None:
            error = transaction.frame_error
        else:
            tries = f" in {transaction.attempts} attempts" if transaction.attempts > 1 else ""
            error = ResponseTimeout(
                f"no reply from unit {transaction.unit} to function "
                f"0x{transaction.request.function_code:02X} within {transaction.timeout:g} s{tries}"
            )
        self._fire(_E.GIVE_UP, Outcome(OutcomeKind.FAILED, error=error))

    def _note_connection_lost(self, error: object) -> None:
        assert isinstance(error, Exception)
        self._fire(_E.GIVE_UP, Outcome(OutcomeKind.FAILED, error=error))

    def _prepare_retry(self, _: object) -> None:
        self.deadline = None
        self._outcome = Outcome(OutcomeKind.RETRY)

    def _finish_with_failure(self, outcome: object) -> None:
        assert isinstance(outcome, Outcome)
        self.deadline = None
        self._outcome = outcome

    def _may_retry(self, failure: Failure | int) -> bool:
        transaction = self._current
        policy = transaction.policy
        return (
            not transaction.abandoned
            and failure in policy.retry_on
            and transaction.attempts <= policy.retries
        )

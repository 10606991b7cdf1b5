"""The slave's state machine, written as a table, and the serial line diagnostic counters.

The machine follows the slave diagram of the serial line spec:

    IDLE              waiting                 -- a frame with a good CRC -->  CHECKING
    CHECKING          for us, and valid?      -- another unit's frame -->     IDLE
                                              -- ignored (listen-only) -->    IDLE
                                              -- valid (or broadcast) -->     PROCESSING
                                              -- invalid -->                  FORMATTING_ERROR
    PROCESSING        running the request     -- done -->                     FORMATTING_REPLY
                                              -- failed -->                   FORMATTING_ERROR
    FORMATTING_REPLY  the normal reply        -- sent, or withheld -->        IDLE
    FORMATTING_ERROR  the exception reply     -- sent, or withheld -->        IDLE

`TRANSITIONS` is that diagram as data. A (state, event)
pair missing from it is a bug and raises
[`SlaveMachineError`][aiortu.core.machines.SlaveMachineError], never a silent no-op.

The machine is sans-IO: the slave tells it what happened and it says what to do. It owns the spec's
decisions: frames for units it does not serve are dropped and counted; broadcasts (unit 0) are
executed and never answered, not even with an exception; in listen-only mode requests are only
monitored (counted and logged), never executed nor answered, except restart communications (08/01),
which leaves the mode; and exceptions come in the spec's order. That order falls out of the phases:
[`SlaveMachine.check_request`][aiortu.core.machines.SlaveMachine.check_request] answers 01 for
an unsupported function before any 03 or 02 the decoder found in the request itself (the decoder
checks quantities before address ranges), and only a request that passed those checks reaches
PROCESSING, where the data store answers 02 for unmapped addresses and a failing handler 04.

[`SerialLineCounters`][aiortu.core.machines.SerialLineCounters] are the counters the spec's
Diagnostics function (08) reports; the machine updates them as frames go by, along with the comm
event log and counter ([`CommEventLog`][aiortu.core.machines.CommEventLog]) that 0B and 0C
report.
"""

from __future__ import annotations

import enum
from collections.abc import Iterable
from dataclasses import dataclass, fields
from typing import Final

from aiortu.core.codes import BROADCAST_UNIT, ExceptionCode, FunctionCode
from aiortu.core.machines._comm_events import (
    EVENT_ENTERED_LISTEN_ONLY,
    EVENT_RESTART,
    CommEventLog,
    receive_event,
    send_event,
)

__all__ = (
    "DEFAULT_ASCII_DELIMITER",
    "NEGATIVE_ACKNOWLEDGE",
    "TRANSITIONS",
    "SerialLineCounters",
    "SlaveEvent",
    "SlaveMachine",
    "SlaveMachineError",
    "SlaveState",
)

NEGATIVE_ACKNOWLEDGE: Final = 0x07
"""The exception code the spec's "server NAK count" counts (a legacy programming NAK)."""

DEFAULT_ASCII_DELIMITER: Final = 0x0A
"""The end-of-message character of the ASCII mode until 08/03 changes it (LF)."""

# The requests that fetch the event counter or log do not count as completions.
_NOT_COUNTED_AS_EVENTS = frozenset(
    {FunctionCode.GET_COMM_EVENT_COUNTER, FunctionCode.GET_COMM_EVENT_LOG}
)


class SlaveState(enum.Enum):
    """The states of the slave, named after the spec."""

    # Members are singletons: hashing by identity (in C) makes the transition table's
    # lookups about twice as fast as Enum's hash of the member name.
    __hash__ = object.__hash__

    IDLE = "IDLE"
    CHECKING = "CHECKING"
    PROCESSING = "PROCESSING"
    FORMATTING_REPLY = "FORMATTING_REPLY"
    FORMATTING_ERROR = "FORMATTING_ERROR"


class SlaveEvent(enum.Enum):
    """What can happen to the slave."""

    # Members are singletons: hashing by identity (in C) makes the transition table's
    # lookups about twice as fast as Enum's hash of the member name.
    __hash__ = object.__hash__

    FRAME_RECEIVED = "frame received"
    """A frame with a good CRC arrived."""
    FRAME_CORRUPT = "frame corrupt"
    """Bytes arrived that failed the CRC check."""
    CHARACTER_OVERRUN = "character overrun"
    """More bytes arrived than a frame can hold."""
    NOT_FOR_US = "not for us"
    """The frame is addressed to a unit this slave does not serve."""
    REQUEST_OK = "request ok"
    """A unicast request passed the checks."""
    BROADCAST = "broadcast"
    """A broadcast request passed the checks."""
    IGNORED = "ignored"
    """Listen-only mode: the request is monitored, not executed nor answered."""
    REQUEST_INVALID = "request invalid"
    """The request is unsupported or breaks the spec: it gets an exception."""
    PROCESSED = "processed"
    """The request was executed."""
    PROCESSING_FAILED = "processing failed"
    """Executing the request raised an exception code (02, 04, ...)."""
    REPLY_SENT = "reply sent"
    """The reply (normal or exception) was handed to the line."""
    NO_REPLY = "no reply"
    """Nothing is sent: a broadcast, listen-only mode, or a handler that withheld it."""


class SlaveMachineError(RuntimeError):
    """An event arrived in a state whose table has no entry for it. Caused by a bug in aiortu."""


_S = SlaveState
_E = SlaveEvent

TRANSITIONS: Final[dict[tuple[SlaveState, SlaveEvent], SlaveState]] = {
    # (state, event): next state
    (_S.IDLE, _E.FRAME_RECEIVED): _S.CHECKING,
    (_S.IDLE, _E.FRAME_CORRUPT): _S.IDLE,
    (_S.IDLE, _E.CHARACTER_OVERRUN): _S.IDLE,
    (_S.CHECKING, _E.NOT_FOR_US): _S.IDLE,
    (_S.CHECKING, _E.IGNORED): _S.IDLE,
    (_S.CHECKING, _E.REQUEST_OK): _S.PROCESSING,
    (_S.CHECKING, _E.BROADCAST): _S.PROCESSING,
    (_S.CHECKING, _E.REQUEST_INVALID): _S.FORMATTING_ERROR,
    (_S.PROCESSING, _E.PROCESSED): _S.FORMATTING_REPLY,
    (_S.PROCESSING, _E.PROCESSING_FAILED): _S.FORMATTING_ERROR,
    (_S.FORMATTING_REPLY, _E.REPLY_SENT): _S.IDLE,
    (_S.FORMATTING_REPLY, _E.NO_REPLY): _S.IDLE,
    (_S.FORMATTING_ERROR, _E.REPLY_SENT): _S.IDLE,
    (_S.FORMATTING_ERROR, _E.NO_REPLY): _S.IDLE,
}
"""The slave's transitions: `(state, event) -> next state`."""

_ANSWERED_TARGET: Final = TRANSITIONS[
    TRANSITIONS[TRANSITIONS[TRANSITIONS[_S.IDLE, _E.FRAME_RECEIVED], _E.REQUEST_OK], _E.PROCESSED],
    _E.REPLY_SENT,
]
"""Where a request answered normally leaves the machine (see answered_at_once)."""

_RECEIVE_EVENT: Final = receive_event()
_SEND_EVENT: Final = send_event()
"""The log entries of a unicast request answered normally outside listen-only mode."""


@dataclass(slots=True)
class SerialLineCounters:
    """The diagnostic counters of a serial line slave, as Diagnostics (08) reports them.

    Each counts since the slave started or the counters were last cleared, and wraps at 65536 when
    reported (the spec's counters are 16-bit words;
    [`word`][aiortu.core.machines.SerialLineCounters.word] does that).
    """

    bus_message_count: int = 0
    """Frames with a good CRC seen on the line, for any unit (sub-function 0x0B)."""
    bus_communication_error_count: int = 0
    """Frames that failed the CRC check (0x0C)."""
    bus_exception_error_count: int = 0
    """Exception responses this slave sent (0x0D)."""
    server_message_count: int = 0
    """Requests addressed to this slave's units, or broadcast, that it processed (0x0E)."""
    server_no_response_count: int = 0
    """Requests addressed to this slave, or broadcast, that got no reply at all (0x0F)."""
    server_nak_count: int = 0
    """Negative acknowledge (exception 07) responses this slave sent (0x10)."""
    server_busy_count: int = 0
    """Server device busy (exception 06) responses this slave sent (0x11)."""
    bus_character_overrun_count: int = 0
    """Frames lost because more characters arrived than a frame holds (0x12)."""
    other_unit_count: int = 0
    """Frames addressed to units this slave does not serve (aiortu's own, not in 08)."""

    def clear(self) -> None:
        """Set every counter to zero (08 sub-function 0x0A, or a restart)."""
        for field in fields(self):
            setattr(self, field.name, 0)

    def word(self, name: str) -> int:
        """The counter `name` as the 16-bit word the spec reports."""
        value: int = getattr(self, name)
        return value & 0xFFFF


class SlaveMachine:
    """The state machine of one slave serving `units` on one line (see the module docstring).

    Drive it in this order for each frame:

    1. [`frame_received`][aiortu.core.machines.SlaveMachine.frame_received]; if it returns
       `False` the frame is not for us: stop.
    2. In listen-only mode, unless the request is restart communications (08/01), call
       [`ignore`][aiortu.core.machines.SlaveMachine.ignore] and stop.
    3. [`check_request`][aiortu.core.machines.SlaveMachine.check_request]; if it returns
       `False` the request gets an exception.
    4. Otherwise execute the request, then
       [`processed`][aiortu.core.machines.SlaveMachine.processed] or
       [`processing_failed`][aiortu.core.machines.SlaveMachine.processing_failed].
    5. If [`should_reply`][aiortu.core.machines.SlaveMachine.should_reply], send the reply (an
       exception with [`exception_code`][aiortu.core.machines.SlaveMachine.exception_code] when
       the state is FORMATTING_ERROR) and call
       [`reply_sent`][aiortu.core.machines.SlaveMachine.reply_sent]; otherwise call
       [`no_reply`][aiortu.core.machines.SlaveMachine.no_reply].

    Corrupt frames and overruns are reported with
    [`frame_corrupt`][aiortu.core.machines.SlaveMachine.frame_corrupt] and
    [`character_overrun`][aiortu.core.machines.SlaveMachine.character_overrun], between frames.
    The diagnostics handlers change the machine through
    [`clear_counters`][aiortu.core.machines.SlaveMachine.clear_counters],
    [`enter_listen_only`][aiortu.core.machines.SlaveMachine.enter_listen_only] and
    [`restart_communications`][aiortu.core.machines.SlaveMachine.restart_communications].
    """

    __slots__ = (
        "_entered_listen_only",
        "_reply_allowed",
        "_restart",
        "_units",
        "ascii_delimiter",
        "broadcast",
        "counters",
        "diagnostic_register",
        "event_log",
        "exception_code",
        "function_code",
        "listen_only",
        "state",
        "unit",
    )

    def __init__(self, units: Iterable[int], counters: SerialLineCounters | None = None) -> None:
        self._units = frozenset(units)
        self.counters = counters if counters is not None else SerialLineCounters()
        """The diagnostic counters this machine updates."""
        self.event_log = CommEventLog()
        """The comm event log and event counter (0C, 0B)."""
        self.state = SlaveState.IDLE
        """The current state."""
        self.listen_only = False
        """In listen-only mode (08/04) requests are monitored, never executed nor answered."""
        self.diagnostic_register = 0
        """The 16-bit diagnostic register (08/02); the application sets its bits."""
        self.ascii_delimiter = DEFAULT_ASCII_DELIMITER
        """The ASCII end-of-message character set by 08/03 (kept, unused in RTU)."""
        self.unit = BROADCAST_UNIT
        """The unit address of the frame being handled."""
        self.function_code = 0
        """The function code of the frame being handled."""
        self.broadcast = False
        """Whether the frame being handled is a broadcast."""
        self.exception_code: int | None = None
        """The exception the current request gets, once the state is FORMATTING_ERROR."""
        self._reply_allowed = False
        self._entered_listen_only = False
        self._restart: bool | None = None

    @property
    def units(self) -> frozenset[int]:
        """The unit addresses this slave answers for."""
        return self._units

    @property
    def should_reply(self) -> bool:
        """Whether a reply goes on the line: not for a broadcast, nor in listen-only mode.

        A request that arrived in listen-only mode is never answered, even when it
        leaves the mode (restart communications).
        """
        return self._reply_allowed and not self.listen_only

    def fire(self, event: SlaveEvent) -> SlaveState:
        """Run one transition and return the new state; raise for a pair not in the table."""
        target = TRANSITIONS.get((self.state, event))
        if target is None:
            raise SlaveMachineError(
                f"no transition for event {event.name} in state {self.state.name}"
            )
        self.state = target
        return target

    # -- between frames ------------------------------------------------------------

    def frame_corrupt(self) -> None:
        """Bytes failed the CRC check: count and log them; nothing is ever answered."""
        self.fire(SlaveEvent.FRAME_CORRUPT)
        self.counters.bus_communication_error_count += 1
        self.event_log.add(receive_event(communication_error=True, listen_only=self.listen_only))

    def character_overrun(self) -> None:
        """A frame was lost to an overrun: count and log it."""
        self.fire(SlaveEvent.CHARACTER_OVERRUN)
        self.counters.bus_character_overrun_count += 1
        self.event_log.add(receive_event(overrun=True, listen_only=self.listen_only))

    # -- one frame -------------------------------------------------------------------

    def frame_received(self, unit: int, function_code: int = 0) -> bool:
        """A frame with a good CRC for `unit` arrived; tell whether this slave handles it.

        A frame for another unit is counted and dropped (the machine is IDLE again). A
        frame for us is counted and logged as a receive event.
        """
        self.fire(SlaveEvent.FRAME_RECEIVED)
        counters = self.counters
        counters.bus_message_count += 1
        self.exception_code = None
        self.unit = unit
        self.function_code = function_code
        self.broadcast = unit == BROADCAST_UNIT
        if not self.broadcast and unit not in self._units:
            counters.other_unit_count += 1
            self.fire(SlaveEvent.NOT_FOR_US)
            return False
        counters.server_message_count += 1
        self._reply_allowed = not (self.broadcast or self.listen_only)
        self.event_log.add(receive_event(broadcast=self.broadcast, listen_only=self.listen_only))
        return True

    def answered_at_once(self, unit: int, function_code: int) -> None:
        """A request for `unit` (one of ours, not a broadcast) arrived, was executed and got its
        normal reply, which has gone out, all while the machine was IDLE and not in listen-only
        mode: [`frame_received`][aiortu.core.machines.SlaveMachine.frame_received],
        [`check_request`][aiortu.core.machines.SlaveMachine.check_request],
        [`processed`][aiortu.core.machines.SlaveMachine.processed] and
        [`reply_sent`][aiortu.core.machines.SlaveMachine.reply_sent] in one step, the same
        counters and log entries at a fraction of the work. A slave that answers a request in the
        read callback counts it this way; the tests hold both ways equal.
        """
        if self.state is not _S.IDLE or self.listen_only or unit not in self._units:
            raise SlaveMachineError(
                f"a request answered at once needs IDLE, not listen-only, and unit {unit} "
                f"served; the state is {self.state.name}"
            )
        counters = self.counters
        counters.bus_message_count += 1
        counters.server_message_count += 1
        self.exception_code = None
        self.unit = unit
        self.function_code = function_code
        self.broadcast = False
        self._reply_allowed = True
        self.state = _ANSWERED_TARGET
        log = self.event_log
        log.add(_RECEIVE_EVENT)
        log.add(_SEND_EVENT)
        if function_code not in _NOT_COUNTED_AS_EVENTS:
            log.completed()

    def ignore(self) -> None:
        """Listen-only mode: the request is not executed nor answered; count it."""
        self.fire(SlaveEvent.IGNORED)
        self.counters.server_no_response_count += 1

    def check_request(self, *, supported: bool, violation: int | None = None) -> bool:
        """Check the request; tell whether to execute it.

        `supported` says whether the slave has a handler for the function code; `violation` is the
        exception code decoding the request gave (03 for a quantity or value, 02 for an address
        range), or `None`. An unsupported function gets 01 whatever else is wrong with the request.
        On `False` the machine is in FORMATTING_ERROR with
        [`exception_code`][aiortu.core.machines.SlaveMachine.exception_code] set.
        """
        if not supported:
            return self._invalid(ExceptionCode.ILLEGAL_FUNCTION)
        if violation is not None:
            return self._invalid(violation)
        self.fire(SlaveEvent.BROADCAST if self.broadcast else SlaveEvent.REQUEST_OK)
        return True

    def processed(self) -> None:
        """The request was executed; a normal reply follows."""
        self.fire(SlaveEvent.PROCESSED)

    def processing_failed(self, exception_code: int) -> None:
        """Executing the request gave `exception_code`; an exception reply follows."""
        self.fire(SlaveEvent.PROCESSING_FAILED)
        self.exception_code = exception_code

    def reply_sent(self) -> None:
        """The reply went to the line; count and log it and return to IDLE."""
        if not self.should_reply:
            raise SlaveMachineError("a reply was sent where none is allowed")
        code = self.exception_code if self.state is SlaveState.FORMATTING_ERROR else None
        self.fire(SlaveEvent.REPLY_SENT)
        if code is not None:
            counters = self.counters
            counters.bus_exception_error_count += 1
            if code == ExceptionCode.SERVER_DEVICE_BUSY:
                counters.server_busy_count += 1
            elif code == NEGATIVE_ACKNOWLEDGE:
                counters.server_nak_count += 1
        self._finish(code)

    def no_reply(self) -> None:
        """Nothing was sent for this request; count and log it and return to IDLE."""
        code = self.exception_code if self.state is SlaveState.FORMATTING_ERROR else None
        self.fire(SlaveEvent.NO_REPLY)
        self.counters.server_no_response_count += 1
        self._finish(code)

    # -- what diagnostics change -----------------------------------------------------

    def clear_counters(self) -> None:
        """08/0A: clear the counters, the event counter and the diagnostic register."""
        self.counters.clear()
        self.event_log.event_count = 0
        self.diagnostic_register = 0

    def enter_listen_only(self) -> None:
        """08/04: from now on monitor requests only; logged as event 0x04."""
        self.listen_only = True
        self._entered_listen_only = True

    def restart_communications(self, *, clear_log: bool) -> None:
        """08/01: once the current request is finished (its reply sent, unless the slave
        was in listen-only mode), clear the counters, the event log too if `clear_log`,
        leave listen-only mode and log the restart (event 0x00)."""
        self._restart = clear_log

    def _finish(self, exception_code: int | None) -> None:
        log = self.event_log
        if self._entered_listen_only:
            self._entered_listen_only = False
            log.add(EVENT_ENTERED_LISTEN_ONLY)
        else:
            log.add(send_event(exception_code, listen_only=self.listen_only))
        if exception_code is None and self.function_code not in _NOT_COUNTED_AS_EVENTS:
            log.completed()
        if self._restart is not None:
            clear_log = self._restart
            self._restart = None
            self.counters.clear()
            log.event_count = 0
            if clear_log:
                log.clear_events()
            self.listen_only = False
            log.add(EVENT_RESTART)

    def _invalid(self, exception_code: int) -> bool:
        self.fire(SlaveEvent.REQUEST_INVALID)
        self.exception_code = exception_code
        return False

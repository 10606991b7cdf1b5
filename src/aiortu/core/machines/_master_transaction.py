"""What the master's state machine works on and answers with: one transaction to one unit
([`Transaction`][aiortu.core.machines.Transaction]), how its failed attempts are retried
([`RetryPolicy`][aiortu.core.machines.RetryPolicy]), and the machine's answer to each
event ([`Outcome`][aiortu.core.machines.Outcome]).

Sans-IO, like [`aiortu.core.machines`][aiortu.core.machines], which drives these; the
async master ([`aiortu.master`][aiortu.master]) makes a
[`Transaction`][aiortu.core.machines.Transaction] per request and acts on each
[`Outcome`][aiortu.core.machines.Outcome].
"""

from __future__ import annotations

import enum
from collections.abc import Collection
from dataclasses import dataclass, field
from typing import Final

from aiortu.core.codes import FunctionCode
from aiortu.core.errors import CRCError, FrameError, InvalidValue
from aiortu.core.pdu import ExceptionPDU, Request, Response
from aiortu.core.rtu import crc16, encode_frame

__all__ = (
    "DEFAULT_RETRY_ON",
    "SAFE_TO_REPEAT",
    "Failure",
    "Outcome",
    "OutcomeKind",
    "RetryPolicy",
    "SkipReason",
    "Transaction",
    "frame_error_from_discard",
)


class Failure(enum.Enum):
    """The kinds of failed attempt a [`RetryPolicy`][aiortu.core.machines.RetryPolicy] can
    retry."""

    TIMEOUT = "timeout"
    """No reply within the response timeout."""
    FRAME_ERROR = "frame error"
    """Bad bytes (CRC, framing) or a reply that did not decode, and no good reply."""


DEFAULT_RETRY_ON: Final[frozenset[Failure | int]] = frozenset(
    (Failure.TIMEOUT, Failure.FRAME_ERROR)
)
"""Retry on timeouts and frame errors, never on exception responses."""

SAFE_TO_REPEAT: Final[frozenset[int]] = frozenset(
    (
        # Reads: 01-04, 07, 0B, 0C, 11, 14, 18, 2B.
        FunctionCode.READ_COILS,
        FunctionCode.READ_DISCRETE_INPUTS,
        FunctionCode.READ_HOLDING_REGISTERS,
        FunctionCode.READ_INPUT_REGISTERS,
        FunctionCode.READ_EXCEPTION_STATUS,
        FunctionCode.GET_COMM_EVENT_COUNTER,
        FunctionCode.GET_COMM_EVENT_LOG,
        FunctionCode.REPORT_SERVER_ID,
        FunctionCode.READ_FILE_RECORD,
        FunctionCode.READ_FIFO_QUEUE,
        FunctionCode.ENCAPSULATED_INTERFACE_TRANSPORT,
        # Writes that leave the same state however often they run: 05, 06, 0F, 10, 15, 16.
        FunctionCode.WRITE_SINGLE_COIL,
        FunctionCode.WRITE_SINGLE_REGISTER,
        FunctionCode.WRITE_MULTIPLE_COILS,
        FunctionCode.WRITE_MULTIPLE_REGISTERS,
        FunctionCode.WRITE_FILE_RECORD,
        FunctionCode.MASK_WRITE_REGISTER,
    )
)
"""The function codes whose requests a failed attempt may send again by default.

Not among them: 17 (read/write multiple registers, whose write may change what it
reads), 08 (diagnostics: some sub-functions clear counters or restart the device) and
every code aiortu has no class for (user-defined, vendor codes): what they do is unknown.
"""


@dataclass(frozen=True, slots=True)
class RetryPolicy:
    """How often a failed attempt is repeated, after which failures, and for which requests.

    `retries` is the number of extra attempts (0 sends once). `retry_on` holds
    [`Failure`][aiortu.core.machines.Failure] members and, to retry exception responses
    too, exception codes (`ExceptionCode.SERVER_DEVICE_BUSY`, for instance). `repeatable` holds the
    function codes whose requests may be sent again
    ([`SAFE_TO_REPEAT`][aiortu.core.machines.SAFE_TO_REPEAT] by default: a timed-out write
    may have been done, and only an idempotent one can safely be done twice); a request of any other
    code is sent once.
    """

    retries: int = 2
    retry_on: frozenset[Failure | int] = DEFAULT_RETRY_ON
    repeatable: frozenset[int] = SAFE_TO_REPEAT

    def __post_init__(self) -> None:
        if isinstance(self.retries, bool) or not isinstance(self.retries, int) or self.retries < 0:
            raise InvalidValue("retries", self.retries, "an int >= 0")
        object.__setattr__(self, "retry_on", frozenset(self.retry_on))
        object.__setattr__(self, "repeatable", frozenset(self.repeatable))

    @classmethod
    def of(
        cls,
        retries: int,
        retry_on: Collection[Failure | int] | None = None,
        repeatable: Collection[int] | None = None,
    ) -> RetryPolicy:
        """A policy from the usual arguments; `None` means the default."""
        return cls(
            retries,
            DEFAULT_RETRY_ON if retry_on is None else frozenset(retry_on),
            SAFE_TO_REPEAT if repeatable is None else frozenset(repeatable),
        )

    def for_function(self, function_code: int) -> RetryPolicy:
        """This policy for a request of `function_code`: without retries unless the
        code is [`repeatable`][aiortu.core.machines.RetryPolicy]."""
        if self.retries == 0 or function_code in self.repeatable:
            return self
        return RetryPolicy(0, self.retry_on, self.repeatable)

    def with_retries(self, retries: int) -> RetryPolicy:
        """This policy with `retries` extra attempts."""
        if retries == self.retries:
            return self
        return RetryPolicy(retries, self.retry_on, self.repeatable)


class SkipReason(enum.StrEnum):
    """Why a frame was not taken as the reply."""

    STALE = "stale"
    """It began before a reply to the request could have (see
    [`Transaction.earliest_reply`][aiortu.core.machines.Transaction.earliest_reply])."""
    OTHER_UNIT = "other unit"
    """It comes from another unit."""
    OTHER_FUNCTION = "other function"
    """Its function code is neither the request's nor its exception form."""
    LATE = "late"
    """It does not answer the request, but it answers the unit's last request that timed
    out: that request's reply, come too late."""


class OutcomeKind(enum.Enum):
    """What the caller of the machine does next."""

    WAIT = "wait"
    """Keep waiting until [`deadline`][aiortu.core.machines.MasterMachine.deadline]."""
    DONE = "done"
    """The transaction is over: [`Outcome.response`][aiortu.core.machines.Outcome] (or
    `None` without reply)."""
    RETRY = "retry"
    """Send [`frame`][aiortu.core.machines.MasterMachine.frame] again, then call
    [`sent`][aiortu.core.machines.MasterMachine.sent]."""
    FAILED = "failed"
    """The transaction is over: raise [`Outcome.error`][aiortu.core.machines.Outcome]."""


@dataclass(slots=True)
class Outcome:
    """The machine's answer to an event; see
    [`OutcomeKind`][aiortu.core.machines.OutcomeKind]. Read it, do not change it (not
    frozen: one is made per reply, and a frozen dataclass takes twice as long)."""

    kind: OutcomeKind
    response: Response | ExceptionPDU | None = None
    error: Exception | None = None
    skipped: SkipReason | None = None


@dataclass(slots=True)
class Transaction:
    """One request to one unit, and what happened to it so far.

    `expects_reply` is false for broadcasts and for requests a device never answers (diagnostics 04,
    force listen-only mode); those wait `turnaround` seconds instead. `priority`, then
    `order`, place the transaction in its line's queue: lower runs first, equal keys in order
    of arrival (a caller's priority; a line server's listener priority and its fairness turn
    between connections). Set
    [`abandoned`][aiortu.core.machines.Transaction] when the caller is gone: the attempt
    in flight finishes (so that its reply cannot reach a later request) but is not retried.
    """

    unit: int
    request: Request
    timeout: float
    policy: RetryPolicy = field(default_factory=RetryPolicy)
    expects_reply: bool = True
    turnaround: float = 0.0
    priority: int = 0
    order: int = 0
    abandoned: bool = False
    attempts: int = 0
    """Attempts sent so far."""
    attempt_start: float = 0.0
    """When the current attempt began to go out."""
    attempt_end: float = 0.0
    """When the current attempt had left the wire."""
    reply_delay: float | None = None
    """The least delay from the end of a request on the wire to the arrival of the first
    byte of its reply (the unit's turnaround and that byte's wire time), where the line's
    wire times are real (a serial port, a paced virtual line); None where they are not
    (TCP, unpaced virtual lines, ptys): there a request's computed wire time may not have
    passed yet when its genuine reply arrives."""
    earliest_reply: float = 0.0
    """The earliest the first byte of a reply to the current attempt can arrive, set by
    [`sent`][aiortu.core.machines.MasterMachine.sent]: *attempt_end* plus
    *reply_delay*; a frame that began sooner is stale. Without *reply_delay* it is
    *attempt_start*, and a frame that ended sooner is stale."""
    frame_error: FrameError | None = None
    """The last frame error of the current attempt, if any."""
    failures: list[Failure] = field(default_factory=list)
    """The failure of every failed attempt, in order."""

    @property
    def frame(self) -> bytes:
        """The RTU frame of the request."""
        return encode_frame(self.unit, self.request.encode())


_CRC_REASONS: Final = frozenset(("crc", "noise"))


def frame_error_from_discard(data: bytes, reason: str) -> FrameError:
    """The error that discarded bytes stand for: [`CRCError`][aiortu.errors.CRCError] when a CRC is
    there to compare, else [`FrameError`][aiortu.errors.FrameError] with `reason`.

    Bytes discarded as noise (they came while the receiver still waited for the line's
    first silence, as a reply does right after the port was opened) hold no frame whose
    CRC checks, or the receiver would have handed it on: four or more of them are a CRC
    error as much as a frame closed by silence is.
    """
    if reason in _CRC_REASONS and len(data) >= 4:
        return CRCError(data[-2] | data[-1] << 8, crc16(data[:-2]))
    return FrameError(
        f"{len(data)} bytes discarded ({reason}): {data[:16].hex(' ')}", reason=reason
    )

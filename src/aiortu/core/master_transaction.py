"""What the master's state machine works on and answers with: one transaction to one
unit (:class:`Transaction`), how its failed attempts are retried (:class:`RetryPolicy`),
and the machine's answer to each event (:class:`Outcome`).

Sans-IO, like :mod:`aiortu.core.master_machine`, which drives these; the async master
(:mod:`aiortu.master._engine`) makes a :class:`Transaction` per request and acts on each
:class:`Outcome`.
"""

from __future__ import annotations

import enum
from collections.abc import Collection
from dataclasses import dataclass, field
from typing import Final

from aiortu.core.crc import crc16
from aiortu.core.errors import CRCError, FrameError
from aiortu.core.frame import encode_frame
from aiortu.core.pdu import ExceptionPDU, Request, Response

__all__ = (
    "DEFAULT_RETRY_ON",
    "Failure",
    "Outcome",
    "OutcomeKind",
    "RetryPolicy",
    "SkipReason",
    "Transaction",
    "frame_error_from_discard",
)


class Failure(enum.Enum):
    """The kinds of failed attempt a :class:`RetryPolicy` can retry."""

    TIMEOUT = "timeout"
    """No reply within the response timeout."""
    FRAME_ERROR = "frame error"
    """Bad bytes (CRC, framing) or a reply that did not decode, and no good reply."""


DEFAULT_RETRY_ON: Final[frozenset[Failure | int]] = frozenset(
    (Failure.TIMEOUT, Failure.FRAME_ERROR)
)
"""Retry on timeouts and frame errors, never on exception responses."""


@dataclass(frozen=True, slots=True)
class RetryPolicy:
    """How often a failed attempt is repeated, and after which failures.

    *retries* is the number of extra attempts (0 sends once). *retry_on* holds
    :class:`Failure` members and, to retry exception responses too, exception codes
    (``ExceptionCode.SERVER_DEVICE_BUSY``, for instance).
    """

    retries: int = 2
    retry_on: frozenset[Failure | int] = DEFAULT_RETRY_ON

    def __post_init__(self) -> None:
        if isinstance(self.retries, bool) or not isinstance(self.retries, int) or self.retries < 0:
            raise ValueError(f"retries must be an int >= 0, not {self.retries!r}")
        object.__setattr__(self, "retry_on", frozenset(self.retry_on))

    @classmethod
    def of(cls, retries: int, retry_on: Collection[Failure | int] | None = None) -> RetryPolicy:
        """A policy from the usual arguments; *retry_on* ``None`` means the default."""
        return cls(retries, DEFAULT_RETRY_ON if retry_on is None else frozenset(retry_on))


class SkipReason(enum.StrEnum):
    """Why a frame was not taken as the reply."""

    STALE = "stale"
    """It began before a reply to the request could have (see
    :attr:`Transaction.earliest_reply`)."""
    OTHER_UNIT = "other unit"
    """It comes from another unit."""
    OTHER_FUNCTION = "other function"
    """Its function code is neither the request's nor its exception form."""
    MALFORMED = "malformed"
    """It does not decode, or does not answer the request (count, echo)."""


class OutcomeKind(enum.Enum):
    """What the caller of the machine does next."""

    WAIT = "wait"
    """Keep waiting until :attr:`~aiortu.core.master_machine.MasterMachine.deadline`."""
    DONE = "done"
    """The transaction is over: :attr:`Outcome.response` (or ``None`` without reply)."""
    RETRY = "retry"
    """Send :attr:`~aiortu.core.master_machine.MasterMachine.frame` again, then call
    :meth:`~aiortu.core.master_machine.MasterMachine.sent`."""
    FAILED = "failed"
    """The transaction is over: raise :attr:`Outcome.error`."""


@dataclass(slots=True)
class Outcome:
    """The machine's answer to an event; see :class:`OutcomeKind`. Read it, do not change
    it (not frozen: one is made per reply, and a frozen dataclass takes twice as long)."""

    kind: OutcomeKind
    response: Response | ExceptionPDU | None = None
    error: Exception | None = None
    skipped: SkipReason | None = None


@dataclass(slots=True)
class Transaction:
    """One request to one unit, and what happened to it so far.

    *expects_reply* is false for broadcasts and for requests a device never answers
    (diagnostics 04, force listen-only mode); those wait *turnaround* seconds instead.
    Set :attr:`abandoned` when the caller is gone: the attempt in flight finishes (so
    that its reply cannot reach a later request) but is not retried.
    """

    unit: int
    request: Request
    timeout: float
    policy: RetryPolicy = field(default_factory=RetryPolicy)
    expects_reply: bool = True
    turnaround: float = 0.0
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
    :meth:`~aiortu.core.master_machine.MasterMachine.sent`: *attempt_end* plus
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


def frame_error_from_discard(data: bytes, reason: str) -> FrameError:
    """The error that discarded bytes stand for: :class:`CRCError` when a CRC is there to
    compare, else :class:`FrameError` with *reason*."""
    if reason == "crc" and len(data) >= 4:
        return CRCError(data[-2] | data[-1] << 8, crc16(data[:-2]))
    return FrameError(
        f"{len(data)} bytes discarded ({reason}): {data[:16].hex(' ')}", reason=reason
    )

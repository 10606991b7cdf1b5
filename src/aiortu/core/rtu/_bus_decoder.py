"""What the frames on a bus mean: requests, replies, their pairing, and one-line descriptions.

A passive observer of an RTU line sees frames without being told who sent them. A
[`BusDecoder`][aiortu.core.rtu.BusDecoder] is fed what a receiver in the `MONITOR` role
yields ([`FrameReceived`][aiortu.core.rtu.FrameReceived] and
[`FrameDiscarded`][aiortu.core.rtu.FrameDiscarded]) and turns each into a
[`DecodedFrame`][aiortu.core.rtu.DecodedFrame]: the unit, the direction (request, reply,
exception reply, broadcast, or unknown), the decoded PDU or the decode error, the CRC status, a
one-line description and a JSON-able dict:

    >>> decoder = BusDecoder()
    >>> decoder.decode_frame(bytes.fromhex("11 03 00 6B 00 03 76 87")).description
    'unit 17 read holding registers 107..109 (3)'
    >>> decoder.decode_frame(bytes.fromhex("11 03 06 AE 41 56 52 43 40 49 AD")).description
    'unit 17 reply holding 107..109 = [44609, 22098, 17216]'

How a frame's direction is told, in order:

1. Unit 0 is a broadcast, always a request. A function code with the top bit set is an
   exception reply.
2. Otherwise the frame is decoded both as a request and as a reply. When only one succeeds, that is
   the direction. (Decoding checks the exact length, so this is where the layouts of
   [`expected_request_length`][aiortu.core.rtu.expected_request_length] and
   [`expected_response_length`][aiortu.core.rtu.expected_response_length] tell a request from a
   reply.)
3. When both succeed (05, 06, 08, 15 and 16 echo their request; user-defined codes have
   no known layout; a few reads such as `01 03 ..` fit both), the conversation decides:
   the frame after a request to a unit with a function code, from that unit with that
   code, is its reply; anything else is a request.
4. When neither decodes, the layout whose predicted length fits names the direction and
   the decode error is reported; if no layout fits, the direction is unknown.

A reply is paired with the request it answers, so that the reply to a read can name the
addresses it carries. A request that gets no reply stays pending until the next request,
a frame that looks like its mangled reply, or, with `reply_timeout`, until that long has
passed.

[`describe_frame`][aiortu.core.rtu.describe_frame] describes one frame on its own, for
traces.
"""

from __future__ import annotations

import enum
from collections.abc import Iterable, Iterator
from dataclasses import dataclass
from typing import Any

# Importing the PDU modules registers their classes for decode_request/decode_response.
from aiortu.core.codes import BROADCAST_UNIT, EXCEPTION_BIT
from aiortu.core.errors import CRCError, FrameError, MalformedPDU
from aiortu.core.pdu import (
    PDU,
    DiagnosticsRequest,
    ExceptionPDU,
    Request,
    Response,
    decode_request,
    decode_response,
    describe_reply,
    describe_request,
    enum_name,
    function_name,
    hex_text,
    pdu_to_dict,
    table_access,
)
from aiortu.core.rtu._crc import crc16
from aiortu.core.rtu._frame import (
    CANNOT_KNOW,
    MIN_FRAME_LENGTH,
    expected_request_length,
    expected_response_length,
)
from aiortu.core.rtu._receiver import DiscardReason, FrameDiscarded, FrameReceived

__all__ = (
    "BusDecoder",
    "CrcStatus",
    "DecodedFrame",
    "Direction",
    "describe_frame",
)


class Direction(enum.StrEnum):
    """Who sent a frame, as far as the bus shows it."""

    REQUEST = "request"
    """A master's request to one unit."""
    REPLY = "reply"
    """A slave's normal reply."""
    EXCEPTION = "exception"
    """A slave's exception reply (function code with the top bit set)."""
    BROADCAST = "broadcast"
    """A request to unit 0, which every slave executes and none answers."""
    UNKNOWN = "unknown"
    """Bytes that are neither: a bad CRC, noise, or a frame no layout fits."""


class CrcStatus(enum.StrEnum):
    """Whether the bytes carried a good CRC."""

    OK = "ok"
    """A frame whose CRC checks."""
    ERROR = "error"
    """Bytes ended by silence whose last two bytes are not their CRC."""
    UNCHECKED = "unchecked"
    """Not a frame at all: too short, broken by a gap, noise, or an overflow."""


@dataclass(frozen=True, slots=True)
class DecodedFrame:
    """One frame (or run of discarded bytes) seen on the bus, with its meaning.

    `time` and `end` are when its first and last bytes arrived, in the clock of the
    receiver. `unit` and `function_code` are `None` for discarded bytes. `pdu` is
    the decoded request, response, [`ExceptionPDU`][aiortu.core.pdu.ExceptionPDU] or
    [`RawPDU`][aiortu.core.pdu.RawPDU], or `None` when decoding failed; `error` then
    says why (it is also set when a decoded reply does not answer its request). A reply
    paired with its request carries it in `request` and its `index` in
    `request_index`.
    """

    index: int
    """The position of this record in what the decoder produced, from 0."""
    time: float
    end: float
    frame: bytes
    """The bytes as received (unit, PDU and CRC, or the discarded bytes)."""
    unit: int | None
    direction: Direction
    crc: CrcStatus
    function_code: int | None
    pdu: PDU | None
    error: FrameError | None
    description: str
    """One line saying what the frame means, e.g. `unit 17 read coils 19..37 (19)`."""
    request: Request | None = None
    request_index: int | None = None
    discard_reason: DiscardReason | None = None

    @property
    def function(self) -> str | None:
        """The name of the function code (without the exception bit), if there is one."""
        if self.function_code is None:
            return None
        return function_name(self.function_code)

    def to_dict(self, *, raw: bool = True) -> dict[str, Any]:
        """The record as a dict of JSON types; with `raw`, the bytes in hex under `frame`.

        Keys: `index`, `time`, `end`, `unit`, `direction`, `function_code`,
        `function`, `crc`, `description`, `pdu` (the PDU's class under `type`
        and its fields), `error`, `request_index`, `discard_reason`, and, when the
        frame reads or writes a table, `table`, `address`, `count` and `values`.
        """
        out: dict[str, Any] = {
            "index": self.index,
            "time": self.time,
            "end": self.end,
            "unit": self.unit,
            "direction": self.direction.value,
            "function_code": self.function_code,
            "function": self.function,
            "crc": self.crc.value,
            "description": self.description,
            "pdu": None if self.pdu is None else pdu_to_dict(self.pdu),
            "error": None if self.error is None else str(self.error),
            "request_index": self.request_index,
            "discard_reason": None if self.discard_reason is None else self.discard_reason.value,
        }
        if self.pdu is not None:
            out.update(table_access(self.pdu, self.request))
        if raw:
            out["frame"] = hex_text(self.frame, limit=None)
        return out


@dataclass(slots=True)
class _Pending:
    unit: int
    function_code: int
    request: Request
    index: int
    end: float


class BusDecoder:
    """Decodes the frames of one bus in order, pairing replies with requests.

    `reply_timeout` (seconds, in the receiver's clock): a request not answered within it
    is forgotten, so that a later frame with the same unit and function code is taken for
    a new request. `None` (the default) keeps a request pending until the next one.
    """

    def __init__(self, *, reply_timeout: float | None = None) -> None:
        self.reply_timeout = reply_timeout
        self._pending: _Pending | None = None
        self._count = 0

    def reset(self) -> None:
        """Forget the conversation (after the line was reopened)."""
        self._pending = None

    def feed(self, event: FrameReceived | FrameDiscarded) -> DecodedFrame:
        """Decode one receiver output."""
        if isinstance(event, FrameDiscarded):
            return self._discarded(event.data, event.reason, event.start, event.end)
        return self._received(event.frame, event.start, event.end, None, None)

    def feed_all(self, events: Iterable[FrameReceived | FrameDiscarded]) -> Iterator[DecodedFrame]:
        """Decode receiver outputs in order, yielding one record each."""
        for event in events:
            yield self.feed(event)

    def decode_frame(
        self,
        frame: bytes,
        time: float = 0.0,
        *,
        direction: Direction | str | None = None,
        request: Request | None = None,
    ) -> DecodedFrame:
        """Decode whole frame bytes, checking the CRC here (for frames not from a receiver).

        `direction` (`"request"` or `"reply"`) skips the guessing; `request` pairs a
        reply with that request instead of the pending one.
        """
        if len(frame) < MIN_FRAME_LENGTH:
            return self._discarded(frame, DiscardReason.TOO_SHORT, time, time)
        if crc16(frame) != 0:
            return self._discarded(frame, DiscardReason.CRC, time, time)
        forced = None if direction is None else Direction(direction)
        return self._received(bytes(frame), time, time, forced, request)

    # -- the decoding ----------------------------------------------------------------

    def _next_index(self) -> int:
        index = self._count
        self._count += 1
        return index

    def _discarded(
        self, data: bytes, reason: DiscardReason, start: float, end: float
    ) -> DecodedFrame:
        pending = self._pending
        if (
            pending is not None
            and len(data) >= 2
            and data[0] == pending.unit
            and data[1] & ~EXCEPTION_BIT == pending.function_code
        ):
            # Most likely the pending request's reply, mangled: whatever comes next is
            # a new request, not that reply.
            self._pending = None
        error: FrameError | None = None
        if reason is DiscardReason.CRC:
            crc = CrcStatus.ERROR
            if len(data) >= MIN_FRAME_LENGTH:
                error = CRCError(data[-2] | data[-1] << 8, crc16(data[:-2]))
            text = "CRC error"
        else:
            crc = CrcStatus.UNCHECKED
            text = _DISCARD_TEXT[reason]
        return DecodedFrame(
            index=self._next_index(),
            time=start,
            end=end,
            frame=bytes(data),
            unit=None,
            direction=Direction.UNKNOWN,
            crc=crc,
            function_code=None,
            pdu=None,
            error=error,
            description=f"{text}: {hex_text(data)}",
            discard_reason=reason,
        )

    def _received(
        self,
        frame: bytes,
        start: float,
        end: float,
        forced: Direction | None,
        request: Request | None,
    ) -> DecodedFrame:
        index = self._next_index()
        unit = frame[0]
        pdu_bytes = frame[1:-2]
        code = pdu_bytes[0] & ~EXCEPTION_BIT
        pending = self._pending
        if (
            pending is not None
            and self.reply_timeout is not None
            and start - pending.end > self.reply_timeout
        ):
            pending = self._pending = None
        answers_pending = (
            pending is not None and pending.unit == unit and pending.function_code == code
        )
        direction, pdu, error = _classify(unit, frame, pdu_bytes, forced, answers_pending)

        paired: Request | None = request
        paired_index: int | None = None
        if direction in (Direction.REPLY, Direction.EXCEPTION):
            if paired is None and answers_pending and pending is not None:
                paired, paired_index = pending.request, pending.index
                self._pending = None
            if paired is not None and isinstance(pdu, Response) and error is None:
                try:
                    paired.check_response(pdu)
                except MalformedPDU as mismatch:
                    error = mismatch
        elif direction in (Direction.REQUEST, Direction.BROADCAST):
            # A new request means the master gave up waiting for any earlier reply.
            expects_reply = direction is Direction.REQUEST and not (
                isinstance(pdu, DiagnosticsRequest) and not pdu.expects_reply
            )
            self._pending = (
                _Pending(unit, code, pdu, index, end)
                if isinstance(pdu, Request) and expects_reply
                else None
            )

        description = _describe(
            unit, code, direction, pdu=pdu, error=error, request=paired, frame=frame
        )
        return DecodedFrame(
            index=index,
            time=start,
            end=end,
            frame=frame,
            unit=unit,
            direction=direction,
            crc=CrcStatus.OK,
            function_code=code,
            pdu=pdu,
            error=error,
            description=description,
            request=paired,
            request_index=paired_index,
        )


_DISCARD_TEXT = {
    DiscardReason.GAP: "frame broken by a gap",
    DiscardReason.TOO_SHORT: "too short",
    DiscardReason.NOISE: "noise",
    DiscardReason.OVERFLOW: "overflow",
}


def _try(decode: Any, pdu: bytes) -> tuple[PDU | None, MalformedPDU | None]:
    try:
        return decode(pdu), None
    except MalformedPDU as error:
        return None, error


def _classify(
    unit: int,
    frame: bytes,
    pdu_bytes: bytes,
    forced: Direction | None,
    answers_pending: bool,
) -> tuple[Direction, PDU | None, MalformedPDU | None]:
    """The direction of a frame with a good CRC, and its decoded PDU or the decode error."""
    if unit == BROADCAST_UNIT:
        return (Direction.BROADCAST, *_try(decode_request, pdu_bytes))
    if pdu_bytes[0] & EXCEPTION_BIT:
        return (Direction.EXCEPTION, *_try(decode_response, pdu_bytes))
    if forced is Direction.REQUEST:
        return (Direction.REQUEST, *_try(decode_request, pdu_bytes))
    if forced is not None:
        return (Direction.REPLY, *_try(decode_response, pdu_bytes))
    as_request, request_error = _try(decode_request, pdu_bytes)
    as_reply, reply_error = _try(decode_response, pdu_bytes)
    if as_request is not None and as_reply is not None:
        if answers_pending:
            return Direction.REPLY, as_reply, None
        return Direction.REQUEST, as_request, None
    if as_request is not None:
        return Direction.REQUEST, as_request, None
    if as_reply is not None:
        return Direction.REPLY, as_reply, None
    fits_request = expected_request_length(frame) in (len(frame), CANNOT_KNOW)
    fits_reply = expected_response_length(frame) in (len(frame), CANNOT_KNOW)
    if fits_request and fits_reply:
        fits_request = not answers_pending
        fits_reply = answers_pending
    if fits_request:
        return Direction.REQUEST, None, request_error
    if fits_reply:
        return Direction.REPLY, None, reply_error
    return Direction.UNKNOWN, None, reply_error if answers_pending else request_error


# -- descriptions ------------------------------------------------------------------------


def _describe(
    unit: int,
    code: int,
    direction: Direction,
    *,
    pdu: PDU | None,
    error: MalformedPDU | FrameError | None,
    request: Request | None,
    frame: bytes,
) -> str:
    who = "broadcast" if direction is Direction.BROADCAST else f"unit {unit}"
    if direction is Direction.UNKNOWN:
        return f"{who} unknown frame ({function_name(code)}): {hex_text(frame)}"
    if pdu is None:
        kind = "reply" if direction is Direction.EXCEPTION else direction.value
        kind = "request" if direction is Direction.BROADCAST else kind
        return f"{who} malformed {kind} ({function_name(code)}): {error}"
    if isinstance(pdu, ExceptionPDU):
        to = describe_request(request) if request is not None else function_name(code)
        return f"{who} exception {enum_name(pdu.exception_code)} to {to}"
    if isinstance(pdu, Request) and direction is not Direction.REPLY:
        return f"{who} {describe_request(pdu)}"
    assert isinstance(pdu, Response)
    text = f"{who} {describe_reply(pdu, request)}"
    if error is not None:
        text += f" (does not answer the request: {error})"
    return text


def describe_frame(
    frame: bytes,
    *,
    direction: Direction | str | None = None,
    request: Request | None = None,
) -> str:
    """Describe one whole frame (unit, PDU, CRC) on its own, in one line.

    Without `direction`, a frame that is both a valid request and a valid reply is taken
    for a request. Pass `"request"` or `"reply"` when the sender is known (a slave
    tracing what it receives and sends), and the `request` a reply answers to name the
    addresses of its values:

        >>> describe_frame(bytes.fromhex("01 81 02 C1 91"))
        'unit 1 exception ILLEGAL_DATA_ADDRESS to read coils'
    """
    return BusDecoder().decode_frame(frame, direction=direction, request=request).description

"""The RTU receiver: bytes and times in, frames out. A state machine written as a table.

The machine follows the receiver of the Modbus over Serial Line spec (v1.02, section 2.5.1.1):

    INIT     wait for silence; bytes here are noise      -- silence -->  IDLE
    IDLE     waiting for a frame                         -- a byte -->   START
    START    the address byte arrived                    -- a byte -->   DATABUF
    DATABUF  storing the frame                           -- silence, or the known length
                                                            with a good CRC -->  RESPONSE
    RESPONSE checking the frame; handing it on           -- checked -->  IDLE

and `TRANSITIONS` is that diagram as data: each (state, event)
pair names the next state and the action. A pair missing from the table is a bug and raises
[`ReceiverError`][aiortu.core.rtu.ReceiverError], never a silent no-op. The documentation draws
its diagram from the same table.

Two things go beyond the timer-driven spec (docs/protocol.md explains why):

* It is length-aware. Once the first bytes tell a frame's length (see
  [`aiortu.core.rtu`][aiortu.core.rtu]) and the CRC checks at that length, the frame is complete
  at once, without waiting for t3.5 of silence. Silence still ends frames whose length cannot be
  predicted. Its role says which layouts to expect: a master expects replies; a slave expects
  requests for its own units and either layout for other units, since on a multi-drop bus it also
  hears other slaves' replies (a reply and a request with the same function code have different
  lengths, and the CRC tells which one it is). Where both layouts are possible, the first predicted
  length whose CRC checks wins, so a frame whose first bytes happen to make a good shorter frame
  (about one in 65,536 of the frames that can be read both ways) is split in two; waiting for
  silence instead would take the length-aware completion from every short reply.
* It resynchronises. A buffer that fails its CRC, or outgrows the longest frame, is
  searched for a frame that starts later in it (garbage right before a good frame), and a
  frame whose CRC fails is never accepted. The search is cheap even in a flood of noise:
  a precompiled pattern finds where a unit address and a function code with a known
  layout may start a frame (see `Receiver._salvage`). A slave searches garbage for
  its own requests only (see [`Role.SLAVE`][aiortu.core.rtu.Role.SLAVE]).

Timing comes in as arguments: [`Receiver.feed`][aiortu.core.rtu.Receiver.feed] takes a chunk
and the time it arrived, [`Receiver.expire`][aiortu.core.rtu.Receiver.expire] the current time,
and [`Receiver.next_deadline`][aiortu.core.rtu.Receiver.next_deadline] tells the caller when to
call [`expire`][aiortu.core.rtu.Receiver.expire] next. Chunks are assumed to hold back-to-back
characters that ended arriving at the given time, which is what a serial driver or a USB adapter
hands over.

The t1.5 rule comes in two modes. `strict` follows the spec: a gap of more than t1.5 inside a frame
discards it, and t3.5 of silence ends a frame. `tolerant` (the default) ignores gaps inside frames,
because USB adapters and virtual lines deliver bytes in bursts, and ends a frame only after a longer
silence ([`TOLERANT_FRAME_SILENCE`][aiortu.core.rtu.TOLERANT_FRAME_SILENCE], or t3.5 when that
is longer). INIT ends on t3.5 of silence in both modes, as the spec says: on a line that is never
quiet for the longer bound (a master polling back to back), a receiver that started listening would
otherwise stay deaf, then hand on frames it had gathered as noise long after they came.
"""

from __future__ import annotations

import enum
from collections.abc import Callable, Iterable
from dataclasses import dataclass
from typing import Final

from aiortu.core.codes import BROADCAST_UNIT
from aiortu.core.rtu._crc import crc16
from aiortu.core.rtu._frame import (
    CANNOT_KNOW,
    MAX_FRAME_LENGTH,
    MIN_FRAME_LENGTH,
    NEED_MORE,
    expected_request_length,
    expected_response_length,
)
from aiortu.core.rtu._frame_search import LAST_UNIT, FrameSearch
from aiortu.core.serial import LineSettings

__all__ = (
    "TOLERANT_FRAME_SILENCE",
    "TRANSITIONS",
    "DiscardReason",
    "FrameDiscarded",
    "FrameReceived",
    "Receiver",
    "ReceiverError",
    "ReceiverEvent",
    "ReceiverState",
    "Role",
    "TimingMode",
)

TOLERANT_FRAME_SILENCE: Final = 0.020
"""Silence (seconds) that ends a frame in tolerant mode, unless t3.5 is longer: it rides
over the latency timer of USB adapters (often 16 ms), which may split a frame in two."""


class ReceiverState(enum.Enum):
    """The states of the RTU receiver, named after the spec."""

    __hash__ = object.__hash__  # singletons: identity hashing, in C (fast table lookups)

    INIT = "INIT"
    IDLE = "IDLE"
    START = "START"
    DATABUF = "DATABUF"
    RESPONSE = "RESPONSE"


class ReceiverEvent(enum.Enum):
    """What can happen to the receiver."""

    __hash__ = object.__hash__  # singletons: identity hashing, in C (fast table lookups)

    CHARS = "chars"
    """Characters arrived within the allowed gap of the previous ones."""
    LATE_CHARS = "late chars"
    """Characters arrived after a gap longer than t1.5 but shorter than the frame silence
    (strict mode only)."""
    SILENCE = "silence"
    """The line has been silent long enough to end a frame (t3.5, or the tolerant bound)."""
    COMPLETE = "complete"
    """The frame reached its predicted length and its CRC checks."""
    OVERFLOW = "overflow"
    """The buffer outgrew the longest frame (256 bytes)."""
    CHECKED = "checked"
    """The closed frame has been checked and handed on."""


class Role(enum.Enum):
    """Which frames the receiver expects, for length prediction."""

    MASTER = "master"
    """Replies only."""
    SLAVE = "slave"
    """Requests to its own units and broadcasts; requests or replies of other units.

    Inside garbage (bytes that did not make a frame, searched after a CRC failure or an
    overflow) a slave looks only for requests to its own units and broadcasts: frames of
    other units found there would help nobody, and leaving them out makes the search
    cheap. Frames of other units framed normally (after silence, or back to back with
    other frames) are still received; one glued to garbage is discarded with it, so a
    slave's bus message count (diagnostics 08/0B) does not count it, and its bytes count
    towards the communication error or overrun counters instead.
    """
    MONITOR = "monitor"
    """Requests or replies of any unit (a passive sniffer)."""


class TimingMode(enum.StrEnum):
    """How the receiver applies the t1.5 rule (see the module docstring)."""

    STRICT = "strict"
    TOLERANT = "tolerant"


class DiscardReason(enum.StrEnum):
    """Why bytes were not handed on as a frame."""

    CRC = "crc"
    """The bytes ended by silence do not make a frame whose CRC checks."""
    GAP = "gap"
    """A gap longer than t1.5 broke the frame (strict mode)."""
    TOO_SHORT = "too short"
    """Fewer than 4 bytes before silence."""
    OVERFLOW = "overflow"
    """More than 256 bytes without a frame boundary."""
    NOISE = "noise"
    """Bytes that arrived while the receiver waited for silence."""


class ReceiverError(RuntimeError):
    """An event arrived in a state whose table has no entry for it. Caused by a bug in aiortu."""


@dataclass(frozen=True, slots=True)
class FrameReceived:
    """A frame whose CRC checks: its bytes (unit, PDU and CRC) and when it arrived.

    `start` is when its first byte arrived and `end` when its last byte did, in the
    clock of the times given to the receiver.
    """

    frame: bytes
    start: float
    end: float

    @property
    def unit(self) -> int:
        """The unit address, the first byte."""
        return self.frame[0]

    @property
    def pdu(self) -> bytes:
        """The PDU: the frame without the address and the CRC."""
        return self.frame[1:-2]


@dataclass(frozen=True, slots=True)
class FrameDiscarded:
    """Bytes that did not make a frame, with the reason and when they arrived."""

    data: bytes
    reason: DiscardReason
    start: float
    end: float


ReceiverOutput = FrameReceived | FrameDiscarded

_S = ReceiverState
_E = ReceiverEvent

TRANSITIONS: Final[dict[tuple[ReceiverState, ReceiverEvent], tuple[ReceiverState, str]]] = {
    # (state, event): (next state, action)
    (_S.INIT, _E.CHARS): (_S.INIT, "gather_noise"),
    (_S.INIT, _E.LATE_CHARS): (_S.INIT, "gather_noise"),
    (_S.INIT, _E.SILENCE): (_S.IDLE, "salvage_noise"),
    (_S.INIT, _E.OVERFLOW): (_S.INIT, "salvage_overflow"),
    (_S.IDLE, _E.CHARS): (_S.START, "begin_frame"),
    (_S.IDLE, _E.LATE_CHARS): (_S.START, "begin_frame"),
    (_S.IDLE, _E.SILENCE): (_S.IDLE, "nothing"),
    (_S.START, _E.CHARS): (_S.DATABUF, "store"),
    (_S.START, _E.LATE_CHARS): (_S.INIT, "discard_gap"),
    (_S.START, _E.SILENCE): (_S.IDLE, "discard_short"),
    (_S.DATABUF, _E.CHARS): (_S.DATABUF, "store"),
    (_S.DATABUF, _E.LATE_CHARS): (_S.INIT, "discard_gap"),
    (_S.DATABUF, _E.SILENCE): (_S.RESPONSE, "check_closed_frame"),
    (_S.DATABUF, _E.COMPLETE): (_S.RESPONSE, "deliver_complete_frame"),
    (_S.DATABUF, _E.OVERFLOW): (_S.INIT, "salvage_overflow"),
    (_S.RESPONSE, _E.CHECKED): (_S.IDLE, "nothing"),
}
"""The receiver's transitions: `(state, event) -> (next state, action name)`."""


class Receiver:
    """The RTU receiver of one line (see the module docstring).

    `settings` give the character time, t1.5 and t3.5. `role` chooses the layouts to expect; `units`
    are a slave's own unit addresses (for [`Role.SLAVE`][aiortu.core.rtu.Role.SLAVE]). `timing`
    is `"tolerant"` (default) or `"strict"`. `frame_silence` overrides the silence that ends a frame
    (default: t3.5 in strict mode, the longer of t3.5 and
    [`TOLERANT_FRAME_SILENCE`][aiortu.core.rtu.TOLERANT_FRAME_SILENCE] in tolerant mode).

    `now` is when it starts listening: given, it starts in INIT (a frame under way when
    the port opened is not taken for a whole one); left out, in IDLE. `whole_frames`: each
    chunk is whole frames, handed over at once (a Modbus TCP stream's), so there is no
    character time: two frames in one chunk's clock reading are two.
    """

    def __init__(
        self,
        settings: LineSettings | None = None,
        *,
        role: Role = Role.MASTER,
        units: Iterable[int] = (),
        timing: TimingMode | str = TimingMode.TOLERANT,
        frame_silence: float | None = None,
        now: float | None = None,
        whole_frames: bool = False,
    ) -> None:
        self.settings = settings if settings is not None else LineSettings()
        self.role = role
        self.units = frozenset(units)
        self.timing = TimingMode(timing)
        self.char_time = 0.0 if whole_frames else self.settings.char_time
        """Seconds per character: when a chunk's first byte came, and the silence between
        chunks; none for a stream of whole frames."""
        self.t1_5 = self.settings.t1_5
        if frame_silence is None:
            frame_silence = self.settings.t3_5
            if self.timing is TimingMode.TOLERANT:
                frame_silence = max(frame_silence, TOLERANT_FRAME_SILENCE)
        if frame_silence < 0:
            raise ValueError(f"frame_silence must be >= 0, not {frame_silence}")
        self.frame_silence = frame_silence
        self._init_silence = min(self.settings.t3_5, frame_silence)
        self._strict = self.timing is TimingMode.STRICT
        self.state = ReceiverState.IDLE if now is None else ReceiverState.INIT
        self._buffer = bytearray()
        if role is Role.SLAVE:
            self._search = FrameSearch((BROADCAST_UNIT, *self.units), requests=True, replies=False)
        else:
            self._search = FrameSearch(
                range(LAST_UNIT + 1), requests=role is Role.MONITOR, replies=True
            )
        self._candidates: list[int] = []
        self._predicted = False
        self._first: float = 0.0
        self._last: float | None = now
        self._out: list[ReceiverOutput] = []
        self._now = 0.0
        self._first_arrival = 0.0
        self._chunk_end = 0.0
        self._chunk_length = 0
        self._end_index = 0
        # The length of the whole frame a chunk begins with, where one layout tells it.
        self._whole: Callable[[bytes], int]
        if role is Role.MASTER:
            self._whole = expected_response_length
        elif role is Role.SLAVE:
            self._whole = self._whole_request_length
        else:
            self._whole = lambda data: CANNOT_KNOW  # a monitor cannot tell which layout
        self._actions: dict[
            tuple[ReceiverState, ReceiverEvent], tuple[ReceiverState, Callable[..., int]]
        ] = {
            key: (target, getattr(self, f"_{action}"))
            for key, (target, action) in TRANSITIONS.items()
        }

    # -- the driving interface -------------------------------------------------------

    def feed(self, data: bytes, now: float) -> list[ReceiverOutput]:
        """Take a chunk of bytes that finished arriving at `now`; return what it completed."""
        out: list[ReceiverOutput] = []
        self._out = out
        count = len(data)
        if not count:
            return self._expire(now, out)
        char_time = self.char_time
        first_arrival = now - (count - 1) * char_time
        last = self._last
        if last is not None:
            first_arrival = max(first_arrival, last)
            silence = first_arrival - char_time - last
            # (IDLE, SILENCE) does nothing (see TRANSITIONS), and IDLE is where each frame
            # of a poll loop finds the receiver: no need to fire it there.
            if self.state is not _S.IDLE:
                needed = self._silence_needed()
                if silence >= needed:
                    self._fire(ReceiverEvent.SILENCE, b"", 0, last + needed)
        else:
            silence = float("inf")
        state = self.state
        if state is _S.IDLE and self._take_whole_frame(data, now):
            out.append(FrameReceived(bytes(data), first_arrival, now))
            return out
        late = self._strict and silence > self.t1_5 and state in _MID_FRAME
        event = ReceiverEvent.LATE_CHARS if late else ReceiverEvent.CHARS
        self._first_arrival = first_arrival
        self._chunk_end = now
        self._chunk_length = count
        position = 0
        while position < count:
            position = self._fire(event, data, position, now)
            event = ReceiverEvent.CHARS
        self._last = now
        return out

    def _take_whole_frame(self, data: bytes, now: float) -> bool:
        """Take `data`, a chunk that finished arriving at `now`, if it is exactly one frame
        with a good CRC reaching an idle receiver (the work of START, DATABUF and RESPONSE
        at once); return whether it was. False changes nothing."""
        if (
            self.state is _S.IDLE
            and len(data) >= MIN_FRAME_LENGTH
            and self._whole(data) == len(data)
            and crc16(data) == 0
        ):
            self._last = now
            return True
        return False

    def take_expected_frame(self, data: bytes, now: float, checked: bytes | None = None) -> bool:
        """Take `data`, a chunk that finished arriving at `now`, if it is one frame with a
        good CRC reaching an idle receiver; return whether it was. False changes nothing:
        give the chunk to [`feed`][aiortu.core.rtu.Receiver.feed].

        This is what [`feed`][aiortu.core.rtu.Receiver.feed] does with such a chunk, without
        building its [`FrameReceived`][aiortu.core.rtu.FrameReceived], for a caller that has
        already matched the chunk's length to the layout of the frame it expects (a link told what
        reply to look for): only the state and the CRC are left to check here. `checked` is a frame
        whose CRC was found good before (the last reply to the same request): a chunk equal to it
        has the same CRC, so it is not computed again."""
        if self.state is _S.IDLE and (
            data == checked or (len(data) >= MIN_FRAME_LENGTH and crc16(data) == 0)
        ):
            self._last = now
            return True
        return False

    def expire(self, now: float) -> list[ReceiverOutput]:
        """Tell the receiver the time is `now`; return what the silence so far completed."""
        out: list[ReceiverOutput] = []
        self._out = out
        return self._expire(now, out)

    def next_deadline(self) -> float | None:
        """When [`expire`][aiortu.core.rtu.Receiver.expire] should next be called, or `None` if
        no timer runs."""
        if self.state is ReceiverState.IDLE or self._last is None:
            return None
        return self._last + self._silence_needed()

    def _silence_needed(self) -> float:
        """The silence that fires SILENCE now: t3.5 in INIT, as the spec has it (the
        tolerant bound would keep a receiver that starts on a busy line deaf, then have
        it hand on old frames gathered as noise), else the frame silence."""
        if self.state is _S.INIT:
            return self._init_silence
        return self.frame_silence

    def reset(self, now: float) -> None:
        """Forget any partial frame and wait for silence from `now` (after reopening a port)."""
        self._buffer.clear()
        self._search.forget()
        self._last = now
        self.state = ReceiverState.INIT

    # -- the machine -----------------------------------------------------------------

    def _expire(self, now: float, out: list[ReceiverOutput]) -> list[ReceiverOutput]:
        deadline = self.next_deadline()
        if deadline is not None and now >= deadline:
            self._fire(ReceiverEvent.SILENCE, b"", 0, deadline)
        return out

    def _fire(self, event: ReceiverEvent, data: bytes, position: int, now: float) -> int:
        """Run one transition; return how far into `data` it consumed."""
        entry = self._actions.get((self.state, event))
        if entry is None:
            raise ReceiverError(f"no transition for event {event.name} in state {self.state.name}")
        target, action = entry
        self._now = now
        self.state = target
        result: int = action(data, position)
        return result

    def _arrival(self, position: int) -> float:
        """When the byte at `position` of the current chunk finished arriving."""
        return max(
            self._first_arrival,
            self._chunk_end - (self._chunk_length - 1 - position) * self.char_time,
        )

    # -- actions: each takes the chunk and a position, returns the new position --------

    def _nothing(self, data: bytes, position: int) -> int:
        return position

    def _gather_noise(self, data: bytes, position: int) -> int:
        if not self._buffer:
            self._first = self._arrival(position)
            self._search.forget()
        room = MAX_FRAME_LENGTH - len(self._buffer)
        take = len(data) - position
        if take > room:
            self._buffer += data[position : position + room]
            self._fire(ReceiverEvent.OVERFLOW, b"", 0, self._arrival(position + room - 1))
            return position + room
        self._buffer += data[position:]
        return len(data)

    def _salvage_noise(self, data: bytes, position: int) -> int:
        self._salvage(DiscardReason.NOISE, keep_tail=False)
        return position

    def _salvage_overflow(self, data: bytes, position: int) -> int:
        # Overflow strikes in the middle of a chunk, before the chunk's time is recorded:
        # the last byte held arrived at the time the event was fired with.
        self._salvage(DiscardReason.OVERFLOW, keep_tail=True, end=self._now)
        return position

    def _begin_frame(self, data: bytes, position: int) -> int:
        self._buffer.clear()
        self._buffer.append(data[position])
        self._first = self._arrival(position)
        self._candidates = []
        self._predicted = False
        self._search.forget()
        return position + 1

    def _store(self, data: bytes, position: int) -> int:
        buffer = self._buffer
        end = len(data)
        while position < end:
            if not self._predicted:
                buffer.append(data[position])
                position += 1
                self._predict()
                if self._complete_at_candidate(position):
                    return position
                continue
            if self._candidates:
                target = self._candidates[0]
                take = min(end - position, target - len(buffer))
                buffer += data[position : position + take]
                position += take
                if self._complete_at_candidate(position):
                    return position
                continue
            room = MAX_FRAME_LENGTH - len(buffer)
            if end - position > room:
                buffer += data[position : position + room]
                position += room
                self._fire(ReceiverEvent.OVERFLOW, b"", 0, self._arrival(position - 1))
                return position
            buffer += data[position:]
            return end
        return position

    def _whole_request_length(self, data: bytes) -> int:
        """The length of the request `data` begins with, if it is for one of our units
        (else < 1: a slave salvages no other unit's frame out of a chunk)."""
        own = data[0] in self.units or data[0] == BROADCAST_UNIT
        return expected_request_length(data) if own else CANNOT_KNOW

    def _predict(self) -> None:
        """Set the candidate lengths of the frame in the buffer, once its first bytes tell."""
        buffer = self._buffer
        role = self.role
        if role is Role.MASTER:
            guesses: tuple[int, ...] = (expected_response_length(buffer),)
        elif role is Role.SLAVE and (buffer[0] in self.units or buffer[0] == BROADCAST_UNIT):
            guesses = (expected_request_length(buffer),)
        else:
            guesses = (expected_request_length(buffer), expected_response_length(buffer))
        # NEED_MORE (0) and CANNOT_KNOW (-1) are never >= the bytes held: the filters drop them.
        have = len(buffer)
        if NEED_MORE in guesses:
            # A length one layout already gives is checked even while the other layout
            # still needs bytes: a 7-byte 2B/0E request completes at 7 instead of waiting
            # for the reply layout's object count at byte 8. At most one guess is left.
            self._candidates = [guess for guess in guesses if guess >= have]
            return
        self._predicted = True
        self._candidates = sorted({guess for guess in guesses if guess >= have})

    def _complete_at_candidate(self, position: int) -> bool:
        """Check the CRC when the buffer reaches a candidate length; fire COMPLETE if it holds.

        `position` is how far into the current chunk the buffer reaches.
        """
        candidates = self._candidates
        buffer = self._buffer
        while candidates and len(buffer) >= candidates[0]:
            length = candidates.pop(0)
            if length == len(buffer) and length >= MIN_FRAME_LENGTH and crc16(buffer) == 0:
                self._end_index = position - 1
                self._fire(ReceiverEvent.COMPLETE, b"", 0, self._now)
                return True
        return False

    def _deliver_complete_frame(self, data: bytes, position: int) -> int:
        end = self._arrival(self._end_index)
        self._out.append(FrameReceived(bytes(self._buffer), self._first, end))
        self._buffer.clear()
        self._fire(ReceiverEvent.CHECKED, b"", 0, self._now)
        return position

    def _check_closed_frame(self, data: bytes, position: int) -> int:
        buffer = self._buffer
        if len(buffer) >= MIN_FRAME_LENGTH and crc16(buffer) == 0:
            self._out.append(FrameReceived(bytes(buffer), self._first, self._last_arrival()))
            buffer.clear()
        else:
            self._salvage(
                DiscardReason.CRC if len(buffer) >= MIN_FRAME_LENGTH else DiscardReason.TOO_SHORT
            )
        self._fire(ReceiverEvent.CHECKED, b"", 0, self._now)
        return position

    def _discard_gap(self, data: bytes, position: int) -> int:
        self._discard(bytes(self._buffer), DiscardReason.GAP, self._last_arrival())
        self._buffer.clear()
        return position

    def _discard_short(self, data: bytes, position: int) -> int:
        self._discard(bytes(self._buffer), DiscardReason.TOO_SHORT, self._last_arrival())
        self._buffer.clear()
        return position

    # -- helpers ---------------------------------------------------------------------

    def _last_arrival(self) -> float:
        return self._last if self._last is not None else self._now

    def _discard(
        self, data: bytes, reason: DiscardReason, end: float, start: float | None = None
    ) -> None:
        if data:
            start = self._first if start is None else start
            self._out.append(FrameDiscarded(data, reason, start, end))

    def _salvage(
        self, reason: DiscardReason, *, keep_tail: bool = False, end: float | None = None
    ) -> None:
        """Hand on every valid frame found inside the buffer; discard the rest with `reason`.

        With `keep_tail` (overflow), bytes at the end that could still begin a frame stay
        in the buffer; otherwise the buffer is emptied.

        Where frames may start, and whether one does, is
        `FrameSearch`'s business; after an overflow it
        remembers what it judged in the bytes kept.
        """
        buffer = self._buffer
        if end is None:
            end = self._last_arrival()
        length = len(buffer)
        last_start = length - MIN_FRAME_LENGTH
        garbage_from = 0
        resume = 0
        pending: list[int] = []
        search = self._search
        frame_at = search.frame_at
        for offset in search.offsets(buffer, last_start):
            if offset < resume:
                continue  # inside a frame found before
            found = frame_at(buffer, offset)
            if found > 0:
                if offset > garbage_from:
                    self._discard(
                        bytes(buffer[garbage_from:offset]),
                        reason,
                        self._estimate(offset - 1, end),
                        self._estimate(garbage_from, end),
                    )
                self._out.append(
                    FrameReceived(
                        bytes(buffer[offset : offset + found]),
                        self._estimate(offset, end, None if keep_tail else length),
                        self._estimate(offset + found - 1, end, None if keep_tail else length),
                    )
                )
                resume = garbage_from = offset + found
            elif found == NEED_MORE:
                pending.append(offset)
        if keep_tail:
            # The bytes from the first offset that needs more bytes stay; so do the last
            # bytes, too few to judge, which may begin a frame.
            keep_from = pending[0] if pending else length
            keep_from = min(keep_from, length - (MIN_FRAME_LENGTH - 1))
            keep_from = max(keep_from, garbage_from, length - (MAX_FRAME_LENGTH - 1))
            if keep_from > garbage_from:
                self._discard(
                    bytes(buffer[garbage_from:keep_from]),
                    reason,
                    self._estimate(keep_from - 1, end),
                    self._estimate(garbage_from, end),
                )
            del buffer[:keep_from]
            # Later salvages time the kept bytes from the first of them.
            self._first = self._estimate(keep_from, end)
            search.keep(pending, keep_from, max(resume, last_start + 1))
        else:
            if length > garbage_from:
                self._discard(
                    bytes(buffer[garbage_from:]), reason, end, self._estimate(garbage_from, end)
                )
            buffer.clear()
            search.forget()

    def _estimate(self, index: int, end: float, length: int | None = None) -> float:
        """When byte `index` of the buffer arrived, assuming back-to-back characters.

        With `length`, the buffer's length when its last byte arrived at `end`: no sooner
        than the bytes after it allow. A frame found after a pause in the buffer (garbage,
        a pause, a reply) is then never dated before it came, which a master relies on
        to tell a reply from a stale frame.
        """
        char_time = self.char_time
        time = min(end, self._first + index * char_time)
        if length is None:
            return time
        return max(time, end - (length - 1 - index) * char_time)


_MID_FRAME = frozenset((ReceiverState.START, ReceiverState.DATABUF))

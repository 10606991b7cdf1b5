"""The ASCII receiver: characters and times in, frames out. A state machine written as a table.

The machine is the serial line spec's (2.5.2.1, figure 14):

    IDLE         waiting for ':'; other characters are noise     -- ':' -->  RECEPTION
    RECEPTION    storing hex characters                          -- CR -->   WAITING_END
                 a ':' drops the frame and starts a new one      -- ':' -->  RECEPTION
    WAITING_END  after CR: the delimiter (LF, unless Diagnostics 08/03 changed it) ends the
                 frame, which is checked and handed on           -- END -->  IDLE

and [`ASCII_TRANSITIONS`][aiortu.core.ascii.ASCII_TRANSITIONS] is that diagram as data: each
(state, event) pair names the next state and the action. A pair missing from the table is a bug
and raises [`ReceiverError`][aiortu.core.rtu.ReceiverError], never a silent no-op. The
documentation draws its diagram from the same table.

A gap between two characters of a frame longer than the inter-character timeout (1 s by
default, configurable, as the spec says) drops the frame; so do a frame longer than 513
characters, a character after CR that is not the delimiter, malformed hex and a wrong LRC.
Every dropped frame comes out as an
[`AsciiFrameDiscarded`][aiortu.core.ascii.AsciiFrameDiscarded] with its reason and a
one-sentence detail; a frame is never accepted unless its LRC checks.

Timing comes in as arguments, as for the RTU receiver:
[`feed`][aiortu.core.ascii.AsciiReceiver.feed] takes a chunk and the time its last character
arrived, [`expire`][aiortu.core.ascii.AsciiReceiver.expire] the current time, and
[`next_deadline`][aiortu.core.ascii.AsciiReceiver.next_deadline] says when to call
[`expire`][aiortu.core.ascii.AsciiReceiver.expire] next. Chunks hold back-to-back characters.

The machine fires one event per run of ordinary characters, not one per character, and a
frame that reaches an idle receiver whole (':', at most 510 characters with neither ':' nor CR
among them, CR and the delimiter, all in one chunk) is one event, FRAME: the work of START,
CHARS, CR and END at once, its hex and LRC checked once, through its own row of the table.
Whatever follows it in the chunk is fed on as usual. A frame that comes in pieces, or with a
':' or a CR inside, takes the four steps (START, CHARS, CR, END), which give the same frames
and the same discards.
"""

from __future__ import annotations

import enum
from collections.abc import Callable
from dataclasses import dataclass
from typing import Final

from aiortu.core.ascii._frame import ASCII_START, CR, LF, MAX_ASCII_FRAME_LENGTH, check_ascii_body
from aiortu.core.errors import FrameError, InvalidValue, LRCError
from aiortu.core.rtu import ReceiverError
from aiortu.core.serial import LineSettings

__all__ = (
    "ASCII_TRANSITIONS",
    "DEFAULT_ASCII_TIMEOUT",
    "AsciiDiscardReason",
    "AsciiEvent",
    "AsciiFrameDiscarded",
    "AsciiFrameReceived",
    "AsciiReceiver",
    "AsciiReceiverOutput",
    "AsciiState",
)

DEFAULT_ASCII_TIMEOUT: Final = 1.0
"""The spec's default inter-character timeout, in seconds."""

_MAX_BODY: Final = MAX_ASCII_FRAME_LENGTH - 3


class AsciiState(enum.Enum):
    """The states of the ASCII receiver, named after the spec."""

    __hash__ = object.__hash__  # singletons: identity hashing, in C (fast table lookups)

    IDLE = "IDLE"
    RECEPTION = "RECEPTION"
    WAITING_END = "WAITING_END"


class AsciiEvent(enum.Enum):
    """What can happen to the ASCII receiver."""

    __hash__ = object.__hash__

    START = "start"
    """A ':' arrived."""
    CHARS = "chars"
    """A run of other characters arrived (after CR: one character that is not the delimiter)."""
    CR = "cr"
    """A CR arrived during reception."""
    END = "end"
    """The delimiter arrived after CR."""
    TIMEOUT = "timeout"
    """The gap since the last character exceeded the inter-character timeout."""
    OVERLONG = "overlong"
    """The frame outgrew 513 characters."""
    FRAME = "frame"
    """A ':' reached an idle receiver with the rest of its frame in the same chunk: at most 510
    characters, none of them ':' or CR, then CR and the delimiter (START, CHARS, CR, END at
    once)."""


class AsciiDiscardReason(enum.StrEnum):
    """Why characters were not handed on as a frame."""

    NOISE = "noise"
    """Characters outside a frame (before its ':')."""
    RESTART = "restart"
    """A ':' began a new frame before this one ended."""
    TIMEOUT = "timeout"
    """A gap longer than the inter-character timeout."""
    OVERLONG = "overlong"
    """More than 513 characters."""
    NO_END = "no end"
    """A character after CR that is not the delimiter."""
    MALFORMED = "malformed"
    """An odd number of characters, a character that is not a hex digit, or a wrong length."""
    LRC = "lrc"
    """The LRC does not check."""


@dataclass(frozen=True, slots=True)
class AsciiFrameReceived:
    """A frame whose LRC checks: its bytes (unit, PDU and LRC, decoded from hex) and when the
    ':' and the delimiter arrived."""

    frame: bytes
    start: float
    end: float

    @property
    def unit(self) -> int:
        """The unit address, the first byte."""
        return self.frame[0]

    @property
    def pdu(self) -> bytes:
        """The PDU: the frame without the address and the LRC."""
        return self.frame[1:-1]


@dataclass(frozen=True, slots=True)
class AsciiFrameDiscarded:
    """Characters that did not make a frame: the reason, a one-sentence `detail`, and when the
    first and the last of them arrived."""

    data: bytes
    reason: AsciiDiscardReason
    start: float
    end: float
    detail: str


AsciiReceiverOutput = AsciiFrameReceived | AsciiFrameDiscarded
"""What [`feed`][aiortu.core.ascii.AsciiReceiver.feed] and
[`expire`][aiortu.core.ascii.AsciiReceiver.expire] return a list of."""

_S = AsciiState
_E = AsciiEvent
# The members feed() compares with on every character run, as plain globals.
_IDLE: Final = _S.IDLE
_RECEPTION: Final = _S.RECEPTION
_WAITING_END: Final = _S.WAITING_END
_START: Final = _E.START
_CHARS: Final = _E.CHARS
_CR: Final = _E.CR
_END: Final = _E.END
_FRAME: Final = _E.FRAME
_MALFORMED: Final = AsciiDiscardReason.MALFORMED

ASCII_TRANSITIONS: Final[dict[tuple[AsciiState, AsciiEvent], tuple[AsciiState, str]]] = {
    # (state, event): (next state, action)
    (_S.IDLE, _E.START): (_S.RECEPTION, "begin_frame"),
    (_S.IDLE, _E.CHARS): (_S.IDLE, "skip_noise"),
    (_S.IDLE, _E.FRAME): (_S.IDLE, "check_whole_frame"),
    (_S.RECEPTION, _E.START): (_S.RECEPTION, "restart_frame"),
    (_S.RECEPTION, _E.CHARS): (_S.RECEPTION, "store"),
    (_S.RECEPTION, _E.CR): (_S.WAITING_END, "store_cr"),
    (_S.RECEPTION, _E.TIMEOUT): (_S.IDLE, "discard_timeout"),
    (_S.RECEPTION, _E.OVERLONG): (_S.IDLE, "discard_overlong"),
    (_S.WAITING_END, _E.START): (_S.RECEPTION, "restart_frame"),
    (_S.WAITING_END, _E.END): (_S.IDLE, "check_frame"),
    (_S.WAITING_END, _E.CHARS): (_S.IDLE, "discard_no_end"),
    (_S.WAITING_END, _E.TIMEOUT): (_S.IDLE, "discard_timeout"),
}
"""The ASCII receiver's transitions: `(state, event) -> (next state, action name)`."""


class AsciiReceiver:
    """The ASCII receiver of one line (see the module docstring).

    `settings` give the character time (default: 9600 7E1, 10 bits a character, as the spec's
    ASCII characters are); `timeout` is the longest gap allowed between two characters of a
    frame, in seconds; `delimiter` the character that ends a frame after CR (LF unless
    Diagnostics 08/03 changed it; it may be changed later through
    [`delimiter`][aiortu.core.ascii.AsciiReceiver.delimiter]).
    """

    def __init__(
        self,
        settings: LineSettings | None = None,
        *,
        timeout: float = DEFAULT_ASCII_TIMEOUT,
        delimiter: int = LF,
    ) -> None:
        self.settings = settings if settings is not None else LineSettings(9600, bytesize=7)
        if not timeout > 0:
            raise InvalidValue("timeout", timeout, "a positive number of seconds")
        self.timeout = timeout
        self.char_time = self.settings.char_time
        self._delimiter = LF
        self.delimiter = delimiter
        self.state = AsciiState.IDLE
        self._buffer = bytearray()
        self._first = 0.0
        self._last: float | None = None
        self._now = 0.0
        self._first_arrival = 0.0
        self._chunk_end = 0.0
        self._chunk_length = 0
        self._frame_end = 0  # where the frame of a FRAME event ends in its chunk
        self._out: list[AsciiReceiverOutput] = []
        self._actions: dict[
            tuple[AsciiState, AsciiEvent], tuple[AsciiState, Callable[[bytes, int], int]]
        ] = {
            key: (target, getattr(self, f"_{action}"))
            for key, (target, action) in ASCII_TRANSITIONS.items()
        }

    @property
    def delimiter(self) -> int:
        """The character that ends a frame after CR (LF by default; Diagnostics 08/03)."""
        return self._delimiter

    @delimiter.setter
    def delimiter(self, value: int) -> None:
        if not 0 <= value <= 0xFF or value == ASCII_START:
            raise InvalidValue("delimiter", value, "a byte other than ':'")
        self._delimiter = value

    # -- the driving interface -------------------------------------------------------

    def feed(self, data: bytes, now: float) -> list[AsciiReceiverOutput]:
        """Take a chunk of characters whose last arrived at `now`; return what it completed."""
        out: list[AsciiReceiverOutput] = []
        self._out = out
        count = len(data)
        if not count:
            return self._expire(now, out)
        first_arrival = now - (count - 1) * self.char_time
        last = self._last
        if last is not None:
            first_arrival = first_arrival if first_arrival > last else last
            if self.state is not _S.IDLE and first_arrival - self.char_time - last > self.timeout:
                self._fire(_E.TIMEOUT, data, 0, last + self.timeout)
        self._first_arrival = first_arrival
        self._chunk_end = now
        self._chunk_length = count
        position = 0
        delimiter = self._delimiter
        fire = self._fire
        tail = count - 1
        char_time = self.char_time
        while position < count:
            byte = data[position]
            if byte == ASCII_START:
                event = _START
                if self.state is _IDLE and self._whole_frame_at(data, position):
                    event = _FRAME
            elif byte == CR and self.state is _RECEPTION:
                event = _CR
            elif byte == delimiter and self.state is _WAITING_END:
                event = _END
            else:
                event = _CHARS
            # When this character arrived (`_arrival`, inline: four calls a frame fed whole).
            arrival = now - (tail - position) * char_time
            arrival = arrival if arrival > first_arrival else first_arrival
            position = fire(event, data, position, arrival)
        self._last = now
        return out

    def next_deadline(self) -> float | None:
        """When the frame under way times out if nothing more arrives, or None when idle."""
        if self.state is _S.IDLE or self._last is None:
            return None
        return self._last + self.timeout

    def expire(self, now: float) -> list[AsciiReceiverOutput]:
        """Tell the receiver the time is `now`; return the frame a timeout dropped, if any."""
        out: list[AsciiReceiverOutput] = []
        self._out = out
        return self._expire(now, out)

    def _expire(self, now: float, out: list[AsciiReceiverOutput]) -> list[AsciiReceiverOutput]:
        deadline = self.next_deadline()
        if deadline is not None and now > deadline:
            self._fire(_E.TIMEOUT, b"", 0, deadline)
        return out

    def _fire(self, event: AsciiEvent, data: bytes, position: int, now: float) -> int:
        """Run one transition; return how far into `data` it consumed."""
        entry = self._actions.get((self.state, event))
        if entry is None:
            raise ReceiverError(f"no transition for event {event.name} in state {self.state.name}")
        target, action = entry
        self._now = now
        self.state = target
        return action(data, position)

    def _whole_frame_at(self, data: bytes, position: int) -> bool:
        """Whether the ':' at `position` begins a frame that ends in this chunk with nothing
        on the way that the four steps would treat apart (a ':', a CR before the end, more
        than 513 characters); if so, note where it ends for the FRAME action."""
        cr = data.find(b"\r", position + 1, position + MAX_ASCII_FRAME_LENGTH - 1)
        if (
            cr > 0
            and cr + 1 < len(data)
            and data[cr + 1] == self._delimiter
            and data.find(b":", position + 1, cr) < 0
        ):
            self._frame_end = cr + 2
            return True
        return False

    def _arrival(self, position: int) -> float:
        """When the character at `position` of the current chunk finished arriving."""
        return max(
            self._first_arrival,
            self._chunk_end - (self._chunk_length - 1 - position) * self.char_time,
        )

    # -- actions: each takes the chunk and a position, returns the new position --------

    def _begin_frame(self, data: bytes, position: int) -> int:
        self._buffer.clear()
        self._first = self._now
        return position + 1

    def _skip_noise(self, data: bytes, position: int) -> int:
        end = data.find(b":", position)
        end = len(data) if end < 0 else end
        self._discard(
            bytes(data[position:end]),
            AsciiDiscardReason.NOISE,
            "characters outside a frame (before its ':') were dropped",
            self._now,
            self._arrival(end - 1),
        )
        return end

    def _restart_frame(self, data: bytes, position: int) -> int:
        self._drop(AsciiDiscardReason.RESTART, "a ':' began a new frame before this one ended")
        return self._begin_frame(data, position)

    def _store(self, data: bytes, position: int) -> int:
        # The run ends at CR or at a ':' before it (two finds cost less than a regex search).
        end = data.find(b"\r", position)
        if end < 0:
            end = len(data)
        colon = data.find(b":", position, end)
        if colon >= 0:
            end = colon
        room = _MAX_BODY - len(self._buffer)
        if end - position > room:
            self._buffer += data[position : position + room + 1]
            self._fire(_E.OVERLONG, data, position, self._arrival(position + room))
            return position + room + 1
        self._buffer += data[position:end]
        return end

    def _store_cr(self, data: bytes, position: int) -> int:
        self._buffer.append(CR)
        return position + 1

    def _discard_timeout(self, data: bytes, position: int) -> int:
        self._drop(
            AsciiDiscardReason.TIMEOUT,
            f"a gap of more than {self.timeout:g} s between two characters broke the frame",
        )
        return position

    def _discard_overlong(self, data: bytes, position: int) -> int:
        self._drop(
            AsciiDiscardReason.OVERLONG,
            f"an ASCII frame is at most {MAX_ASCII_FRAME_LENGTH} characters",
        )
        return position

    def _discard_no_end(self, data: bytes, position: int) -> int:
        self._buffer.append(data[position])
        self._drop(
            AsciiDiscardReason.NO_END,
            f"CR was followed by 0x{data[position]:02X}, not the delimiter 0x{self._delimiter:02X}",
        )
        return position + 1

    def _check_whole_frame(self, data: bytes, position: int) -> int:
        # START, CHARS, CR and END at once: the frame ends where _whole_frame_at saw it end.
        end = self._frame_end
        arrival = self._chunk_end - (self._chunk_length - end) * self.char_time
        arrival = arrival if arrival > self._first_arrival else self._first_arrival
        try:
            frame = check_ascii_body(data[position + 1 : end - 2])
        except FrameError as error:
            reason = AsciiDiscardReason.LRC if isinstance(error, LRCError) else _MALFORMED
            self._discard(bytes(data[position:end]), reason, str(error), self._now, arrival)
        else:
            self._out.append(AsciiFrameReceived(frame, self._now, arrival))
        return end

    def _check_frame(self, data: bytes, position: int) -> int:
        try:
            frame = check_ascii_body(self._buffer[:-1])  # without the CR
        except LRCError as error:
            self._reject(AsciiDiscardReason.LRC, str(error))
        except FrameError as error:
            self._reject(AsciiDiscardReason.MALFORMED, str(error))
        else:
            self._out.append(AsciiFrameReceived(frame, self._first, self._now))
            self._buffer.clear()
        return position + 1

    # -- helpers ---------------------------------------------------------------------

    def _reject(self, reason: AsciiDiscardReason, detail: str) -> None:
        self._buffer.append(self._delimiter)
        self._drop(reason, detail)

    def _drop(self, reason: AsciiDiscardReason, detail: str) -> None:
        """Discard the frame held: ':' and the characters stored (a CR among them)."""
        self._discard(b":" + self._buffer, reason, detail, self._first, self._now)
        self._buffer.clear()

    def _discard(
        self, data: bytes, reason: AsciiDiscardReason, detail: str, start: float, end: float
    ) -> None:
        if data:
            self._out.append(AsciiFrameDiscarded(data, reason, start, end, detail))

"""Serial line timing: character time, t1.5, t3.5 and the wire time of frames.

Every figure is derived from the line settings alone, in seconds, with no clock: the
receiver, the link and the benchmarks take their numbers from here.

The spec's rules (Modbus over Serial Line v1.02, 2.5.1.1): a character is a start bit,
the data bits, an optional parity bit and the stop bits; frames are separated by at least
3.5 character times (t3.5) of silence, and a gap of more than 1.5 character times (t1.5)
inside a frame breaks it. Above 19200 baud the spec fixes t1.5 at 750 us and t3.5 at
1750 us, because per-character timers get too short for devices to honour.
"""

from __future__ import annotations

import enum
from dataclasses import dataclass

from aiortu.core.errors import InvalidValue

__all__ = (
    "FIXED_T1_5",
    "FIXED_T3_5",
    "FIXED_TIMING_ABOVE_BAUDRATE",
    "LineSettings",
    "Parity",
)

FIXED_TIMING_ABOVE_BAUDRATE = 19200
"""Above this baud rate t1.5 and t3.5 are the fixed values below."""

FIXED_T1_5 = 750e-6
"""t1.5 in seconds above 19200 baud."""

FIXED_T3_5 = 1750e-6
"""t3.5 in seconds above 19200 baud."""


class Parity(enum.StrEnum):
    """The parity of a serial character, spelled as pyserial spells it."""

    NONE = "N"
    EVEN = "E"
    ODD = "O"
    MARK = "M"
    SPACE = "S"


@dataclass(frozen=True, slots=True)
class LineSettings:
    """The settings of a serial line and the timing they imply.

    The defaults are the spec's: 19200 baud, 8 data bits, even parity, 1 stop bit
    (8E1, 11 bits a character).

    >>> LineSettings(9600).t3_5
    0.004010416666666667
    """

    baudrate: int = 19200
    bytesize: int = 8
    parity: Parity | str = Parity.EVEN
    stopbits: float = 1

    def __post_init__(self) -> None:
        if not isinstance(self.baudrate, int) or isinstance(self.baudrate, bool):
            raise InvalidValue("baudrate", self.baudrate, "a positive integer")
        if self.baudrate <= 0:
            raise InvalidValue("baudrate", self.baudrate, "a positive integer")
        if self.bytesize not in (5, 6, 7, 8):
            raise InvalidValue("bytesize", self.bytesize, "5, 6, 7 or 8")
        try:
            parity = Parity(str(self.parity).upper()[:1])
        except ValueError:
            raise InvalidValue("parity", self.parity, "N, E, O, M or S") from None
        object.__setattr__(self, "parity", parity)
        if self.stopbits not in (1, 1.5, 2):
            raise InvalidValue("stopbits", self.stopbits, "1, 1.5 or 2")

    @property
    def bits_per_character(self) -> float:
        """Start bit + data bits + parity bit (if any) + stop bits."""
        parity_bits = 0 if self.parity is Parity.NONE else 1
        return 1 + self.bytesize + parity_bits + self.stopbits

    @property
    def char_time(self) -> float:
        """Seconds one character takes on the wire."""
        return self.bits_per_character / self.baudrate

    @property
    def t1_5(self) -> float:
        """The longest gap allowed between two characters of one frame, in seconds."""
        if self.baudrate > FIXED_TIMING_ABOVE_BAUDRATE:
            return FIXED_T1_5
        return 1.5 * self.char_time

    @property
    def t3_5(self) -> float:
        """The shortest silence between two frames, in seconds."""
        if self.baudrate > FIXED_TIMING_ABOVE_BAUDRATE:
            return FIXED_T3_5
        return 3.5 * self.char_time

    def wire_time(self, length: int) -> float:
        """Seconds a frame of `length` bytes takes on the wire, sent back to back."""
        return length * self.char_time

    def transaction_time(self, request_length: int, reply_length: int) -> float:
        """The shortest time a request/reply pair can take on this line.

        Both frames at the character rate plus two t3.5 silences: the one before the
        reply and the one before the next request. Device processing time is not counted.
        """
        return self.wire_time(request_length + reply_length) + 2 * self.t3_5

    def transaction_rate(self, request_length: int, reply_length: int) -> float:
        """The wire-limited request/reply pairs per second (see
        [`transaction_time`][aiortu.core.serial.LineSettings.transaction_time])."""
        return 1.0 / self.transaction_time(request_length, reply_length)

    def __str__(self) -> str:
        stop = int(self.stopbits) if self.stopbits == int(self.stopbits) else self.stopbits
        return f"{self.baudrate} {self.bytesize}{Parity(self.parity).value}{stop}"

"""Serial-line settings shared by every serial framing: baud rate, parity, stop bits and
the character times (t1.5, t3.5) they give."""

from __future__ import annotations

from aiortu._public import publish
from aiortu.core.serial._timing import (
    FIXED_T1_5,
    FIXED_T3_5,
    FIXED_TIMING_ABOVE_BAUDRATE,
    LineSettings,
    Parity,
)

__all__ = (
    "FIXED_T1_5",
    "FIXED_T3_5",
    "FIXED_TIMING_ABOVE_BAUDRATE",
    "LineSettings",
    "Parity",
)

publish(__name__, __all__, globals())

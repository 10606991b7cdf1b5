"""Finding frames inside bytes that did not make one: the receiver's resynchronisation.

When bytes end in silence, or overflow the 256-byte buffer, without making one valid frame (garbage
glued to a reply, a flood of noise with requests inside), the receiver asks a
`FrameSearch` where valid frames start in them. A frame is
found only where its CRC checks at the length its first bytes predict, so a search never accepts a
frame whose CRC fails.

The search is cheap on noise: a precompiled pattern finds the offsets where an expected unit address
is followed by a function code with a known layout; a length is predicted only there, and the CRC is
checked only when the predicted frame is all in the buffer. The search also remembers what it has
judged (`FrameSearch.keep`), so bytes kept after an
overflow are not searched again: a flood costs a pattern scan per byte, not a prediction per offset
per overflow.
"""

from __future__ import annotations

import re
from collections.abc import Callable, Iterable, Iterator
from typing import Final

from aiortu.core.codes import MEI_READ_DEVICE_IDENTIFICATION
from aiortu.core.rtu._crc import crc16
from aiortu.core.rtu._frame import (
    CANNOT_KNOW,
    MAX_FRAME_LENGTH,
    MIN_FRAME_LENGTH,
    NEED_MORE,
    expected_request_length,
    expected_response_length,
)

__all__ = ("LAST_UNIT", "FrameSearch")

LAST_UNIT: Final = 247
"""The highest unit address a device may have; frames from 248..255 are not searched for."""

_HEAD: Final = 11
"""Bytes that tell the length of every frame layout but the 2B/0E reply (the longest: the
byte count of a 17 request at offset 10)."""

_MEI: Final = 0x2B


class FrameSearch:
    """Where valid frames start in a buffer, for one receiver.

    `addresses` are the unit addresses to look for; `requests` and `replies` say which
    layouts to expect (a master: replies; a slave: requests to its own units; a monitor:
    both, from anyone).
    """

    def __init__(self, addresses: Iterable[int], *, requests: bool, replies: bool) -> None:
        self.requests = requests
        self.replies = replies
        codes: frozenset[int] = frozenset()
        if requests:
            codes |= _REQUEST_CODES
        if replies:
            codes |= _RESPONSE_CODES
        wanted = sorted({address for address in addresses if 0 <= address < 256})
        pattern = b"(?=[" + _byte_class(wanted) + b"][" + _byte_class(codes) + b"])"
        self._starts = re.compile(pattern)
        self._scan_from = 0
        self._pending: list[int] = []

    def forget(self) -> None:
        """The buffer starts afresh: no offset of it has been searched yet."""
        self._scan_from = 0
        if self._pending:
            self._pending = []

    def offsets(self, buffer: bytearray, last_start: int) -> Iterator[int]:
        """The offsets up to `last_start` where a frame may start, in order, not yet judged."""
        yield from self._pending
        # The pattern looks two bytes ahead: offsets up to last_start need last_start + 2.
        for match in self._starts.finditer(buffer, self._scan_from, last_start + 2):
            yield match.start()

    def keep(self, pending: list[int], keep_from: int, scanned_to: int) -> None:
        """The buffer's first `keep_from` bytes are dropped; remember what was judged.

        `pending` are the offsets that needed more bytes, `scanned_to` the first offset
        the pattern has not scanned yet (both in the buffer before the drop).
        """
        self._pending = [offset - keep_from for offset in pending if offset >= keep_from]
        self._scan_from = max(0, scanned_to - keep_from)

    def frame_at(self, buffer: bytearray, offset: int) -> int:
        """The length of a valid frame starting at `offset`, or NEED_MORE / CANNOT_KNOW.

        Only for offsets `offsets` gave: unit
        address and function code are known.
        """
        function_code = buffer[offset + 1]
        if self.requests and not self.replies:
            head = buffer[offset : offset + _HEAD]
            guesses: tuple[int, ...] = (expected_request_length(head),)
        else:
            # A 2B/0E reply's length needs every object's length byte, however far into
            # the frame; every other layout is told by the first few bytes.
            size = MAX_FRAME_LENGTH if function_code == _MEI else _HEAD
            head = buffer[offset : offset + size]
            guesses = (expected_response_length(head),)
            if self.requests:
                guesses = (expected_request_length(head), *guesses)
        need_more = False
        available = len(buffer) - offset
        for guess in guesses:
            if guess == NEED_MORE:
                need_more = True
            elif guess >= MIN_FRAME_LENGTH:
                if guess > available:
                    need_more = True
                elif crc16(buffer[offset : offset + guess]) == 0:
                    return guess
        return NEED_MORE if need_more else CANNOT_KNOW


def _known_codes(predict: Callable[[bytes], int]) -> frozenset[int]:
    """The function codes whose frames `predict` can tell the length of."""
    return frozenset(
        code
        for code in range(256)
        if predict(bytes((1, code)) + bytes(_HEAD - 2)) != CANNOT_KNOW
        or predict(bytes((1, code, MEI_READ_DEVICE_IDENTIFICATION)) + bytes(_HEAD - 3))
        != CANNOT_KNOW
    )


_REQUEST_CODES: Final = _known_codes(expected_request_length)
_RESPONSE_CODES: Final = _known_codes(expected_response_length)


def _byte_class(values: Iterable[int]) -> bytes:
    return b"".join(b"\\x%02x" % value for value in sorted(values))

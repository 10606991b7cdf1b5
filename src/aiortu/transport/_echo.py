"""Removing the local echo that some RS-485 adapters return.

A half-duplex RS-485 adapter whose receiver stays enabled while it transmits hands every byte we
send straight back to us, ahead of the device's reply.
[`LocalEchoFilter`][aiortu.transport.LocalEchoFilter] remembers what was sent and strips exactly
those bytes from the front of the received stream, however the echo is split across reads.

Mismatch policy: when a received byte differs from the next expected echo byte, the echo was
corrupted (two transmitters collided, or the line is faulty) or the adapter does not echo at all.
The filter then stops stripping: it forgets the rest of the expected echo, passes the mismatching
byte and everything after it on unchanged, and counts the event in
[`LocalEchoFilter.mismatches`][aiortu.transport.LocalEchoFilter.mismatches]. Passing the bytes on,
rather than dropping them, leaves the decision to the frame receiver, which rejects the garbage on
its CRC and resynchronises, so the master sees a frame error or a timeout and can retry; nothing is
ever silently swallowed beyond the bytes that did match the echo.

Missing echo: an echo comes back while its bytes are on the wire, ahead of any reply, so the echo
still expected is at most the frame being sent (256 bytes at most, possibly written in several
chunks). Bytes expected beyond that are echoes that never came (an adapter that dropped them, or
does not echo, with a device that left the requests unanswered):
[`LocalEchoFilter.expect`][aiortu.transport.LocalEchoFilter.expect] forgets them and counts them in
[`LocalEchoFilter.missing`][aiortu.transport.LocalEchoFilter.missing], so that what is expected
never grows with the requests.

The filter does no I/O and reads no clock, so every case is testable with exact bytes.
"""

from __future__ import annotations

__all__ = ("LocalEchoFilter",)

_MAX_ECHO = 256
"""The longest frame, so the longest echo that can still be on its way."""


class LocalEchoFilter:
    """Strips the echo of our own transmissions from a received byte stream.

    Call [`expect`][aiortu.transport.LocalEchoFilter.expect] with every chunk just before it is
    written, and [`feed`][aiortu.transport.LocalEchoFilter.feed] with every received chunk;
    [`feed`][aiortu.transport.LocalEchoFilter.feed] returns what is left once the echo is removed.

    >>> echo = LocalEchoFilter()
    >>> echo.expect(b"\\x11\\x03\\x00\\x6b")
    >>> echo.feed(b"\\x11\\x03")
    b''
    >>> echo.feed(b"\\x00\\x6b\\x11\\x03\\x06")
    b'\\x11\\x03\\x06'
    """

    __slots__ = ("_pending", "echoed", "mismatches", "missing")

    def __init__(self) -> None:
        self._pending = bytearray()
        self.echoed = 0
        """Bytes removed as echo so far."""
        self.mismatches = 0
        """Times the received bytes differed from the expected echo (see the module docs)."""
        self.missing = 0
        """Bytes whose echo never came, forgotten by
        [`expect`][aiortu.transport.LocalEchoFilter.expect] (see the module docs)."""

    @property
    def pending(self) -> int:
        """Bytes sent whose echo has not arrived yet."""
        return len(self._pending)

    def expect(self, sent: bytes | bytearray | memoryview) -> None:
        """Record bytes about to be written, whose echo will arrive ahead of anything else.

        An echo still expected that would take the total past 256 bytes (the longest
        frame) never came, and is forgotten first (see the module docs).
        """
        pending = self._pending
        if pending and len(pending) + len(sent) > _MAX_ECHO:
            self.missing += len(pending)
            pending.clear()
        pending += sent

    def reset(self) -> None:
        """Forget any echo still expected (after the line was reopened, for instance)."""
        self._pending.clear()

    def feed(self, received: bytes | bytearray | memoryview) -> bytes:
        """Return `received` without the echo bytes it starts with."""
        data = bytes(received)
        if not self._pending or not data:
            return data
        length = min(len(self._pending), len(data))
        matched = 0
        # Compare the overlap in one slice when it matches entirely, the common case.
        if data[:length] == self._pending[:length]:
            matched = length
        else:
            while data[matched] == self._pending[matched]:
                matched += 1
        self.echoed += matched
        if matched == length:
            del self._pending[:matched]
            return data[matched:]
        self.mismatches += 1
        self._pending.clear()
        return data[matched:]

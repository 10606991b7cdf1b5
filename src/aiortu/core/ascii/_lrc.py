"""The LRC, the checksum that ends every ASCII frame.

The serial line spec (2.5.2.2) defines it as the two's complement of the 8-bit sum of the
frame's bytes (the unit address and the PDU, as binary values, before hex encoding; not the
':' nor the end characters):

    >>> hex(lrc(bytes.fromhex("01 03 00 00 00 01")))
    '0xfb'

A frame whose bytes, LRC included, sum to zero modulo 256 checks.
"""

from __future__ import annotations

__all__ = ("lrc",)


def lrc(data: bytes | bytearray | memoryview) -> int:
    """The LRC of `data`: `-sum(data) mod 256`."""
    return -sum(data) & 0xFF

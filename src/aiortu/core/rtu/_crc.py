"""CRC-16/MODBUS, the checksum that ends every RTU frame, in pure Python.

The CRC is the reflected polynomial 0xA001 with initial value 0xFFFF, computed over the
unit address and the PDU and sent low byte first:

    >>> hex(crc16(b"\\x02\\x07"))
    '0x1241'
    >>> crc16_bytes(bytes.fromhex("11 03 00 6B 00 03")).hex(" ")
    '76 87'

How it is fast. The classic method looks up one byte at a time in a 256-entry table; inputs
under 32 bytes (most requests and replies) use exactly that, because anything more costs
more than it saves on so few bytes once the CPU caches are cold (see _WORD_THRESHOLD).
Longer inputs take two bytes per step: the CRC register is 16 bits wide, so XOR-ing a
little-endian data word into it and then running two zero-byte steps is one lookup in a
65536-entry table indexed by the register itself. That halves the number of Python-level
iterations, and reading the words through `memoryview.cast("H")` keeps the loop free of
shifts and masks; on CPython 3.11 it is 2.5 to 3 times as fast as the byte loop on 256-byte
frames. The word table (about 2.6 MB as a list of ints, built in 3 to 5 ms with
bytes-level operations rather than 65536 Python steps) is built on first use, not at
import, so importing the core stays cheap.

Why no compiled extension. Compiled CRC packages from PyPI (fastcrc, crcmod, anycrc) are 10
to 70 times faster on a 256-byte frame, but this pure-Python code already checks such a
frame in about 10 microseconds, while the frame takes 24 ms on the wire even at 115200 baud:
the CRC costs under 0.05 % of the line's time, and on the 8-byte requests that make up most
traffic the packages save well under a microsecond, less than the call overhead around
them. That is not worth a binary dependency and the platforms it would lack wheels for.
`benchmarks/bench_core.py` measures them all side by side.
"""

from __future__ import annotations

import sys
from array import array

from aiortu.core.errors import InvalidValue

__all__ = ("CRC_INITIAL", "check_crc", "crc16", "crc16_bytes")

CRC_INITIAL = 0xFFFF
"""The value the CRC register starts from for every frame."""

_POLYNOMIAL = 0xA001
"""0x8005 bit-reversed: Modbus shifts the register right, least significant bit first."""

_CRC_RANGE = range(0x10000)

_WORD_THRESHOLD = 32 if sys.byteorder == "little" else sys.maxsize
"""Inputs shorter than this take the byte loop. In a tight loop the two cross between 6 and
10 bytes, but a master or a slave computes one CRC per frame, between which the other
processes of the machine evict the CPU caches: then the word loop's setup (a memoryview, a
slice, a cast) and its 2.6 MB table cost more than they save on short frames (measured
with `benchmarks/bench_core.py`: a 23-byte reply, caches flushed before each call). The
frames of the commonest requests and replies are under 32 bytes. The word loop reads
little-endian words through `memoryview.cast("H")`, which is native order, so a
big-endian machine always takes the byte loop."""


def _byte_table() -> list[int]:
    table = []
    for byte in range(256):
        crc = byte
        for _ in range(8):
            crc = (crc >> 1) ^ _POLYNOMIAL if crc & 1 else crc >> 1
        table.append(crc)
    return table


_TABLE: list[int] = _byte_table()
"""`_TABLE[i]`: the register after eight shifts starting from `i` (one byte step)."""

_WORD_TABLE: list[int] = []
"""`_WORD_TABLE[r]`: the register after two zero-byte steps from `r`; empty until the
first long input needs it."""


def _build_word_table() -> list[int]:
    # Two byte steps from r = h << 8 | l give
    #     (_TABLE[l] >> 8) ^ _TABLE[h ^ (_TABLE[l] & 0xFF)].
    # For one h, the 256 results over l are computed at once with bytes.translate for the
    # lookups and big-int XOR for the XORs, so only 256 Python iterations run, not 65536.
    low_of = bytes(value & 0xFF for value in _TABLE)
    high_of = bytes(value >> 8 for value in _TABLE)
    first_low = int.from_bytes(low_of, "little")
    first_high = int.from_bytes(high_of, "little")
    ones = int.from_bytes(b"\x01" * 256, "little")
    packed = bytearray(2 * 0x10000)
    for high in range(256):
        index = (first_low ^ high * ones).to_bytes(256, "little")
        low = (int.from_bytes(index.translate(low_of), "little") ^ first_high).to_bytes(
            256, "little"
        )
        start = high << 9
        packed[start : start + 512 : 2] = low
        packed[start + 1 : start + 512 : 2] = index.translate(high_of)
    words = array("H")
    words.frombytes(packed)
    if sys.byteorder == "big":
        words.byteswap()
    _WORD_TABLE[:] = words.tolist()
    return _WORD_TABLE


def crc16(data: bytes | bytearray | memoryview, initial: int = CRC_INITIAL) -> int:
    """The CRC-16/MODBUS of `data`, as an int 0..0xFFFF.

    `initial` continues a CRC over several pieces: `crc16(b, crc16(a)) == crc16(a + b)`.
    A `memoryview` must be contiguous; it is read as bytes whatever its format.
    Raises [`InvalidValue`][aiortu.errors.InvalidValue] when `initial` is not 0..0xFFFF.
    """
    # A frame's bytes from the initial value, the call made per frame, check nothing
    # more: with cold caches every step counts.
    if type(data) is not bytes or initial != CRC_INITIAL:
        if initial >> 16 or initial < 0:
            raise InvalidValue("initial", initial, _CRC_RANGE)
        if type(data) is memoryview:
            data = data.cast("B")
    crc = initial
    length = len(data)
    if length < _WORD_THRESHOLD:
        table = _TABLE
        for byte in data:
            crc = (crc >> 8) ^ table[(crc ^ byte) & 0xFF]
        return crc
    words = _WORD_TABLE or _build_word_table()
    even = length & ~1
    view = memoryview(data)
    for word in (view[:even] if length & 1 else view).cast("H"):
        crc = words[crc ^ word]
    if length & 1:
        crc = (crc >> 8) ^ _TABLE[(crc ^ data[even]) & 0xFF]
    return crc


def crc16_bytes(data: bytes | bytearray | memoryview) -> bytes:
    """The CRC of `data` as the two bytes that follow it on the wire, low byte first."""
    crc = crc16(data)
    return bytes((crc & 0xFF, crc >> 8))


def check_crc(frame: bytes | bytearray | memoryview) -> bool:
    """Whether the last two bytes of `frame` are the CRC of the bytes before them.

    Runs the CRC over the whole frame, CRC included: the result is 0 exactly when the CRC
    matches. A frame shorter than two bytes has no CRC and gives `False`; whether the
    frame is long enough to mean anything is the framer's business.
    """
    if type(frame) is memoryview:
        frame = frame.cast("B")
    return len(frame) >= 2 and crc16(frame) == 0

"""The per-block read cache: a read answered again, within a maximum age, without the line.

A block is a unit, a read function code (01 to 04), an address and a count: the read's PDU.
Only a device's data reply is kept, never an exception. A write never is; it drops every
cached block of its unit in the table it writes (coils or holding registers) that overlaps the
addresses it writes. A request the cache cannot place (a user-defined code, a file record
write, diagnostics) drops every block of its unit, and a broadcast every block.

A read in flight while a write to its unit is sent may return a value from before the write:
each unit has a generation, bumped by every write, and a reply is kept only when the
generation did not change while it was on the line.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

from aiortu.core.codes import FunctionCode

__all__ = ("ReadCache",)

_COILS = (FunctionCode.READ_COILS,)
_HOLDING = (FunctionCode.READ_HOLDING_REGISTERS,)
_CACHED = frozenset(
    {
        FunctionCode.READ_COILS,
        FunctionCode.READ_DISCRETE_INPUTS,
        FunctionCode.READ_HOLDING_REGISTERS,
        FunctionCode.READ_INPUT_REGISTERS,
    }
)
# Reads that change nothing and have no table to invalidate.
_HARMLESS = frozenset({FunctionCode.READ_EXCEPTION_STATUS, FunctionCode.READ_FIFO_QUEUE})


@dataclass(slots=True)
class _Block:
    first: int
    end: int
    reply: bytes
    stored_at: float


def _span(pdu: bytes, with_count: bool) -> tuple[int, int] | None:
    """The addresses `first..end-1` a PDU names (a count after the address, or one)."""
    if len(pdu) < (5 if with_count else 3):
        return None
    first = int.from_bytes(pdu[1:3], "big")
    count = int.from_bytes(pdu[3:5], "big") if with_count else 1
    return first, first + count


def written(pdu: bytes) -> tuple[tuple[int, ...], tuple[int, int]] | None:
    """The read codes whose blocks a write PDU touches and the addresses it writes; None when
    the cache cannot tell (drop the unit's every block)."""
    code = pdu[0]
    if code == FunctionCode.WRITE_SINGLE_COIL:
        span, tables = _span(pdu, False), _COILS
    elif code == FunctionCode.WRITE_MULTIPLE_COILS:
        span, tables = _span(pdu, True), _COILS
    elif code in (FunctionCode.WRITE_SINGLE_REGISTER, FunctionCode.MASK_WRITE_REGISTER):
        span, tables = _span(pdu, False), _HOLDING
    elif code == FunctionCode.WRITE_MULTIPLE_REGISTERS:
        span, tables = _span(pdu, True), _HOLDING
    elif code == FunctionCode.READ_WRITE_MULTIPLE_REGISTERS:
        span, tables = _span(pdu[4:], True), _HOLDING  # the write half follows the read's
    else:
        return None
    return (tables, span) if span is not None else None


class ReadCache:
    """Read replies of at most `max_age` seconds, by unit and block (see the module docstring).

    `clock` gives the time in seconds (monotonic)."""

    def __init__(self, max_age: float, clock: Callable[[], float]) -> None:
        self.max_age = max_age
        self._clock = clock
        self._blocks: dict[int, dict[bytes, _Block]] = {}
        self._generations: dict[int, int] = {}
        self._epoch = 0

    @staticmethod
    def cacheable(pdu: bytes) -> bool:
        """Whether `pdu` is a read whose reply may be kept (01 to 04, address and count)."""
        return len(pdu) == 5 and pdu[0] in _CACHED

    def get(self, unit: int, pdu: bytes) -> bytes | None:
        """The kept reply to read `pdu` of `unit`, when it is at most `max_age` old."""
        block = self._blocks.get(unit, {}).get(pdu)
        if block is None:
            return None
        if self._clock() - block.stored_at > self.max_age:
            del self._blocks[unit][pdu]
            return None
        return block.reply

    def generation(self, unit: int) -> tuple[int, int]:
        """The writes to `unit` and the broadcasts so far: give it back to `put` with the reply."""
        return self._epoch, self._generations.get(unit, 0)

    def put(self, unit: int, pdu: bytes, reply: bytes, generation: tuple[int, int]) -> None:
        """Keep `reply` to read `pdu`, unless it is an exception or a write to `unit` was sent
        since `generation` was taken."""
        if reply[0] & 0x80 or generation != self.generation(unit):
            return
        first, end = _span(pdu, True) or (0, 0)
        self._blocks.setdefault(unit, {})[pdu] = _Block(first, end, reply, self._clock())

    def invalidate(self, unit: int, pdu: bytes) -> None:
        """Forget what request `pdu` to `unit` may change (nothing for a read)."""
        if pdu[0] in _CACHED or pdu[0] in _HARMLESS:
            return
        self._generations[unit] = self._generations.get(unit, 0) + 1
        blocks = self._blocks.get(unit)
        if not blocks:
            return
        touched = written(pdu)
        if touched is None:
            blocks.clear()
            return
        tables, (first, end) = touched
        for key in [key for key, block in blocks.items() if key[0] in tables]:
            block = blocks[key]
            if block.first < end and first < block.end:
                del blocks[key]

    def clear(self) -> None:
        """Forget every block (a broadcast may have written anything)."""
        self._epoch += 1
        self._blocks.clear()

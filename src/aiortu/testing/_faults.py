"""Fault plans: reproducible line noise for virtual serial lines.

A [`FaultPlan`][aiortu.testing.FaultPlan] says what goes wrong on a line and how often: flipped
bits, dropped bytes, bursts of garbage, pauses inside frames and extra latency. A
[`FaultInjector`][aiortu.testing.FaultInjector] applies a plan to the bytes that go on the wire,
draws every decision from its own seeded random generators, and counts what it did in
[`FaultInjector.stats`][aiortu.testing.FaultInjector].

Reproducibility: the same plan with the same seed, fed the same bytes, gives the same
faults. Bit errors, drops and gaps are drawn per bit or per byte from generators of their
own, so they land on the same byte positions however the bytes are split into sends.
Garbage and delay are drawn per chunk (one send), so they also depend on the chunking.
"""

from __future__ import annotations

import math
import random
from dataclasses import dataclass
from typing import NamedTuple

from aiortu.errors import InvalidValue

__all__ = ("FaultInjector", "FaultPlan", "FaultStats", "FaultedChunk")


def _check_rate(name: str, value: float) -> None:
    if isinstance(value, bool) or not isinstance(value, int | float):
        raise InvalidValue(name, value, "a probability from 0 to 1")
    if not 0.0 <= value <= 1.0:  # also rejects NaN
        raise InvalidValue(name, value, "a probability from 0 to 1")


def _check_seconds(name: str, value: float) -> None:
    if isinstance(value, bool) or not isinstance(value, int | float):
        raise InvalidValue(name, value, "a number of seconds >= 0")
    if not 0.0 <= value < math.inf:
        raise InvalidValue(name, value, "a number of seconds >= 0")


@dataclass(frozen=True, slots=True)
class FaultPlan:
    """What goes wrong on a virtual line, and how often. All rates default to 0 (a clean line).

    - `bit_error_rate`: probability that any one data bit is flipped.
    - `drop_rate`: probability that a byte is lost; it still takes its time on the wire.
    - `garbage_rate`: probability per chunk (one send) of inserting 1..`garbage_max` random
      bytes at a random position in it.
    - `gap_rate` and `gap`: probability per byte of a pause of `gap` seconds after it,
      which breaks a frame when `gap` exceeds t1.5.
    - `delay`: extra latency in seconds before each chunk goes on the wire, either fixed or
      drawn uniformly from a `(min, max)` pair; a slow device, or a late reply.
    - `seed`: the seed of the random generators; `None` draws a fresh one (see
      [`FaultInjector.seed`][aiortu.testing.FaultInjector.seed] to find out which).

    Raises [`InvalidValue`][aiortu.errors.InvalidValue] (caused by the caller) for a rate outside
    0..1, a negative time, or a gap rate without a gap length.
    """

    bit_error_rate: float = 0.0
    drop_rate: float = 0.0
    garbage_rate: float = 0.0
    garbage_max: int = 8
    gap_rate: float = 0.0
    gap: float = 0.0
    delay: float | tuple[float, float] = 0.0
    seed: int | None = 0

    def __post_init__(self) -> None:
        for name in ("bit_error_rate", "drop_rate", "garbage_rate", "gap_rate"):
            _check_rate(name, getattr(self, name))
        if isinstance(self.garbage_max, bool) or not isinstance(self.garbage_max, int):
            raise InvalidValue("garbage_max", self.garbage_max, "an integer >= 1")
        if self.garbage_max < 1:
            raise InvalidValue("garbage_max", self.garbage_max, "an integer >= 1")
        _check_seconds("gap", self.gap)
        if self.gap_rate > 0 and self.gap == 0:
            raise InvalidValue("gap", self.gap, "a number of seconds > 0", "gap_rate needs a gap")
        if isinstance(self.delay, tuple):
            if len(self.delay) != 2:
                raise InvalidValue("delay", self.delay, "seconds, or a (min, max) pair")
            low, high = self.delay
            _check_seconds("delay", low)
            _check_seconds("delay", high)
            if low > high:
                raise InvalidValue("delay", self.delay, "a (min, max) pair with min <= max")
        else:
            _check_seconds("delay", self.delay)
        if self.seed is not None and (
            isinstance(self.seed, bool) or not isinstance(self.seed, int)
        ):
            raise InvalidValue("seed", self.seed, "an integer or None")

    @property
    def is_clean(self) -> bool:
        """True if the plan changes nothing."""
        return (
            self.bit_error_rate == 0
            and self.drop_rate == 0
            and self.garbage_rate == 0
            and self.gap_rate == 0
            and self.delay in (0, (0, 0))
        )


@dataclass(slots=True)
class FaultStats:
    """What a [`FaultInjector`][aiortu.testing.FaultInjector] has done so far."""

    chunks: int = 0
    bytes: int = 0
    bits_flipped: int = 0
    bytes_dropped: int = 0
    garbage_insertions: int = 0
    garbage_bytes: int = 0
    gaps: int = 0
    delays: int = 0


class FaultedChunk(NamedTuple):
    """One chunk after the faults: what the wire carries, in order, after `delay` seconds.

    `items` holds runs of bytes (sent back to back) and pauses (a `float` of seconds).
    A dropped byte becomes a pause of one character time, as the wire is busy while it
    passes unseen.
    """

    delay: float
    items: list[bytes | float]

    @property
    def data(self) -> bytes:
        """The bytes a receiver gets, without the timing."""
        return b"".join(item for item in self.items if isinstance(item, bytes))


class _Countdown:
    """Positions of rare events in an endless stream, drawn geometrically.

    Drawing the distance to the next event instead of one coin per position costs one
    random number per event, and makes the positions independent of how the stream is cut.
    """

    __slots__ = ("_log_keep", "_next", "_rng")

    def __init__(self, rate: float, rng: random.Random) -> None:
        self._rng = rng
        self._log_keep = math.log1p(-rate) if 0 < rate < 1 else 0.0
        if rate == 0:
            self._next: float = math.inf
        elif rate == 1:
            self._next = 0
        else:
            self._next = self._skip()

    def _skip(self) -> int:
        if self._log_keep == 0.0:
            return 0
        return int(math.log1p(-self._rng.random()) / self._log_keep)

    def take(self, length: int) -> list[int]:
        """Return the event positions within the next `length` positions of the stream."""
        hits: list[int] = []
        position = self._next
        while position < length:
            hits.append(int(position))
            position += 1 + self._skip()
        self._next = position - length
        return hits


class _Wire:
    """What the wire carries for one chunk, built in order: runs of bytes and pauses."""

    __slots__ = ("_items", "run")

    def __init__(self) -> None:
        self._items: list[bytes | float] = []
        self.run = bytearray()
        """The bytes since the last pause."""

    def pause(self, seconds: float) -> None:
        """The line falls silent for `seconds` here (pauses in a row add up)."""
        if seconds <= 0:
            return
        items = self._items
        if self.run:
            items.append(bytes(self.run))
            self.run.clear()
        if items and isinstance(items[-1], float):
            items[-1] += seconds
        else:
            items.append(seconds)

    def items(self) -> list[bytes | float]:
        """The runs and pauses, the last run included."""
        if self.run:
            self._items.append(bytes(self.run))
            self.run.clear()
        return self._items


class FaultInjector:
    """Applies a [`FaultPlan`][aiortu.testing.FaultPlan] to the chunks of one line, reproducibly.

    Feed it every chunk that goes on the wire, in order, with
    [`apply`][aiortu.testing.FaultInjector.apply] (or
    [`corrupt`][aiortu.testing.FaultInjector.corrupt] when the timing does not matter).
    [`stats`][aiortu.testing.FaultInjector] counts what it did.
    """

    def __init__(self, plan: FaultPlan) -> None:
        self.plan = plan
        seed = plan.seed if plan.seed is not None else random.SystemRandom().getrandbits(63)
        self.seed: int = seed
        """The seed in use; report it from a failing test to replay the same faults."""
        self.stats = FaultStats()
        self._bits = _Countdown(plan.bit_error_rate, random.Random(f"{self.seed}:bits"))
        self._drops = _Countdown(plan.drop_rate, random.Random(f"{self.seed}:drops"))
        self._gaps = _Countdown(plan.gap_rate, random.Random(f"{self.seed}:gaps"))
        self._chunk_rng = random.Random(f"{self.seed}:chunks")

    def _draw_delay(self) -> float:
        delay = self.plan.delay
        if isinstance(delay, tuple):
            return self._chunk_rng.uniform(*delay)
        return float(delay)

    def apply(self, data: bytes, char_time: float = 0.0) -> FaultedChunk:
        """Return what the wire carries for `data`: the bytes after the faults, with pauses.

        `char_time` is the time of one character on the line, the length of the pause a
        dropped byte leaves (0 on an unpaced line).
        """
        stats = self.stats
        stats.chunks += 1
        stats.bytes += len(data)
        length = len(data)
        buffer = bytearray(data)
        flipped = self._bits.take(8 * length)
        for bit in flipped:
            buffer[bit // 8] ^= 1 << (bit % 8)
        stats.bits_flipped += len(flipped)
        # The draws keep their order (bits, drops, gaps, garbage, delay): a seed replays
        # the same faults.
        drops = set(self._drops.take(length))
        gaps = set(self._gaps.take(length))
        garbage_at, garbage = self._draw_garbage(length)
        delay = self._draw_delay()
        if delay > 0:
            stats.delays += 1
        stats.bytes_dropped += len(drops)
        stats.gaps += len(gaps)
        wire = _Wire()
        marks = sorted(drops | gaps | ({garbage_at} if garbage_at >= 0 else set()))
        done = 0
        for mark in marks:
            wire.run += buffer[done:mark]
            done = mark
            if mark == garbage_at:
                wire.run += garbage
            if mark < length:
                if mark in drops:
                    wire.pause(char_time)
                else:
                    wire.run.append(buffer[mark])
                done = mark + 1
                if mark in gaps:
                    wire.pause(self.plan.gap)
        wire.run += buffer[done:]
        return FaultedChunk(delay, wire.items())

    def _draw_garbage(self, length: int) -> tuple[int, bytes]:
        """Where garbage goes into a chunk of `length` bytes, and the garbage (-1 and none,
        mostly)."""
        plan = self.plan
        rng = self._chunk_rng
        if plan.garbage_rate <= 0 or rng.random() >= plan.garbage_rate:
            return -1, b""
        at = rng.randint(0, length)
        count = rng.randint(1, plan.garbage_max)
        garbage = bytes(rng.getrandbits(8) for _ in range(count))
        self.stats.garbage_insertions += 1
        self.stats.garbage_bytes += count
        return at, garbage

    def corrupt(self, data: bytes) -> bytes:
        """Apply the plan to `data` and return only the bytes a receiver would get."""
        return self.apply(data).data

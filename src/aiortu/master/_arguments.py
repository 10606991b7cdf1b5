"""Checks of the master's arguments and settings, run in the caller's task before anything
is queued or sent.

Each check raises [`InvalidRequest`][aiortu.errors.InvalidRequest] (a call's arguments) or
[`InvalidValue`][aiortu.errors.InvalidValue] (a master's settings), naming the argument, what
was given and what is allowed. The common case costs one `type(x) is int` test: the
master's register read runs them on every call.
"""

from __future__ import annotations

import math
from collections.abc import Collection, Iterable, Sequence
from typing import Final

from aiortu.core.codes import BROADCAST_UNIT, SERIAL_UNIT_IDS
from aiortu.core.errors import InvalidRequest, InvalidValue
from aiortu.core.machines import Failure
from aiortu.core.pdu import REGISTER_RANGE

__all__ = (
    "UNIT_RANGE",
    "check_at_least",
    "check_bool",
    "check_coil",
    "check_coils",
    "check_delays",
    "check_function_codes",
    "check_int",
    "check_items",
    "check_priority",
    "check_registers",
    "check_retry_on",
    "check_seconds",
    "check_timeout",
    "check_unit",
    "is_int",
)

UNIT_RANGE: Final = SERIAL_UNIT_IDS.unicast
"""The unit addresses a unicast request may go to on a serial line."""

_TEXT_TYPES: Final = (str, bytes, bytearray, memoryview)
"""Iterables that are never a sequence of values: text, and bytes (each byte an int)."""


def is_int(value: object) -> bool:
    """Whether `value` is an `int` (an `IntEnum` member included), not a `bool`."""
    return type(value) is int or (isinstance(value, int) and not isinstance(value, bool))


def check_int(name: str, value: object, allowed: range, error: type[InvalidValue]) -> int:
    """Return `value` if it is an int within `allowed`, else raise `error` naming `name`."""
    if not is_int(value):
        raise error(name, value, allowed, "an int is required")
    assert isinstance(value, int)
    if value not in allowed:
        raise error(name, value, allowed)
    return value


def check_unit(unit: object, allowed: range = UNIT_RANGE) -> int:
    """Return `unit` if a unicast may go to it (`allowed`: the framing's unit ids), else
    raise InvalidRequest."""
    if type(unit) is int and unit in allowed:
        return unit
    if is_int(unit) and unit == BROADCAST_UNIT:
        raise InvalidRequest("unit", unit, allowed, "use master.broadcast for unit 0")
    return check_int("unit", unit, allowed, InvalidRequest)


def check_priority(priority: object) -> int:
    """Return `priority` if it is an int (lower goes first), else raise InvalidRequest.

    Priorities are compared with each other inside the master's queue, in other callers'
    tasks: one that is not an int must never get there.
    """
    if isinstance(priority, int) and not isinstance(priority, bool):
        return priority
    raise InvalidRequest("priority", priority, "an int (lower goes first)")


def check_seconds(
    name: str, value: object, *, zero: bool = False, error: type[InvalidValue] = InvalidValue
) -> float:
    """Return `value` if it is a finite number of seconds > 0 (>= 0 with `zero`)."""
    allowed = "a finite number of seconds >= 0" if zero else "a finite number of seconds > 0"
    if type(value) is not float and not is_int(value):
        raise error(name, value, allowed)
    seconds = float(value)  # type: ignore[arg-type]  # a float or an int, checked above
    if not math.isfinite(seconds) or seconds < 0 or (seconds == 0 and not zero):
        raise error(name, value, allowed)
    return seconds


def check_turnaround(seconds: object) -> float:
    """Return `seconds` as a unit's minimum turnaround if it is a number from 0 to 10."""
    allowed = "a number of seconds from 0 to 10"
    if type(seconds) is not float and not is_int(seconds):
        raise InvalidValue("min_turnaround", seconds, allowed)
    value = float(seconds)  # type: ignore[arg-type]  # a float or an int, checked above
    if not 0 <= value <= 10:  # also rejects NaN
        raise InvalidValue("min_turnaround", seconds, allowed)
    return value


def check_timeout(timeout: object) -> float:
    """Return a call's response timeout, in seconds, if it is finite and > 0."""
    if type(timeout) is float and 0 < timeout < math.inf:
        return timeout
    return check_seconds("timeout", timeout, error=InvalidRequest)


def check_bool(name: str, value: object) -> bool:
    """Return `value` if it is a bool, else raise InvalidValue naming `name`."""
    if not isinstance(value, bool):
        raise InvalidValue(name, value, "True or False")
    return value


def check_coil(value: object) -> bool:
    """A single coil's state: a bool, 0 or 1, or the spec's 0xFF00 (on) or 0x0000 (off).

    Text and other numbers are refused: `"off"` is true to Python.
    """
    if type(value) is bool:
        return value
    if is_int(value) and value in (0, 1, 0xFF00):
        return value != 0
    raise InvalidRequest("value", value, "True, False, 1, 0, 0xFF00 (on) or 0x0000 (off)")


def check_coils(values: object) -> tuple[bool, ...]:
    """Coil states for write multiple coils: each a bool, 0 or 1."""
    items = check_items("values", values, "a sequence of bools (or 0 and 1)")
    coils: list[bool] = []
    for index, value in enumerate(items):
        if type(value) is bool:
            coils.append(value)
        elif is_int(value) and value in (0, 1):
            coils.append(value == 1)
        else:
            raise InvalidRequest(f"values[{index}]", value, "True, False, 1 or 0")
    return tuple(coils)


def check_registers(name: str, values: object) -> tuple[int, ...]:
    """Register values: a sequence of ints 0..65535 (not bools, not bytes)."""
    items = check_items(name, values, "a sequence of ints 0..65535")
    for index, value in enumerate(items):
        if type(value) is not int or value not in REGISTER_RANGE:
            check_int(f"{name}[{index}]", value, REGISTER_RANGE, InvalidRequest)
    return items  # type: ignore[return-value]  # every item checked above


def check_items(name: str, values: object, allowed: str) -> tuple[object, ...]:
    """`values` as a tuple, if it is a sequence (or another iterable) that is not text."""
    if isinstance(values, _TEXT_TYPES) or not isinstance(values, Iterable):
        raise InvalidRequest(name, values, allowed)
    return tuple(values)


def check_retry_on(retry_on: object) -> frozenset[Failure | int] | None:
    """The failures and exception codes a master retries: None (the default), or a
    collection of [`Failure`][aiortu.core.machines.Failure] members and
    exception codes 1..255."""
    if retry_on is None:
        return None
    allowed = "Failure.TIMEOUT, Failure.FRAME_ERROR or exception codes 1..255"
    if isinstance(retry_on, _TEXT_TYPES) or not isinstance(retry_on, Collection):
        raise InvalidValue("retry_on", retry_on, f"a collection of {allowed}")
    for item in retry_on:
        if not isinstance(item, Failure) and not (is_int(item) and 1 <= item <= 255):
            raise InvalidValue("retry_on", item, allowed, "an item that is not retryable")
    return frozenset(retry_on)


def check_function_codes(name: str, codes: object) -> frozenset[int] | None:
    """None, or a collection of function codes 1..127."""
    if codes is None:
        return None
    if isinstance(codes, _TEXT_TYPES) or not isinstance(codes, Collection):
        raise InvalidValue(name, codes, "a collection of function codes 1..127")
    return frozenset(check_int(name, code, range(1, 128), InvalidValue) for code in codes)


def check_at_least(
    name: str, value: object, minimum: int, error: type[InvalidValue] = InvalidValue
) -> int:
    """Return `value` if it is an int >= `minimum`, else raise `error`."""
    if not is_int(value) or value < minimum:  # type: ignore[operator]  # an int by then
        raise error(name, value, f"an int >= {minimum}")
    return value  # type: ignore[return-value]  # checked above


def check_delays(name: str, delays: object) -> tuple[float, float]:
    """A `(first, longest)` pair of finite delays, 0 < first <= longest."""
    allowed = "(first, longest): two finite numbers of seconds, 0 < first <= longest"
    if not isinstance(delays, Sequence) or isinstance(delays, _TEXT_TYPES) or len(delays) != 2:
        raise InvalidValue(name, delays, allowed)
    first = check_seconds(name, delays[0])
    longest = check_seconds(name, delays[1])
    if first > longest:
        raise InvalidValue(name, delays, allowed)
    return first, longest

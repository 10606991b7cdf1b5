"""A point's value as an MQTT payload, and a command payload as a value to write.

State payloads are text: numbers as decimals (a float32 to its 7 significant digits, so
230.1 stays 230.1), booleans `true`/`false`, enums and strings as their text, bitfields as a
JSON list of the flags set, and `null` for no value. A command payload is read the same way,
and more leniently: `ON`/`OFF` and `1`/`0` for booleans, JSON or plain text for the rest;
whether the value fits the point (its access, kind and limits) is the profile's to say, when
the write is checked.
"""

from __future__ import annotations

import json
import math

from aiortu.core.model import PointType, ProfilePoint, Value

__all__ = ("CommandError", "format_value", "parse_command")

_TRUE = {"true", "on", "1"}
_FALSE = {"false", "off", "0"}


class CommandError(ValueError):
    """A command payload that cannot be a value of its point; the message says why."""


def format_value(point: ProfilePoint, value: Value) -> bytes:
    """The state payload of `value`, a value of `point`."""
    if type(value) is int:  # the most common, and not a bool
        return b"%d" % value
    if value is None:
        return b"null"
    if isinstance(value, bool):
        return b"true" if value else b"false"
    if isinstance(value, int):  # an int subclass (an IntEnum)
        return b"%d" % value
    if isinstance(value, float):
        if not math.isfinite(value):
            return b"null"
        digits = 7 if point.type is PointType.F32 else 15
        text = f"{value:.{digits}g}"
        return text.encode() if "e" in text or "." in text else f"{text}.0".encode()
    if isinstance(value, tuple):
        return json.dumps(list(value)).encode()
    return value.encode()


def parse_command(point: ProfilePoint, payload: bytes) -> object:
    """The value a command `payload` asks `point` to take; raises
    [`CommandError`][aiortu.bridge.CommandError] when it cannot be one."""
    try:
        text = payload.decode("utf-8").strip()
    except UnicodeDecodeError:
        raise CommandError("the payload is not UTF-8 text") from None
    if not text:
        raise CommandError("the payload is empty")
    kind = point.type
    if kind is PointType.BOOL:
        if text.lower() in _TRUE:
            return True
        if text.lower() in _FALSE:
            return False
        raise CommandError(f"{text!r} is not a boolean (true/false, on/off, 1/0)")
    if kind is PointType.STRING or kind is PointType.ENUM:
        decoded = _json(text)
        return decoded if isinstance(decoded, str) else text
    if kind is PointType.BITFIELD:
        decoded = _json(text)
        if isinstance(decoded, list) and all(isinstance(flag, str) for flag in decoded):
            return tuple(decoded)
        raise CommandError(f"{text!r} is not a JSON list of flag names")
    decoded = _json(text)
    if isinstance(decoded, bool) or not isinstance(decoded, int | float):
        raise CommandError(f"{text!r} is not a number")
    return decoded


def _json(text: str) -> object:
    try:
        return json.loads(text)
    except ValueError:
        return text

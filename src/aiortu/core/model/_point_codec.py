"""A point's value to and from its registers or bits: types, layouts, scaling, enums, flags.

These are the general, checked conversions, used for writes, for serving and for single
points; a [`ReadPlan`][aiortu.core.model.ReadPlan] decodes whole replies by a faster route
that a test holds to the same results.
"""

from __future__ import annotations

import functools
import math
import struct
from collections.abc import Sequence

from aiortu.core.errors import InvalidValue
from aiortu.core.model._profile import PointType, ProfilePoint, Value
from aiortu.core.model._values import Layout

__all__ = (
    "check_value",
    "coding",
    "check_write",
    "decode_point",
    "encode_point",
    "packed_little_endian",
    "raw_of",
    "scaled",
    "struct_code",
    "text_of",
    "value_order",
)

_CODES = {
    PointType.U16: "H",
    PointType.I16: "h",
    PointType.U32: "I",
    PointType.I32: "i",
    PointType.U64: "Q",
    PointType.I64: "q",
    PointType.F32: "f",
    PointType.F64: "d",
    PointType.BOOL: "H",
}


@functools.cache
def coding(kind: PointType, layout: Layout, size: int) -> tuple[bool, str, str]:
    """How a value of `kind` in `layout` over `size` registers is unpacked from its registers:
    whether they are packed little-endian, the `struct` byte order, and the `struct` code.

    Packed big-endian, ABCD reads big-endian and DCBA little-endian; packed little-endian
    (each register's bytes swapped), CDAB reads little-endian and BADC big-endian. A
    string's bytes follow its layout's byte swap alone.
    """
    if kind is PointType.STRING:
        return layout.byte_swap, ">", f"{2 * size}s"
    if kind in (PointType.BITFIELD, PointType.ENUM):
        code = "H" if size == 1 else "I"
    else:
        code = _CODES[kind]
    return layout.word_swap != layout.byte_swap, "<" if layout.word_swap else ">", code


def struct_code(point: ProfilePoint) -> str:
    """The `struct` code of the point's raw value: `H`, `i`, `f`, ..., or `Ns` for a string."""
    return coding(point.type, point.layout, point.size)[2]


def packed_little_endian(point: ProfilePoint) -> bool:
    """Whether the point is read from its registers packed little-endian (see
    `coding`)."""
    return coding(point.type, point.layout, point.size)[0]


def value_order(point: ProfilePoint) -> str:
    """The `struct` byte order of the point's value in its packed registers."""
    return coding(point.type, point.layout, point.size)[1]


def _unpack(point: ProfilePoint, registers: Sequence[int]) -> int | float | bytes:
    packing = "<" if packed_little_endian(point) else ">"
    data = struct.pack(f"{packing}{len(registers)}H", *registers)
    order = value_order(point)
    value: int | float | bytes = struct.unpack(f"{order}{struct_code(point)}", data)[0]
    return value


def raw_of(point: ProfilePoint, elements: Sequence[int | bool]) -> int | float | bool | str:
    """The point's raw value from its elements: a bool, an integer, a float or a text."""
    if point.table.is_bit:
        return bool(elements[0])
    raw = _unpack(point, [int(e) for e in elements])
    if isinstance(raw, bytes):
        return text_of(point, raw)
    if point.type is PointType.BOOL:
        return bool(raw)
    return raw


def text_of(point: ProfilePoint, data: bytes) -> str:
    """A string point's text from its bytes, without the trailing NULs and spaces of padding;
    bytes its encoding cannot decode are replaced (a device's garbage is not the caller's)."""
    return data.decode(point.encoding, errors="replace").rstrip("\x00 ")


def scaled(point: ProfilePoint, raw: int | float | bool | str, sf: int | None) -> Value:
    """The value of `raw`: scaled, named (enums, flags), or None when not available.

    `sf` is the value of the point's scale factor (None when it has none or it could not be
    read: the value is then None).
    """
    if isinstance(raw, str):
        # not_available = 0 on a string: all NULs (an empty text) is no value, as in SunSpec.
        return None if raw == "" and point.not_available == 0 else raw
    if isinstance(raw, bool):
        return raw
    if point.not_available is not None and raw == point.not_available:
        return None
    kind = point.type
    if kind is PointType.ENUM:
        return point.values.get(int(raw), int(raw))
    if kind is PointType.BITFIELD:
        return tuple(
            point.bits.get(bit, str(bit)) for bit in range(16 * point.size) if int(raw) >> bit & 1
        )
    value: int | float = raw
    if point.scale is not None:
        value = value * point.scale
    if point.scale_factor is not None:
        if sf is None:
            return None
        value = value * 10.0**sf
    if point.offset is not None:
        value = value + point.offset
    return value


def decode_point(
    point: ProfilePoint, elements: Sequence[int | bool], sf: int | None = None
) -> Value:
    """The point's value from its elements (`point.size` of them); `sf` as for
    [`scaled`][aiortu.core.model.scaled]."""
    if len(elements) != point.size:
        raise InvalidValue("len(elements)", len(elements), range(point.size, point.size + 1))
    return scaled(point, raw_of(point, elements), sf)


def _fail(point: ProfilePoint, value: object, allowed: object, problem: str) -> InvalidValue:
    return InvalidValue(point.name, value, allowed, message=f"point {point.name}: {problem}")


def check_value(point: ProfilePoint, value: object) -> Value:
    """`value` as a value of `point` (an enum's name or number, a bitfield's flag names or
    number, a number for numeric points), else [`InvalidValue`][aiortu.errors.InvalidValue]."""
    kind = point.type
    if kind is PointType.BOOL:
        if isinstance(value, bool) or value in (0, 1):
            return bool(value)
        raise _fail(point, value, "true or false", f"value must be true or false, not {value!r}")
    if kind is PointType.STRING:
        if isinstance(value, str):
            return value
        raise _fail(point, value, "a text", f"value must be a text, not {value!r}")
    if kind is PointType.ENUM:
        return _enum_value(point, value)
    if kind is PointType.BITFIELD:
        return _flags_value(point, value)
    if isinstance(value, bool) or not isinstance(value, int | float):
        raise _fail(point, value, "a number", f"value must be a number, not {value!r}")
    return value


def _enum_value(point: ProfilePoint, value: object) -> Value:
    if isinstance(value, str):
        if value in point.values.values():
            return value
        known = ", ".join(point.values.values())
        raise _fail(point, value, known, f"value {value!r} is not one of {known}")
    if isinstance(value, int) and not isinstance(value, bool):
        return point.values.get(value, value)
    raise _fail(
        point, value, "a name or a number", f"value must be a name or a number, not {value!r}"
    )


def _flags_value(point: ProfilePoint, value: object) -> Value:
    if isinstance(value, int) and not isinstance(value, bool):
        return scaled(point, value, None)
    if isinstance(value, list | tuple) and all(isinstance(v, str) for v in value):
        known = {name: bit for bit, name in point.bits.items()}
        for name in value:
            if name not in known and not (name.isdigit() and int(name) < 16 * point.size):
                raise _fail(point, name, ", ".join(known), f"value has no flag named {name!r}")
        return tuple(value)
    raise _fail(point, value, "flag names", f"value must be a list of flag names, not {value!r}")


def check_write(point: ProfilePoint, value: object) -> Value:
    """`value` checked for a write of `point`: writable, of its kind, within its limits."""
    if not point.writable:
        raise _fail(point, value, "a writable point", 'is read-only (access = "r")')
    checked = check_value(point, value)
    if isinstance(checked, int | float) and not isinstance(checked, bool):
        low, high = point.minimum, point.maximum
        if (low is not None and checked < low) or (high is not None and checked > high):
            shown = (
                f"{'-inf' if low is None else f'{low:g}'}..{'inf' if high is None else f'{high:g}'}"
            )
            raise _fail(point, value, shown, f"value {checked:g} is outside the limits {shown}")
    return checked


def _raw_number(point: ProfilePoint, value: float, sf: int | None) -> int | float:
    raw: float = value
    if point.offset is not None:
        raw -= point.offset
    if point.scale is not None:
        raw /= point.scale
    if point.scale_factor is not None:
        raw /= 10.0 ** (sf or 0)
    if point.type in (PointType.F32, PointType.F64):
        return raw
    if not math.isfinite(raw):
        raise _fail(point, value, "a finite number", f"value {value!r} has no raw integer")
    return round(raw)


def _raw_flags(point: ProfilePoint, names: tuple[str, ...]) -> int:
    bits = {name: bit for bit, name in point.bits.items()}
    return sum(1 << (bits[name] if name in bits else int(name)) for name in set(names))


def encode_point(point: ProfilePoint, value: Value, sf: int | None = None) -> tuple[int, ...]:
    """The elements (registers, or one bit as 0/1) that hold `value` (checked by
    [`check_value`][aiortu.core.model.check_value]) in `point`; `sf` is its scale factor's
    value. Raises [`InvalidValue`][aiortu.errors.InvalidValue] when the raw value does not fit."""
    kind = point.type
    if point.table.is_bit:
        return (int(bool(value)),)
    if kind is PointType.STRING:
        assert isinstance(value, str)
        try:
            data = value.encode(point.encoding)
        except UnicodeEncodeError as error:
            raise _fail(
                point,
                value,
                point.encoding,
                f"text {value!r} has characters {point.encoding} cannot encode ({error.reason})",
            ) from None
        if len(data) > 2 * point.size:
            raise _fail(
                point,
                value,
                f"{2 * point.size} bytes",
                f"text {value!r} is longer than {2 * point.size} bytes",
            )
        raw: int | float | bytes = data.ljust(2 * point.size, b"\x00")
    elif kind is PointType.ENUM:
        names = {name: number for number, name in point.values.items()}
        raw = names[value] if isinstance(value, str) else int(value)  # type: ignore[arg-type]
    elif kind is PointType.BITFIELD:
        raw = _raw_flags(point, value) if isinstance(value, tuple) else int(value)  # type: ignore[arg-type]
    elif kind is PointType.BOOL:
        raw = int(bool(value))
    else:
        assert isinstance(value, int | float)
        raw = _raw_number(point, value, sf)
    return _pack(point, raw)


def _pack(point: ProfilePoint, raw: int | float | bytes) -> tuple[int, ...]:
    order = value_order(point)
    try:
        data = struct.pack(f"{order}{struct_code(point)}", raw)
    except (struct.error, OverflowError):
        raise _fail(
            point, raw, str(point.type), f"raw value {raw!r} does not fit in {point.type}"
        ) from None
    packing = "<" if packed_little_endian(point) else ">"
    registers: tuple[int, ...] = struct.unpack(f"{packing}{point.size}H", data)
    return registers

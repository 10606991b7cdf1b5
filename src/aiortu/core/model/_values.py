"""Typed values in 16-bit registers: integers, floats and strings, in every word layout.

A register holds 16 bits; wider values span 2 or 4 consecutive registers, and devices disagree on
the order of their bytes. [`Layout`][aiortu.core.model.Layout] names the four orders users meet,
after the bytes of a 32-bit value written big-endian as `A B C D` (`A` the most significant), listed
in the order they sit in the registers:

======  ================  =====================  =============================
layout  32-bit registers  64-bit registers       meaning
======  ================  =====================  =============================
ABCD    AB CD             AB CD EF GH            big-endian: words in order, each word big-endian
CDAB    CD AB             GH EF CD AB            words in reverse order, each word big-endian
BADC    BA DC             BA DC FE HG            words in order, the two bytes of each word swapped
DCBA    DC BA             HG FE DC BA            little-endian: everything reversed
======  ================  =====================  =============================

So a layout is two independent switches, [`Layout.word_swap`][aiortu.core.model.Layout.word_swap]
and [`Layout.byte_swap`][aiortu.core.model.Layout.byte_swap], and extends to any number of
registers. A 16-bit value has one word: ABCD and CDAB leave it as it is, BADC and DCBA swap its two
bytes.

    >>> [hex(r) for r in encode_value(123.456, ValueType.FLOAT32)]
    ['0x42f6', '0xe979']
    >>> [hex(r) for r in encode_value(123.456, ValueType.FLOAT32, Layout.CDAB)]
    ['0xe979', '0x42f6']

Every value that does not fit (70000 as an int16, a float beyond float32's range, a wrong
number of registers, a register outside 0..65535) raises
[`InvalidValue`][aiortu.errors.InvalidValue] naming the field, the value and the allowed range.
Floats may be NaN or infinite: devices use both.
"""

from __future__ import annotations

import codecs
import enum
import struct
from collections.abc import Iterable, Sequence

from aiortu.core.errors import InvalidValue
from aiortu.core.pdu import pack_bits, unpack_bits

__all__ = (
    "Layout",
    "ValueType",
    "as_layout",
    "as_value_type",
    "bits_to_bytes",
    "check_encoding",
    "bytes_to_bits",
    "decode_value",
    "encode_value",
    "float32_to_registers",
    "float64_to_registers",
    "int16_to_register",
    "int32_to_registers",
    "int64_to_registers",
    "register_count",
    "register_to_int16",
    "registers_to_float32",
    "registers_to_float64",
    "registers_to_int32",
    "registers_to_int64",
    "registers_to_string",
    "registers_to_uint32",
    "registers_to_uint64",
    "string_to_registers",
    "uint32_to_registers",
    "uint64_to_registers",
)

_REGISTER_RANGE = range(0x10000)


class Layout(enum.StrEnum):
    """The order of the bytes of a multi-register value; see the module's table."""

    ABCD = "ABCD"
    """Big-endian: the most significant word first, each word big-endian (the spec's order)."""
    CDAB = "CDAB"
    """Word swap: the least significant word first, each word big-endian."""
    BADC = "BADC"
    """Byte swap: the most significant word first, the bytes of each word swapped."""
    DCBA = "DCBA"
    """Little-endian: the least significant byte first."""

    @property
    def word_swap(self) -> bool:
        """Whether the registers come least significant word first (CDAB, DCBA)."""
        return self in (Layout.CDAB, Layout.DCBA)

    @property
    def byte_swap(self) -> bool:
        """Whether each register has its two bytes swapped (BADC, DCBA)."""
        return self in (Layout.BADC, Layout.DCBA)


class ValueType(enum.StrEnum):
    """A typed value held in one or more registers."""

    INT16 = "int16"
    UINT16 = "uint16"
    INT32 = "int32"
    UINT32 = "uint32"
    INT64 = "int64"
    UINT64 = "uint64"
    FLOAT32 = "float32"
    FLOAT64 = "float64"

    @property
    def register_count(self) -> int:
        """How many registers a value of this type spans: 1, 2 or 4."""
        return _FORMATS[self][1]

    @property
    def is_float(self) -> bool:
        """Whether values of this type are floats (IEEE 754) rather than integers."""
        return self in (ValueType.FLOAT32, ValueType.FLOAT64)


def _int_range(bits: int, signed: bool) -> range:
    return range(-(1 << (bits - 1)), 1 << (bits - 1)) if signed else range(1 << bits)


# struct format of the value written big-endian, registers spanned, and (integers) the range.
_FORMATS: dict[ValueType, tuple[str, int, range | None]] = {
    ValueType.INT16: (">h", 1, _int_range(16, signed=True)),
    ValueType.UINT16: (">H", 1, _int_range(16, signed=False)),
    ValueType.INT32: (">i", 2, _int_range(32, signed=True)),
    ValueType.UINT32: (">I", 2, _int_range(32, signed=False)),
    ValueType.INT64: (">q", 4, _int_range(64, signed=True)),
    ValueType.UINT64: (">Q", 4, _int_range(64, signed=False)),
    ValueType.FLOAT32: (">f", 2, None),
    ValueType.FLOAT64: (">d", 4, None),
}

_FLOAT_RANGES = {
    ValueType.FLOAT32: "finite values within +-3.4028235e38 (float32), NaN or infinity",
    ValueType.FLOAT64: "finite values within +-1.7976931348623157e308, NaN or infinity",
}


def as_value_type(kind: ValueType | str) -> ValueType:
    """`kind` as a [`ValueType`][aiortu.core.model.ValueType]; raise InvalidValue if it names
    none."""
    try:
        return ValueType(kind)
    except (ValueError, TypeError):
        raise InvalidValue("kind", kind, ", ".join(ValueType)) from None


def as_layout(layout: Layout | str) -> Layout:
    """`layout` as a [`Layout`][aiortu.core.model.Layout]; raise InvalidValue if it names none."""
    try:
        return Layout(layout)
    except (ValueError, TypeError):
        raise InvalidValue("layout", layout, ", ".join(Layout)) from None


def check_encoding(encoding: str) -> str:
    """`encoding` if Python has a codec of that name; raise InvalidValue otherwise."""
    try:
        codecs.lookup(encoding)
    except (LookupError, TypeError):
        raise InvalidValue("encoding", encoding, "a codec Python knows") from None
    return encoding


def register_count(kind: ValueType | str) -> int:
    """How many registers a value of type `kind` spans: 1, 2 or 4."""
    return as_value_type(kind).register_count


def _words(data: bytes, layout: Layout) -> tuple[int, ...]:
    """Big-endian value bytes to registers in `layout`."""
    # Reading the words little-endian is the same as swapping the bytes of each one.
    count = len(data) // 2
    words: tuple[int, ...] = struct.unpack(f"{'<' if layout.byte_swap else '>'}{count}H", data)
    return words[::-1] if layout.word_swap else words


def _check_registers(registers: Sequence[int], count: int | None) -> tuple[int, ...]:
    """`registers` as a tuple, each 0..65535, `count` of them unless `count` is None."""
    try:
        registers = tuple(registers)
    except TypeError:
        raise InvalidValue("registers", registers, "a sequence of ints 0..65535") from None
    if count is not None and len(registers) != count:
        raise InvalidValue("len(registers)", len(registers), range(count, count + 1))
    for index, register in enumerate(registers):
        if (
            not isinstance(register, int)
            or isinstance(register, bool)
            or register not in _REGISTER_RANGE
        ):
            raise InvalidValue(f"registers[{index}]", register, _REGISTER_RANGE)
    return registers


def _value_bytes(registers: tuple[int, ...], layout: Layout) -> bytes:
    """Registers in `layout` back to the value's big-endian bytes (registers checked)."""
    words = registers[::-1] if layout.word_swap else registers
    return struct.pack(f"{'<' if layout.byte_swap else '>'}{len(words)}H", *words)


def encode_value(
    value: float, kind: ValueType | str, layout: Layout | str = Layout.ABCD
) -> tuple[int, ...]:
    """The registers (each 0..65535) that hold `value` as a `kind` in `layout`.

    Integer types take an `int` in the type's range; float types take an `int` or a
    `float` (NaN and infinities included) that the type can represent, rounded to it.
    """
    kind = as_value_type(kind)
    layout = as_layout(layout)
    fmt, _, allowed = _FORMATS[kind]
    if allowed is not None:
        if not isinstance(value, int) or isinstance(value, bool) or value not in allowed:
            raise InvalidValue("value", value, allowed, f"does not fit in {kind}")
        return _words(struct.pack(fmt, value), layout)
    if not isinstance(value, int | float) or isinstance(value, bool):
        raise InvalidValue("value", value, _FLOAT_RANGES[kind], f"not a number for {kind}")
    try:
        # float() first: an int too large for any float fails here, not inside struct.
        data = struct.pack(fmt, float(value))
    except OverflowError:
        raise InvalidValue("value", value, _FLOAT_RANGES[kind], f"does not fit in {kind}") from None
    return _words(data, layout)


def decode_value(
    registers: Sequence[int], kind: ValueType | str, layout: Layout | str = Layout.ABCD
) -> int | float:
    """The `kind` held in `registers` (exactly [`register_count`][aiortu.core.model.register_count]
    of them) in `layout`."""
    kind = as_value_type(kind)
    layout = as_layout(layout)
    fmt, count, _ = _FORMATS[kind]
    checked = _check_registers(registers, count)
    value: int | float = struct.unpack(fmt, _value_bytes(checked, layout))[0]
    return value


def int16_to_register(value: int, layout: Layout | str = Layout.ABCD) -> int:
    """The register holding the signed 16-bit `value` (-32768..32767)."""
    return encode_value(value, ValueType.INT16, layout)[0]


def register_to_int16(register: int, layout: Layout | str = Layout.ABCD) -> int:
    """The signed 16-bit value held in `register`."""
    return int(decode_value((register,), ValueType.INT16, layout))


def int32_to_registers(value: int, layout: Layout | str = Layout.ABCD) -> tuple[int, int]:
    """The two registers holding the signed 32-bit `value`."""
    first, second = encode_value(value, ValueType.INT32, layout)
    return first, second


def registers_to_int32(registers: Sequence[int], layout: Layout | str = Layout.ABCD) -> int:
    """The signed 32-bit value held in two `registers`."""
    return int(decode_value(registers, ValueType.INT32, layout))


def uint32_to_registers(value: int, layout: Layout | str = Layout.ABCD) -> tuple[int, int]:
    """The two registers holding the unsigned 32-bit `value`."""
    first, second = encode_value(value, ValueType.UINT32, layout)
    return first, second


def registers_to_uint32(registers: Sequence[int], layout: Layout | str = Layout.ABCD) -> int:
    """The unsigned 32-bit value held in two `registers`."""
    return int(decode_value(registers, ValueType.UINT32, layout))


def int64_to_registers(value: int, layout: Layout | str = Layout.ABCD) -> tuple[int, ...]:
    """The four registers holding the signed 64-bit `value`."""
    return encode_value(value, ValueType.INT64, layout)


def registers_to_int64(registers: Sequence[int], layout: Layout | str = Layout.ABCD) -> int:
    """The signed 64-bit value held in four `registers`."""
    return int(decode_value(registers, ValueType.INT64, layout))


def uint64_to_registers(value: int, layout: Layout | str = Layout.ABCD) -> tuple[int, ...]:
    """The four registers holding the unsigned 64-bit `value`."""
    return encode_value(value, ValueType.UINT64, layout)


def registers_to_uint64(registers: Sequence[int], layout: Layout | str = Layout.ABCD) -> int:
    """The unsigned 64-bit value held in four `registers`."""
    return int(decode_value(registers, ValueType.UINT64, layout))


def float32_to_registers(value: float, layout: Layout | str = Layout.ABCD) -> tuple[int, int]:
    """The two registers holding `value` as an IEEE 754 single (rounded to it)."""
    first, second = encode_value(value, ValueType.FLOAT32, layout)
    return first, second


def registers_to_float32(registers: Sequence[int], layout: Layout | str = Layout.ABCD) -> float:
    """The IEEE 754 single held in two `registers`."""
    return float(decode_value(registers, ValueType.FLOAT32, layout))


def float64_to_registers(value: float, layout: Layout | str = Layout.ABCD) -> tuple[int, ...]:
    """The four registers holding `value` as an IEEE 754 double."""
    return encode_value(value, ValueType.FLOAT64, layout)


def registers_to_float64(registers: Sequence[int], layout: Layout | str = Layout.ABCD) -> float:
    """The IEEE 754 double held in four `registers`."""
    return float(decode_value(registers, ValueType.FLOAT64, layout))


def _swap_bytes(data: bytes) -> bytes:
    swapped = bytearray(len(data))
    swapped[0::2] = data[1::2]
    swapped[1::2] = data[0::2]
    return bytes(swapped)


def string_to_registers(
    text: str,
    register_count: int | None = None,
    encoding: str = "ascii",
    byte_swap: bool = False,
) -> tuple[int, ...]:
    """`text` encoded two bytes per register, the first byte in the high half.

    The bytes are padded with NULs to whole registers, or to `register_count` registers
    when given (a text that does not fit raises InvalidValue). `byte_swap` puts the first
    byte of each pair in the low half instead, as some devices do.
    """
    if not isinstance(text, str):
        raise InvalidValue("text", text, "a str")
    try:
        data = text.encode(check_encoding(encoding))
    except LookupError:  # a codec, but not a text encoding (base64, ...)
        raise InvalidValue("encoding", encoding, "a text encoding Python knows") from None
    except UnicodeEncodeError as error:
        raise InvalidValue(
            "text", text, f"characters {encoding} can encode", str(error.reason)
        ) from None
    if register_count is None:
        size = len(data) + (len(data) & 1)
    else:
        if (
            not isinstance(register_count, int)
            or isinstance(register_count, bool)
            or register_count < 0
        ):
            raise InvalidValue("register_count", register_count, "an int >= 0")
        size = 2 * register_count
        if len(data) > size:
            raise InvalidValue(
                "len(text)",
                len(data),
                range(size + 1),
                f"{text!r} takes {len(data)} bytes in {encoding}; "
                f"{register_count} registers hold {size}",
            )
    data = data.ljust(size, b"\x00")
    if byte_swap:
        data = _swap_bytes(data)
    return struct.unpack(f">{size // 2}H", data)


def registers_to_string(
    registers: Sequence[int],
    encoding: str = "ascii",
    byte_swap: bool = False,
    strip: bool = True,
) -> str:
    """The text held in `registers`, two bytes per register, the first in the high half.

    `byte_swap` reads the first byte of each pair from the low half instead. With `strip`,
    trailing NULs and spaces (the usual padding) are removed.
    """
    checked = _check_registers(registers, None)
    check_encoding(encoding)
    data = struct.pack(f">{len(checked)}H", *checked)
    if byte_swap:
        data = _swap_bytes(data)
    try:
        text = data.decode(encoding)
    except LookupError:  # a codec, but not a text encoding (base64, ...)
        raise InvalidValue("encoding", encoding, "a text encoding Python knows") from None
    except UnicodeDecodeError as error:
        raise InvalidValue(
            "registers", checked, f"bytes {encoding} can decode", str(error.reason)
        ) from None
    return text.rstrip("\x00 ") if strip else text


def bits_to_bytes(bits: Iterable[bool | int]) -> bytes:
    """Bits packed eight to a byte, the first in the least significant position.

    The last byte is padded with zeros, as on the wire; each item counts as its truth value.
    """
    return pack_bits(bool(bit) for bit in bits)


def bytes_to_bits(data: bytes | bytearray, count: int | None = None) -> tuple[bool, ...]:
    """The bits of `data`, least significant first: the first `count`, or all of them.

    `count` may not exceed the `8 * len(data)` bits there are.
    """
    bits = unpack_bits(bytes(data))
    if count is None:
        return bits
    allowed = range(len(bits) + 1)
    if not isinstance(count, int) or isinstance(count, bool) or count not in allowed:
        raise InvalidValue("count", count, allowed)
    return bits[:count]

"""Typed values in registers: every type in every layout, strings, and bits."""

from __future__ import annotations

import math
import struct

import pytest
from hypothesis import given
from hypothesis import strategies as st

from aiortu.core.errors import InvalidValue
from aiortu.core.model import (
    Layout,
    ValueType,
    bits_to_bytes,
    bytes_to_bits,
    decode_value,
    encode_value,
    float32_to_registers,
    float64_to_registers,
    int16_to_register,
    int32_to_registers,
    int64_to_registers,
    register_count,
    register_to_int16,
    registers_to_float32,
    registers_to_float64,
    registers_to_int32,
    registers_to_int64,
    registers_to_string,
    registers_to_uint32,
    registers_to_uint64,
    string_to_registers,
    uint32_to_registers,
    uint64_to_registers,
)
from aiortu.core.pdu import pack_bits, unpack_bits

INTEGER_RANGES = {
    ValueType.INT16: (-(2**15), 2**15 - 1),
    ValueType.UINT16: (0, 2**16 - 1),
    ValueType.INT32: (-(2**31), 2**31 - 1),
    ValueType.UINT32: (0, 2**32 - 1),
    ValueType.INT64: (-(2**63), 2**63 - 1),
    ValueType.UINT64: (0, 2**64 - 1),
}
COUNTS = {
    ValueType.INT16: 1,
    ValueType.UINT16: 1,
    ValueType.INT32: 2,
    ValueType.UINT32: 2,
    ValueType.INT64: 4,
    ValueType.UINT64: 4,
    ValueType.FLOAT32: 2,
    ValueType.FLOAT64: 4,
}


def values_of(kind: ValueType) -> st.SearchStrategy[int | float]:
    if kind is ValueType.FLOAT32:
        return st.floats(width=32, allow_nan=False)
    if kind is ValueType.FLOAT64:
        return st.floats(allow_nan=False)
    low, high = INTEGER_RANGES[kind]
    return st.integers(low, high)


def test_register_counts() -> None:
    for kind, count in COUNTS.items():
        assert register_count(kind) == count
        assert register_count(kind.value) == count
        assert kind.register_count == count


def test_layout_switches() -> None:
    assert [layout.word_swap for layout in Layout] == [False, True, False, True]
    assert [layout.byte_swap for layout in Layout] == [False, False, True, True]


@pytest.mark.parametrize("kind", list(ValueType))
@pytest.mark.parametrize("layout", list(Layout))
@given(data=st.data())
def test_round_trip(kind: ValueType, layout: Layout, data: st.DataObject) -> None:
    value = data.draw(values_of(kind))
    registers = encode_value(value, kind, layout)
    assert len(registers) == kind.register_count
    assert all(0 <= register <= 0xFFFF for register in registers)
    assert decode_value(registers, kind, layout) == value


@pytest.mark.parametrize("kind", list(ValueType))
@pytest.mark.parametrize("layout", list(Layout))
@given(data=st.data())
def test_registers_round_trip(kind: ValueType, layout: Layout, data: st.DataObject) -> None:
    # Every bit pattern decodes, and encodes back to itself (NaN payloads aside).
    registers = tuple(
        data.draw(st.lists(st.integers(0, 0xFFFF), min_size=COUNTS[kind], max_size=COUNTS[kind]))
    )
    value = decode_value(registers, kind, layout)
    if isinstance(value, float) and math.isnan(value):
        return
    assert encode_value(value, kind, layout) == registers


@pytest.mark.parametrize("layout", list(Layout))
@given(st.sampled_from([ValueType.FLOAT32, ValueType.FLOAT64]))
def test_nan_and_infinities(layout: Layout, kind: ValueType) -> None:
    assert math.isnan(decode_value(encode_value(math.nan, kind, layout), kind, layout))
    for infinity in (math.inf, -math.inf):
        assert decode_value(encode_value(infinity, kind, layout), kind, layout) == infinity


def test_float32_vectors() -> None:
    assert encode_value(123.456, ValueType.FLOAT32) == (0x42F6, 0xE979)
    assert encode_value(123.456, ValueType.FLOAT32, Layout.CDAB) == (0xE979, 0x42F6)
    assert encode_value(123.456, ValueType.FLOAT32, Layout.BADC) == (0xF642, 0x79E9)
    assert encode_value(123.456, ValueType.FLOAT32, Layout.DCBA) == (0x79E9, 0xF642)
    assert float32_to_registers(123.456) == (0x42F6, 0xE979)
    assert registers_to_float32((0x42F6, 0xE979)) == pytest.approx(123.456, rel=1e-7)
    assert registers_to_float32((0xE979, 0x42F6), Layout.CDAB) == pytest.approx(123.456, rel=1e-7)
    assert float32_to_registers(1.0) == (0x3F80, 0x0000)
    assert float32_to_registers(-2.5, "CDAB") == (0x0000, 0xC020)


def test_layouts_of_a_32_bit_value() -> None:
    # Bytes A=0x11 B=0x22 C=0x33 D=0x44.
    value = 0x11223344
    assert uint32_to_registers(value, Layout.ABCD) == (0x1122, 0x3344)
    assert uint32_to_registers(value, Layout.CDAB) == (0x3344, 0x1122)
    assert uint32_to_registers(value, Layout.BADC) == (0x2211, 0x4433)
    assert uint32_to_registers(value, Layout.DCBA) == (0x4433, 0x2211)


def test_layouts_of_a_64_bit_value() -> None:
    # Bytes A..H = 0x11..0x88: CDAB reverses the words, BADC swaps the bytes in each,
    # DCBA reverses everything.
    value = 0x1122334455667788
    assert uint64_to_registers(value, Layout.ABCD) == (0x1122, 0x3344, 0x5566, 0x7788)
    assert uint64_to_registers(value, Layout.CDAB) == (0x7788, 0x5566, 0x3344, 0x1122)
    assert uint64_to_registers(value, Layout.BADC) == (0x2211, 0x4433, 0x6655, 0x8877)
    assert uint64_to_registers(value, Layout.DCBA) == (0x8877, 0x6655, 0x4433, 0x2211)
    little = struct.pack("<Q", value)
    assert uint64_to_registers(value, Layout.DCBA) == struct.unpack(">4H", little)


def test_layouts_of_a_16_bit_value() -> None:
    assert encode_value(0x1234, ValueType.UINT16, Layout.ABCD) == (0x1234,)
    assert encode_value(0x1234, ValueType.UINT16, Layout.CDAB) == (0x1234,)
    assert encode_value(0x1234, ValueType.UINT16, Layout.BADC) == (0x3412,)
    assert encode_value(0x1234, ValueType.UINT16, Layout.DCBA) == (0x3412,)


def test_integer_vectors() -> None:
    assert int16_to_register(-1) == 0xFFFF
    assert register_to_int16(0x8000) == -32768
    assert int32_to_registers(-2) == (0xFFFF, 0xFFFE)
    assert registers_to_int32((0xFFFE, 0xFFFF), Layout.CDAB) == -2
    assert registers_to_uint32((0x0001, 0x0000)) == 65536
    assert int64_to_registers(-1) == (0xFFFF,) * 4
    assert registers_to_int64((0x8000, 0, 0, 0)) == -(2**63)
    assert registers_to_uint64((0, 0, 0, 1), "DCBA") == 1 << 56
    assert float64_to_registers(1.0) == (0x3FF0, 0, 0, 0)
    assert registers_to_float64((0, 0, 0, 0x3FF0), Layout.CDAB) == 1.0


@pytest.mark.parametrize(
    ("value", "kind"),
    [
        (70000, ValueType.INT16),
        (32768, ValueType.INT16),
        (-32769, ValueType.INT16),
        (-1, ValueType.UINT16),
        (65536, ValueType.UINT16),
        (2**31, ValueType.INT32),
        (-1, ValueType.UINT32),
        (2**32, ValueType.UINT32),
        (2**63, ValueType.INT64),
        (2**64, ValueType.UINT64),
        (1.5, ValueType.INT32),
        (True, ValueType.INT16),
        ("7", ValueType.UINT16),
        (None, ValueType.UINT16),
        (1e39, ValueType.FLOAT32),
        (-1e39, ValueType.FLOAT32),
        (10**39, ValueType.FLOAT32),
        (10**400, ValueType.FLOAT64),
        ("1.0", ValueType.FLOAT32),
        (False, ValueType.FLOAT64),
    ],
)
def test_values_out_of_range(value: object, kind: ValueType) -> None:
    with pytest.raises(InvalidValue) as caught:
        encode_value(value, kind)  # type: ignore[arg-type]
    assert caught.value.field == "value"
    assert caught.value.value is value
    assert str(kind) in str(caught.value)


def test_message_names_field_value_and_range() -> None:
    with pytest.raises(InvalidValue, match=r"value = 70000 .* -32768\.\.32767"):
        encode_value(70000, ValueType.INT16)


@pytest.mark.parametrize("kind", list(ValueType))
def test_wrong_register_count(kind: ValueType) -> None:
    for count in (0, COUNTS[kind] - 1, COUNTS[kind] + 1):
        if count == COUNTS[kind] or count < 0:
            continue
        with pytest.raises(InvalidValue) as caught:
            decode_value((0,) * count, kind)
        assert caught.value.field == "len(registers)"
        assert caught.value.value == count


@pytest.mark.parametrize("bad", [-1, 0x10000, 70000, 1.0, "1", None, True])
def test_register_out_of_range(bad: object) -> None:
    with pytest.raises(InvalidValue) as caught:
        decode_value((0, bad), ValueType.UINT32)  # type: ignore[arg-type]
    assert caught.value.field == "registers[1]"
    assert caught.value.value is bad


def test_registers_not_a_sequence() -> None:
    with pytest.raises(InvalidValue) as caught:
        decode_value(5, ValueType.UINT16)  # type: ignore[arg-type]
    assert caught.value.field == "registers"


def test_unknown_kind_and_layout() -> None:
    with pytest.raises(InvalidValue) as caught:
        encode_value(1, "int24")
    assert caught.value.field == "kind"
    with pytest.raises(InvalidValue) as caught:
        encode_value(1, ValueType.INT32, "ACBD")
    assert caught.value.field == "layout"
    assert decode_value((1, 0), "uint32", "CDAB") == 1


def test_string_vectors() -> None:
    assert string_to_registers("AB") == (0x4142,)
    assert string_to_registers("ABC") == (0x4142, 0x4300)
    assert string_to_registers("ABC", 3) == (0x4142, 0x4300, 0x0000)
    assert string_to_registers("ABC", byte_swap=True) == (0x4241, 0x0043)
    assert string_to_registers("") == ()
    assert registers_to_string((0x4142, 0x4300, 0x0000)) == "ABC"
    assert registers_to_string((0x4142, 0x4320)) == "ABC"
    assert registers_to_string((0x4142, 0x4300), strip=False) == "ABC\x00"
    assert registers_to_string((0x4241, 0x0043), byte_swap=True) == "ABC"
    assert registers_to_string(string_to_registers("é", encoding="utf-8"), "utf-8") == "é"


@given(
    st.text(st.characters(min_codepoint=0x21, max_codepoint=0x7E), max_size=40),
    st.booleans(),
    st.integers(0, 5),
)
def test_string_round_trip(text: str, byte_swap: bool, extra: int) -> None:
    registers = string_to_registers(text, byte_swap=byte_swap)
    assert len(registers) == (len(text) + 1) // 2
    assert registers_to_string(registers, byte_swap=byte_swap) == text
    padded = string_to_registers(text, len(registers) + extra, byte_swap=byte_swap)
    assert len(padded) == len(registers) + extra
    assert registers_to_string(padded, byte_swap=byte_swap) == text


def test_string_too_long() -> None:
    with pytest.raises(InvalidValue) as caught:
        string_to_registers("ABCDE", 2)
    assert caught.value.field == "len(text)"
    assert caught.value.value == 5
    assert string_to_registers("ABCD", 2) == (0x4142, 0x4344)


def test_string_errors() -> None:
    with pytest.raises(InvalidValue) as caught:
        string_to_registers("é")
    assert caught.value.field == "text"
    with pytest.raises(InvalidValue) as caught:
        string_to_registers("A", encoding="no-such-codec")
    assert caught.value.field == "encoding"
    with pytest.raises(InvalidValue) as caught:
        string_to_registers("A", -1)
    assert caught.value.field == "register_count"
    with pytest.raises(InvalidValue) as caught:
        registers_to_string((0xC3C3,))
    assert caught.value.field == "registers"
    with pytest.raises(InvalidValue) as caught:
        registers_to_string((0x41, 0x10000))
    assert caught.value.field == "registers[1]"


def test_bits_vectors() -> None:
    # Read Coils example of the spec: coils 20..38 = CD 6B 05.
    bits = [1, 0, 1, 1, 0, 0, 1, 1, 1, 1, 0, 1, 0, 1, 1, 0, 1, 0, 1]
    assert bits_to_bytes(bits) == bytes.fromhex("CD 6B 05")
    assert bytes_to_bits(bytes.fromhex("CD 6B 05"), 19) == tuple(bool(bit) for bit in bits)
    assert len(bytes_to_bits(b"\x01\x02")) == 16
    assert bits_to_bytes([]) == b""


@given(st.lists(st.booleans(), max_size=2000))
def test_bits_round_trip(bits: list[bool]) -> None:
    data = bits_to_bytes(bits)
    assert len(data) == (len(bits) + 7) // 8
    assert data == pack_bits(bits)
    assert bytes_to_bits(data, len(bits)) == tuple(bits)
    assert bytes_to_bits(data) == unpack_bits(data)


@pytest.mark.parametrize("count", [-1, 17, 1.0])
def test_bit_count_out_of_range(count: object) -> None:
    with pytest.raises(InvalidValue) as caught:
        bytes_to_bits(b"\x00\x00", count)  # type: ignore[arg-type]
    assert caught.value.field == "count"

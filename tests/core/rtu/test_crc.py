"""CRC-16/MODBUS: known vectors, a bit-by-bit reference, and the frame check."""

from __future__ import annotations

import pytest
from hypothesis import given
from hypothesis import strategies as st

from aiortu.core.errors import InvalidValue
from aiortu.core.rtu import CRC_INITIAL, check_crc, crc16, crc16_bytes
from aiortu.core.rtu import _crc as crc_module


def reference_crc16(data: bytes, crc: int = 0xFFFF) -> int:
    """The CRC one bit at a time, straight from the definition, to check the tables."""
    for byte in data:
        crc ^= byte
        for _ in range(8):
            if crc & 1:
                crc = (crc >> 1) ^ 0xA001
            else:
                crc >>= 1
    return crc


def test_vector_from_the_spec() -> None:
    assert crc16(b"\x02\x07") == 0x1241
    assert crc16_bytes(b"\x02\x07") == b"\x41\x12"


def test_read_holding_registers_example() -> None:
    request = bytes.fromhex("11 03 00 6B 00 03")
    assert crc16_bytes(request) == bytes.fromhex("76 87")
    assert check_crc(request + bytes.fromhex("76 87"))


def test_reply_example_checks() -> None:
    assert check_crc(bytes.fromhex("11 03 06 AE 41 56 52 43 40 49 AD"))


def test_empty_input_is_the_initial_value() -> None:
    assert crc16(b"") == CRC_INITIAL
    assert crc16(b"", 0x1234) == 0x1234


def test_check_value_of_the_catalogue() -> None:
    # The standard check string of CRC catalogues; CRC-16/MODBUS gives 0x4B37.
    assert crc16(b"123456789") == 0x4B37


@pytest.mark.parametrize("length", [*range(40), 255, 256, 257])
def test_every_length_takes_the_right_path(length: int) -> None:
    data = bytes((7 * index + 3) & 0xFF for index in range(length))
    assert crc16(data) == reference_crc16(data)


@given(st.binary(max_size=300))
def test_matches_the_bit_by_bit_reference(data: bytes) -> None:
    assert crc16(data) == reference_crc16(data)


@given(st.binary(max_size=300), st.integers(0, 0xFFFF))
def test_matches_the_reference_from_any_initial_value(data: bytes, initial: int) -> None:
    assert crc16(data, initial) == reference_crc16(data, initial)


@given(st.binary(max_size=200), st.binary(max_size=200))
def test_incremental(first: bytes, second: bytes) -> None:
    assert crc16(second, crc16(first)) == crc16(first + second)


@given(st.binary(max_size=300))
def test_bytearray_and_memoryview_give_the_same(data: bytes) -> None:
    expected = crc16(data)
    assert crc16(bytearray(data)) == expected
    assert crc16(memoryview(data)) == expected
    assert crc16(memoryview(b"xx" + data)[2:]) == expected


def test_memoryview_of_another_format_is_read_as_bytes() -> None:
    data = bytes(range(32))
    assert crc16(memoryview(data).cast("H")) == crc16(data)
    assert check_crc(memoryview(data + crc16_bytes(data)).cast("b"))


@given(st.binary(max_size=254))
def test_crc_bytes_make_a_valid_frame(data: bytes) -> None:
    frame = data + crc16_bytes(data)
    assert check_crc(frame)
    assert check_crc(bytearray(frame))
    assert check_crc(memoryview(frame))
    assert int.from_bytes(frame[-2:], "little") == crc16(data)


@given(st.binary(min_size=1, max_size=254), st.data())
def test_any_single_bit_flip_is_caught(data: bytes, draw: st.DataObject) -> None:
    frame = bytearray(data + crc16_bytes(data))
    bit = draw.draw(st.integers(0, 8 * len(frame) - 1))
    frame[bit // 8] ^= 1 << (bit % 8)
    assert not check_crc(frame)


@pytest.mark.parametrize("frame", [b"", b"\x01"])
def test_too_short_for_a_crc(frame: bytes) -> None:
    assert not check_crc(frame)


@pytest.mark.parametrize("initial", [-1, 0x10000, 1 << 40])
def test_initial_out_of_range(initial: int) -> None:
    with pytest.raises(InvalidValue) as caught:
        crc16(b"\x01", initial)
    assert caught.value.field == "initial"


def test_word_table_is_two_byte_steps() -> None:
    table = crc_module._WORD_TABLE or crc_module._build_word_table()
    assert len(table) == 0x10000
    for register in (0, 1, 0xFF, 0x100, 0x1234, 0xA001, 0xFFFF):
        step = register
        for _ in range(16):
            step = (step >> 1) ^ 0xA001 if step & 1 else step >> 1
        assert table[register] == step

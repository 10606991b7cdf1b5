"""Modbus TCP framing: the MBAP header, whole ADUs, and the stream decoder."""

from __future__ import annotations

import pytest
from hypothesis import given
from hypothesis import strategies as st

from aiortu.core.errors import FrameError, InvalidValue
from aiortu.core.mbap import (
    HEADER_LENGTH,
    MAX_ADU_LENGTH,
    Adu,
    AduDecoder,
    MalformedHeader,
    decode_adu,
    encode_adu,
)

adus = st.builds(
    Adu,
    transaction_id=st.integers(0, 0xFFFF),
    unit=st.integers(0, 0xFF),
    pdu=st.binary(min_size=1, max_size=253),
)


def test_the_spec_example_read_holding_registers() -> None:
    # Transaction 1, unit 17, read 3 holding registers at 0x6B.
    adu = encode_adu(1, 17, bytes.fromhex("03006B0003"))
    assert adu == bytes.fromhex("0001 0000 0006 11 03006B0003")
    assert decode_adu(adu) == Adu(1, 17, bytes.fromhex("03006B0003"))


@given(adus)
def test_encode_then_decode_gives_the_same_adu(adu: Adu) -> None:
    data = adu.encode()
    assert len(data) == HEADER_LENGTH + len(adu.pdu) <= MAX_ADU_LENGTH
    assert decode_adu(data) == adu


@pytest.mark.parametrize(
    ("transaction_id", "unit", "pdu", "field"),
    [
        (-1, 1, b"\x03", "transaction_id"),
        (0x10000, 1, b"\x03", "transaction_id"),
        (0, 256, b"\x03", "unit"),
        (0, -1, b"\x03", "unit"),
        (0, 1, b"", "len(pdu)"),
        (0, 1, bytes(254), "len(pdu)"),
    ],
)
def test_encode_refuses_fields_out_of_range(
    transaction_id: int, unit: int, pdu: bytes, field: str
) -> None:
    with pytest.raises(InvalidValue) as caught:
        encode_adu(transaction_id, unit, pdu)
    assert caught.value.field == field


def test_a_protocol_id_other_than_zero_is_refused() -> None:
    adu = bytearray(encode_adu(7, 1, b"\x03\x00\x00\x00\x01"))
    adu[3] = 1
    with pytest.raises(MalformedHeader, match="protocol id is 1"):
        decode_adu(bytes(adu))


@pytest.mark.parametrize("length", [0, 1, 255, 256, 0xFFFF])
def test_a_length_field_outside_2_to_254_is_refused(length: int) -> None:
    header = bytes((0, 1, 0, 0, length >> 8, length & 0xFF, 1))
    with pytest.raises(MalformedHeader, match=f"length field is {length}"):
        decode_adu(header + b"\x03")
    with pytest.raises(MalformedHeader):
        AduDecoder().feed(header)


@pytest.mark.parametrize("extra", [-1, 1])
def test_a_whole_adu_must_be_as_long_as_its_length_field(extra: int) -> None:
    adu = encode_adu(1, 1, b"\x03\x00\x00\x00\x02")
    data = adu[:extra] if extra < 0 else adu + b"\x00"
    with pytest.raises(FrameError) as caught:
        decode_adu(data)
    assert caught.value.reason == "length"


def test_a_too_short_adu_is_refused() -> None:
    with pytest.raises(FrameError, match="at least 8 bytes"):
        decode_adu(bytes(7))


@given(st.lists(adus, min_size=1, max_size=8), st.data())
def test_the_decoder_takes_any_split_of_pipelined_adus(
    adu_list: list[Adu], data: st.DataObject
) -> None:
    stream = b"".join(adu.encode() for adu in adu_list)
    cuts = sorted(data.draw(st.sets(st.integers(1, len(stream) - 1), max_size=12)))
    decoder = AduDecoder()
    decoded: list[Adu] = []
    for start, end in zip([0, *cuts], [*cuts, len(stream)], strict=True):
        decoded += decoder.feed(stream[start:end])
        assert decoder.buffered < MAX_ADU_LENGTH
    assert decoded == adu_list
    assert decoder.buffered == 0


@given(st.lists(adus, min_size=1, max_size=3))
def test_the_decoder_takes_one_byte_at_a_time(adu_list: list[Adu]) -> None:
    stream = b"".join(adu.encode() for adu in adu_list)
    decoder = AduDecoder()
    decoded: list[Adu] = []
    for i in range(len(stream)):
        decoded += decoder.feed(stream[i : i + 1])
    assert decoded == adu_list


def test_after_a_malformed_header_the_stream_is_refused_for_good() -> None:
    good = encode_adu(1, 1, b"\x03\x00\x00\x00\x01")
    bad = bytes((0, 2, 0, 5, 0, 6, 1)) + b"\x03\x00\x00\x00\x01"
    decoder = AduDecoder()
    assert decoder.feed(good) == [decode_adu(good)]
    with pytest.raises(MalformedHeader, match="protocol id is 5"):
        decoder.feed(bad)
    assert decoder.broken
    assert decoder.buffered == 0
    with pytest.raises(MalformedHeader, match="protocol id is 5"):
        decoder.feed(good)


def test_a_bad_header_is_found_as_soon_as_its_seven_bytes_are_in() -> None:
    decoder = AduDecoder()
    assert decoder.feed(bytes((0, 1, 0, 0, 0x01))) == []
    with pytest.raises(MalformedHeader, match="length field is 300"):
        decoder.feed(bytes((0x2C, 1)))

"""The PDUs of the bit tables: read coils (01), read discrete inputs (02), write single coil
(05), write multiple coils (0F)."""

from __future__ import annotations

from collections.abc import Callable

import pytest
from hypothesis import given
from hypothesis import strategies as st

from aiortu.core.codes import ExceptionCode, FunctionCode
from aiortu.core.errors import InvalidRequest, InvalidValue, MalformedPDU
from aiortu.core.pdu import (
    MAX_READ_BITS,
    MAX_WRITE_BITS,
    PDU,
    ExceptionPDU,
    RawPDU,
    ReadCoilsRequest,
    ReadCoilsResponse,
    ReadDiscreteInputsRequest,
    ReadDiscreteInputsResponse,
    ReadHoldingRegistersResponse,
    Request,
    Response,
    WriteMultipleCoilsRequest,
    WriteMultipleCoilsResponse,
    WriteSingleCoilRequest,
    WriteSingleCoilResponse,
    decode_request,
    decode_response,
)
from tests.core.strategies_bits_registers import (
    BITS_REQUEST_STRATEGIES,
    BITS_RESPONSE_STRATEGIES,
    mutations,
    replies_to,
)

REQUEST_STRATEGIES = BITS_REQUEST_STRATEGIES
RESPONSE_STRATEGIES = BITS_RESPONSE_STRATEGIES

CODES = (0x01, 0x02, 0x05, 0x0F)
READS = (ReadCoilsRequest, ReadDiscreteInputsRequest)
A = range(0x10000)
END = range(0x10001)


def words(*values: int) -> bytes:
    return b"".join(value.to_bytes(2, "big") for value in values)


def padded(response: ReadCoilsResponse) -> tuple[bool, ...]:
    values = response.values
    return values + (False,) * (-len(values) % 8)


def decodes_cleanly(data: bytes, decode: Callable[[bytes], PDU]) -> PDU | None:
    """Decode *data*; only MalformedPDU may escape, and a success must re-encode faithfully."""
    try:
        decoded = decode(data)
    except MalformedPDU:
        return None
    if isinstance(decoded, WriteMultipleCoilsRequest):
        # Padding bits of the last byte are ignored, so compare the canonical form.
        assert type(decoded).decode(decoded.encode()) == decoded
    else:
        assert decoded.encode() == data
    return decoded


# Round trips


@pytest.mark.parametrize("cls", list(REQUEST_STRATEGIES), ids=lambda c: c.__name__)
@given(data=st.data())
def test_request_round_trip(cls: type[Request], data: st.DataObject) -> None:
    request = data.draw(REQUEST_STRATEGIES[cls])
    encoded = request.encode()
    assert encoded[0] == cls.function_code
    assert cls.decode(encoded) == request
    decoded = decode_request(encoded)
    assert type(decoded) is cls
    assert decoded == request


@pytest.mark.parametrize("cls", list(RESPONSE_STRATEGIES), ids=lambda c: c.__name__)
@given(data=st.data())
def test_response_round_trip(cls: type[Response], data: st.DataObject) -> None:
    response = data.draw(RESPONSE_STRATEGIES[cls])
    encoded = response.encode()
    decoded = decode_response(encoded)
    assert type(decoded) is cls
    assert cls.decode(encoded) == decoded
    if isinstance(response, ReadCoilsResponse):
        assert isinstance(decoded, ReadCoilsResponse)
        assert decoded.values == padded(response)
        assert decoded.encode() == encoded
    else:
        assert decoded == response


def test_every_class_has_a_strategy() -> None:
    assert set(REQUEST_STRATEGIES) == {
        ReadCoilsRequest,
        ReadDiscreteInputsRequest,
        WriteSingleCoilRequest,
        WriteMultipleCoilsRequest,
    }
    assert set(RESPONSE_STRATEGIES) == {cls.response_class for cls in REQUEST_STRATEGIES}


def test_broadcastable() -> None:
    assert WriteSingleCoilRequest.broadcastable
    assert WriteMultipleCoilsRequest.broadcastable
    assert not ReadCoilsRequest.broadcastable
    assert not ReadDiscreteInputsRequest.broadcastable


# Vectors


def test_exception_vector_of_the_notes() -> None:
    # `01 81 02` + CRC: read coils at a missing address; the PDU is `81 02`.
    decoded = decode_response(bytes.fromhex("81 02"))
    assert decoded == ExceptionPDU(FunctionCode.READ_COILS, ExceptionCode.ILLEGAL_DATA_ADDRESS)


@pytest.mark.parametrize(
    ("pdu", "request_", "reply", "response"),
    [
        (
            "01 00 13 00 13",
            ReadCoilsRequest(0x13, 19),
            "01 03 CD 6B 05",
            ReadCoilsResponse([*map(int, "1011001111010110101")]),
        ),
        (
            "05 00 AC FF 00",
            WriteSingleCoilRequest(0xAC, True),
            "05 00 AC FF 00",
            WriteSingleCoilResponse(0xAC, True),
        ),
        (
            "05 00 AC 00 00",
            WriteSingleCoilRequest(0xAC, False),
            "05 00 AC 00 00",
            WriteSingleCoilResponse(0xAC, False),
        ),
        (
            "0F 00 13 00 0A 02 CD 01",
            WriteMultipleCoilsRequest(0x13, [*map(int, "1011001110")]),
            "0F 00 13 00 0A",
            WriteMultipleCoilsResponse(0x13, 10),
        ),
    ],
)
def test_vectors(pdu: str, request_: Request, reply: str, response: Response) -> None:
    assert request_.encode() == bytes.fromhex(pdu)
    assert decode_request(bytes.fromhex(pdu)) == request_
    assert response.encode() == bytes.fromhex(reply)
    decoded = decode_response(bytes.fromhex(reply))
    assert decoded.encode() == bytes.fromhex(reply)
    assert isinstance(decoded, Response)
    request_.check_response(decoded)
    if isinstance(request_, ReadCoilsRequest):
        assert isinstance(decoded, ReadCoilsResponse)
        assert request_.bits_of(decoded) == list(response.values)  # type: ignore[attr-defined]


# Construction


INVALID: list[tuple[Callable[[], object], type[InvalidValue], str, object, range]] = []
for _read in READS:
    INVALID += [
        (lambda c=_read: c(-1, 1), InvalidRequest, "address", -1, A),
        (lambda c=_read: c(0x10000, 1), InvalidRequest, "address", 0x10000, A),
        (lambda c=_read: c(0, 0), InvalidRequest, "count", 0, range(1, 2001)),
        (lambda c=_read: c(0, 2001), InvalidRequest, "count", 2001, range(1, 2001)),
        (lambda c=_read: c(0xFFFF, 2), InvalidRequest, "address + count", 0x10001, END),
        (lambda c=_read: c(64537, 1000), InvalidRequest, "address + count", 65537, END),
    ]
for _response in (ReadCoilsResponse, ReadDiscreteInputsResponse):
    INVALID += [
        (lambda c=_response: c(()), InvalidValue, "len(values)", 0, range(1, 2001)),
        (lambda c=_response: c([0] * 2001), InvalidValue, "len(values)", 2001, range(1, 2001)),
    ]
_WRITE_COUNT = range(1, MAX_WRITE_BITS + 1)
INVALID += [
    (lambda: WriteSingleCoilRequest(-1, True), InvalidRequest, "address", -1, A),
    (lambda: WriteSingleCoilRequest(0x10000, True), InvalidRequest, "address", 0x10000, A),
    (lambda: WriteSingleCoilResponse(-1, True), InvalidValue, "address", -1, A),
    (lambda: WriteSingleCoilResponse(0x10000, False), InvalidValue, "address", 0x10000, A),
    (lambda: WriteMultipleCoilsRequest(-1, [True]), InvalidRequest, "address", -1, A),
    (lambda: WriteMultipleCoilsRequest(0x10000, [1]), InvalidRequest, "address", 0x10000, A),
    (lambda: WriteMultipleCoilsRequest(0, []), InvalidRequest, "len(values)", 0, _WRITE_COUNT),
    (
        lambda: WriteMultipleCoilsRequest(0, [1] * 1969),
        InvalidRequest,
        "len(values)",
        1969,
        _WRITE_COUNT,
    ),
    (
        lambda: WriteMultipleCoilsRequest(0xFFFF, [1, 0]),
        InvalidRequest,
        "address + len(values)",
        0x10001,
        END,
    ),
    (lambda: WriteMultipleCoilsResponse(-1, 1), InvalidValue, "address", -1, A),
    (lambda: WriteMultipleCoilsResponse(0x10000, 1), InvalidValue, "address", 0x10000, A),
    (lambda: WriteMultipleCoilsResponse(0, 0), InvalidValue, "count", 0, _WRITE_COUNT),
    (lambda: WriteMultipleCoilsResponse(0, 1969), InvalidValue, "count", 1969, _WRITE_COUNT),
    (lambda: WriteMultipleCoilsResponse(0xFFF0, 17), InvalidValue, "address + count", 65537, END),
]


@pytest.mark.parametrize(("build", "error", "field", "value", "allowed"), INVALID)
def test_construction_rejects_out_of_range(
    build: Callable[[], object],
    error: type[InvalidValue],
    field: str,
    value: object,
    allowed: range,
) -> None:
    with pytest.raises(error) as caught:
        build()
    assert type(caught.value) is error
    assert caught.value.field == field
    assert caught.value.value == value
    assert caught.value.allowed == allowed


@pytest.mark.parametrize("cls", READS)
def test_read_limits_accepted(cls: type[ReadCoilsRequest]) -> None:
    assert cls(0, MAX_READ_BITS).count == MAX_READ_BITS
    assert cls(0x10000 - MAX_READ_BITS, MAX_READ_BITS).address == 0x10000 - MAX_READ_BITS
    assert cls(0xFFFF, 1).address == 0xFFFF


def test_write_limits_accepted() -> None:
    request = WriteMultipleCoilsRequest(0x10000 - MAX_WRITE_BITS, [True] * MAX_WRITE_BITS)
    assert request.count == MAX_WRITE_BITS
    assert len(request.encode()) == 6 + 246
    assert WriteMultipleCoilsResponse(0xFFFF, 1).count == 1


def test_coil_values_become_bools() -> None:
    assert WriteSingleCoilRequest(1, 1).value is True  # type: ignore[arg-type]
    assert WriteSingleCoilResponse(1, 0).value is False  # type: ignore[arg-type]
    assert WriteMultipleCoilsRequest(1, [1, 0]).values == (True, False)  # type: ignore[list-item]


# Decoding errors


@given(
    code=st.sampled_from(CODES),
    body=st.binary(max_size=260),
)
def test_arbitrary_bytes_raise_only_malformed(code: int, body: bytes) -> None:
    data = bytes((code,)) + body
    decodes_cleanly(data, decode_request)
    decodes_cleanly(data, decode_response)
    decodes_cleanly(bytes((code | 0x80,)) + body, decode_response)


@pytest.mark.parametrize("cls", list(REQUEST_STRATEGIES), ids=lambda c: c.__name__)
@given(data=st.data())
def test_mutated_requests_raise_only_malformed(cls: type[Request], data: st.DataObject) -> None:
    pdu = data.draw(REQUEST_STRATEGIES[cls]).encode()
    mutated = data.draw(mutations(pdu))
    decodes_cleanly(mutated, decode_request)
    decodes_cleanly(mutated, cls.decode)


@pytest.mark.parametrize("cls", list(RESPONSE_STRATEGIES), ids=lambda c: c.__name__)
@given(data=st.data())
def test_mutated_responses_raise_only_malformed(cls: type[Response], data: st.DataObject) -> None:
    pdu = data.draw(RESPONSE_STRATEGIES[cls]).encode()
    mutated = data.draw(mutations(pdu))
    decodes_cleanly(mutated, decode_response)
    decodes_cleanly(mutated, cls.decode)


@pytest.mark.parametrize("word", [0x0001, 0x00FF, 0xFF01, 0xFFFF, 0x1234, 0x7F00])
def test_single_coil_value_other_than_on_or_off(word: int) -> None:
    pdu = b"\x05" + words(7, word)
    for decode in (decode_request, decode_response):
        with pytest.raises(MalformedPDU) as caught:
            decode(pdu)
        assert caught.value.field == "value"
        assert caught.value.value == word
        assert caught.value.exception_code == ExceptionCode.ILLEGAL_DATA_VALUE


def test_write_coils_ignores_padding_bits() -> None:
    decoded = decode_request(bytes.fromhex("0F 00 00 00 03 01 FD"))
    assert decoded == WriteMultipleCoilsRequest(0, [True, False, True])


@pytest.mark.parametrize(
    ("pdu", "field"),
    [
        ("0F 00 00 00 03 02 07 00", "byte_count"),
        ("0F 00 00 00 09 01 FF", "byte_count"),
        ("0F 00 00 00 09 02 FF", "length"),
        ("0F 00 00 00 01 01 01 00", "length"),
        ("0F 00 00 00 01 01", "length"),
    ],
)
def test_write_coils_byte_count_must_match(pdu: str, field: str) -> None:
    with pytest.raises(MalformedPDU) as caught:
        decode_request(bytes.fromhex(pdu))
    assert caught.value.field == field
    assert caught.value.exception_code == ExceptionCode.ILLEGAL_DATA_VALUE


def _read_pdu(code: int, address: int, count: int) -> bytes:
    return bytes((code,)) + words(address, count)


def _write_coils_pdu(address: int, count: int) -> bytes:
    byte_count = min((count + 7) // 8, 255)
    return b"\x0f" + words(address, count) + bytes((byte_count,)) + b"\xaa" * byte_count


BAD_QUANTITY = st.one_of(st.just(0), st.integers(MAX_READ_BITS + 1, 0xFFFF))


@given(code=st.sampled_from((1, 2)), address=st.integers(0, 0xFFFF), count=BAD_QUANTITY)
def test_decoded_read_with_bad_quantity_is_exception_3(code: int, address: int, count: int) -> None:
    with pytest.raises(MalformedPDU) as caught:
        decode_request(_read_pdu(code, address, count))
    assert caught.value.exception_code == ExceptionCode.ILLEGAL_DATA_VALUE


@given(
    address=st.integers(0, 0xFFFF),
    count=st.one_of(st.just(0), st.integers(MAX_WRITE_BITS + 1, 0xFFFF)),
)
def test_decoded_write_coils_with_bad_quantity_is_exception_3(address: int, count: int) -> None:
    with pytest.raises(MalformedPDU) as caught:
        decode_request(_write_coils_pdu(address, count))
    assert caught.value.exception_code == ExceptionCode.ILLEGAL_DATA_VALUE


@st.composite
def _overflowing(draw: st.DrawFn, maximum: int) -> tuple[int, int]:
    count = draw(st.integers(2, maximum))
    address = draw(st.integers(0x10000 - count + 1, 0xFFFF))
    return address, count


@given(code=st.sampled_from((1, 2)), span=_overflowing(MAX_READ_BITS))
def test_decoded_read_past_the_end_is_exception_2(code: int, span: tuple[int, int]) -> None:
    with pytest.raises(MalformedPDU) as caught:
        decode_request(_read_pdu(code, *span))
    assert caught.value.exception_code == ExceptionCode.ILLEGAL_DATA_ADDRESS
    assert caught.value.field == "address + count"


@given(span=_overflowing(MAX_WRITE_BITS))
def test_decoded_write_coils_past_the_end_is_exception_2(span: tuple[int, int]) -> None:
    with pytest.raises(MalformedPDU) as caught:
        decode_request(_write_coils_pdu(*span))
    assert caught.value.exception_code == ExceptionCode.ILLEGAL_DATA_ADDRESS
    assert caught.value.field == "address + len(values)"


def test_quantity_is_checked_before_the_address_range() -> None:
    # Spec order: a quantity out of range is 03 even when the range also runs past the end.
    with pytest.raises(MalformedPDU) as caught:
        decode_request(_read_pdu(1, 0xFFFF, 2001))
    assert caught.value.exception_code == ExceptionCode.ILLEGAL_DATA_VALUE


def test_unknown_and_invalid_codes() -> None:
    assert isinstance(decode_request(b"\x41\x01"), RawPDU)
    for pdu in (b"\x00\x01", b"\x81\x02"):
        with pytest.raises(MalformedPDU) as caught:
            decode_request(pdu)
        assert caught.value.exception_code == ExceptionCode.ILLEGAL_FUNCTION


# check_response


@pytest.mark.parametrize("cls", list(REQUEST_STRATEGIES), ids=lambda c: c.__name__)
@given(data=st.data())
def test_matching_reply_passes(cls: type[Request], data: st.DataObject) -> None:
    request = data.draw(REQUEST_STRATEGIES[cls])
    reply = data.draw(replies_to(request))
    request.check_response(reply)
    decoded = decode_response(reply.encode())
    assert isinstance(decoded, Response)
    request.check_response(decoded)


MISMATCHES: list[tuple[Request, Response, str | None]] = [
    (ReadCoilsRequest(0, 8), ReadCoilsResponse([1] * 16), "byte_count"),
    (ReadCoilsRequest(0, 9), ReadCoilsResponse([1] * 8), "byte_count"),
    (ReadCoilsRequest(0, 8), ReadDiscreteInputsResponse([1] * 8), None),
    (ReadDiscreteInputsRequest(0, 8), ReadCoilsResponse([1] * 8), None),
    (ReadDiscreteInputsRequest(0, 17), ReadDiscreteInputsResponse([1] * 16), "byte_count"),
    (ReadCoilsRequest(0, 8), ReadHoldingRegistersResponse([1] * 8), None),
    (WriteSingleCoilRequest(5, True), WriteSingleCoilResponse(5, False), "value"),
    (WriteSingleCoilRequest(5, False), WriteSingleCoilResponse(5, True), "value"),
    (WriteSingleCoilRequest(5, True), WriteSingleCoilResponse(6, True), "address"),
    (WriteSingleCoilRequest(5, True), WriteMultipleCoilsResponse(5, 1), None),
    (WriteMultipleCoilsRequest(5, [1, 0]), WriteMultipleCoilsResponse(5, 3), "count"),
    (WriteMultipleCoilsRequest(5, [1, 0]), WriteMultipleCoilsResponse(4, 2), "address"),
    (WriteMultipleCoilsRequest(5, [1]), WriteSingleCoilResponse(5, True), None),
    (WriteMultipleCoilsRequest(5, [1]), RawPDU(0x0F, b"\x00\x05\x00\x01"), None),
]


@pytest.mark.parametrize(("request_", "reply", "field"), MISMATCHES)
def test_mismatching_reply_is_malformed(
    request_: Request, reply: Response, field: str | None
) -> None:
    with pytest.raises(MalformedPDU) as caught:
        request_.check_response(reply)
    assert caught.value.field == field


def test_unpadded_local_reply_passes_the_count_check() -> None:
    ReadCoilsRequest(0, 13).check_response(ReadCoilsResponse([True] * 13))
    with pytest.raises(MalformedPDU):
        ReadCoilsRequest(0, 13).check_response(ReadCoilsResponse([True] * 17))

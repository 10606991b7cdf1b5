"""The PDUs of the register tables: read holding (03) and input (04) registers, write single
(06) and multiple (10) registers, mask write (16), read/write multiple (17), read FIFO (18)."""

from __future__ import annotations

from collections.abc import Callable

import pytest
from hypothesis import given
from hypothesis import strategies as st

from aiortu.core.codes import ExceptionCode
from aiortu.core.errors import InvalidRequest, InvalidValue, MalformedPDU
from aiortu.core.pdu import (
    MAX_FIFO_COUNT,
    MAX_READ_REGISTERS,
    MAX_READ_WRITE_WRITE_REGISTERS,
    MAX_WRITE_REGISTERS,
    PDU,
    MaskWriteRegisterRequest,
    MaskWriteRegisterResponse,
    RawPDU,
    RawRegisterRead,
    ReadFifoQueueRequest,
    ReadFifoQueueResponse,
    ReadHoldingRegistersRequest,
    ReadHoldingRegistersResponse,
    ReadInputRegistersRequest,
    ReadInputRegistersResponse,
    ReadWriteMultipleRegistersRequest,
    ReadWriteMultipleRegistersResponse,
    Request,
    Response,
    WriteMultipleRegistersRequest,
    WriteMultipleRegistersResponse,
    WriteSingleCoilResponse,
    WriteSingleRegisterRequest,
    WriteSingleRegisterResponse,
    decode_request,
    decode_response,
)
from tests.core.strategies_bits_registers import (
    REGISTERS_REQUEST_STRATEGIES,
    REGISTERS_RESPONSE_STRATEGIES,
    mutations,
    registers,
    replies_to,
)

REQUEST_STRATEGIES = REGISTERS_REQUEST_STRATEGIES
RESPONSE_STRATEGIES = REGISTERS_RESPONSE_STRATEGIES

CODES = (0x03, 0x04, 0x06, 0x10, 0x16, 0x17, 0x18)
A = range(0x10000)
R = range(0x10000)
END = range(0x10001)
READ_COUNT = range(1, MAX_READ_REGISTERS + 1)
WRITE_COUNT = range(1, MAX_WRITE_REGISTERS + 1)
RW_WRITE_COUNT = range(1, MAX_READ_WRITE_WRITE_REGISTERS + 1)
FIFO_COUNT = range(MAX_FIFO_COUNT + 1)


def words(*values: int) -> bytes:
    return b"".join(value.to_bytes(2, "big") for value in values)


def decodes_cleanly(data: bytes, decode: Callable[[bytes], PDU]) -> PDU | None:
    """Decode *data*; only MalformedPDU may escape, and a success must re-encode to *data*."""
    try:
        decoded = decode(data)
    except MalformedPDU:
        return None
    assert decoded.encode() == data
    return decoded


# Round trips


@pytest.mark.parametrize("cls", list(REQUEST_STRATEGIES), ids=lambda c: c.__name__)
@given(data=st.data())
def test_request_round_trip(cls: type[Request], data: st.DataObject) -> None:
    request = data.draw(REQUEST_STRATEGIES[cls])
    encoded = request.encode()
    assert encoded[0] == cls.function_code
    assert len(encoded) <= 253
    assert cls.decode(encoded) == request
    decoded = decode_request(encoded)
    assert type(decoded) is cls
    assert decoded == request


@pytest.mark.parametrize("cls", list(RESPONSE_STRATEGIES), ids=lambda c: c.__name__)
@given(data=st.data())
def test_response_round_trip(cls: type[Response], data: st.DataObject) -> None:
    response = data.draw(RESPONSE_STRATEGIES[cls])
    encoded = response.encode()
    assert len(encoded) <= 253
    assert cls.decode(encoded) == response
    decoded = decode_response(encoded)
    assert type(decoded) is cls
    assert decoded == response


def test_every_class_has_a_strategy() -> None:
    assert set(REQUEST_STRATEGIES) == {
        ReadHoldingRegistersRequest,
        ReadInputRegistersRequest,
        WriteSingleRegisterRequest,
        WriteMultipleRegistersRequest,
        MaskWriteRegisterRequest,
        ReadWriteMultipleRegistersRequest,
        ReadFifoQueueRequest,
    }
    assert set(RESPONSE_STRATEGIES) == {cls.response_class for cls in REQUEST_STRATEGIES}


def test_broadcastable() -> None:
    assert WriteSingleRegisterRequest.broadcastable
    assert WriteMultipleRegistersRequest.broadcastable
    assert MaskWriteRegisterRequest.broadcastable
    for cls in (
        ReadHoldingRegistersRequest,
        ReadInputRegistersRequest,
        ReadWriteMultipleRegistersRequest,
        ReadFifoQueueRequest,
    ):
        assert not cls.broadcastable, cls


def test_largest_pdus_fit() -> None:
    assert len(WriteMultipleRegistersRequest(0, [0] * MAX_WRITE_REGISTERS).encode()) == 252
    request = ReadWriteMultipleRegistersRequest(0, 125, 0, [0] * MAX_READ_WRITE_WRITE_REGISTERS)
    assert len(request.encode()) == 252
    assert len(ReadHoldingRegistersResponse([0] * MAX_READ_REGISTERS).encode()) == 252
    assert len(ReadFifoQueueResponse([0] * MAX_FIFO_COUNT).encode()) == 67


# Vectors


def test_read_holding_registers_vector_of_the_notes() -> None:
    # Unit 17, `11 03 00 6B 00 03 76 87` and `11 03 06 AE 41 56 52 43 40 49 AD`: the PDUs are
    # the frames without the unit address and the CRC.
    request = ReadHoldingRegistersRequest(0x6B, 3)
    assert request.encode() == bytes.fromhex("03 00 6B 00 03")
    assert decode_request(bytes.fromhex("03 00 6B 00 03")) == request
    reply = decode_response(bytes.fromhex("03 06 AE 41 56 52 43 40"))
    assert reply == ReadHoldingRegistersResponse((0xAE41, 0x5652, 0x4340))
    assert isinstance(reply, Response)
    request.check_response(reply)


@pytest.mark.parametrize(
    ("pdu", "request_", "reply", "response"),
    [
        (
            "04 00 08 00 01",
            ReadInputRegistersRequest(8, 1),
            "04 02 00 0A",
            ReadInputRegistersResponse([10]),
        ),
        (
            "06 00 01 00 03",
            WriteSingleRegisterRequest(1, 3),
            "06 00 01 00 03",
            WriteSingleRegisterResponse(1, 3),
        ),
        (
            "10 00 01 00 02 04 00 0A 01 02",
            WriteMultipleRegistersRequest(1, [0x000A, 0x0102]),
            "10 00 01 00 02",
            WriteMultipleRegistersResponse(1, 2),
        ),
        (
            "16 00 04 00 F2 00 25",
            MaskWriteRegisterRequest(4, 0x00F2, 0x0025),
            "16 00 04 00 F2 00 25",
            MaskWriteRegisterResponse(4, 0x00F2, 0x0025),
        ),
        (
            "17 00 03 00 06 00 0E 00 03 06 00 FF 00 FF 00 FF",
            ReadWriteMultipleRegistersRequest(3, 6, 14, [0xFF, 0xFF, 0xFF]),
            "17 0C 00 FE 0A CD 00 01 00 03 00 0D 00 FF",
            ReadWriteMultipleRegistersResponse([0xFE, 0x0ACD, 1, 3, 0x0D, 0xFF]),
        ),
        (
            "18 04 DE",
            ReadFifoQueueRequest(0x04DE),
            "18 00 06 00 02 01 B8 12 84",
            ReadFifoQueueResponse([0x01B8, 0x1284]),
        ),
        ("18 00 00", ReadFifoQueueRequest(0), "18 00 02 00 00", ReadFifoQueueResponse([])),
    ],
)
def test_vectors(pdu: str, request_: Request, reply: str, response: Response) -> None:
    assert request_.encode() == bytes.fromhex(pdu)
    assert decode_request(bytes.fromhex(pdu)) == request_
    assert response.encode() == bytes.fromhex(reply)
    decoded = decode_response(bytes.fromhex(reply))
    assert decoded == response
    request_.check_response(response)


@pytest.mark.parametrize(
    ("current", "and_mask", "or_mask", "result"),
    [
        (0x12, 0xF2, 0x25, 0x17),
        (0xFFFF, 0xFFFF, 0x0000, 0xFFFF),
        (0xFFFF, 0x0000, 0x0000, 0x0000),
        (0x1234, 0x0000, 0xABCD, 0xABCD),
        (0x0000, 0xFF00, 0x00FF, 0x00FF),
    ],
)
def test_mask_write_apply(current: int, and_mask: int, or_mask: int, result: int) -> None:
    assert MaskWriteRegisterRequest(0, and_mask, or_mask).apply(current) == result


@given(current=registers(), and_mask=registers(), or_mask=registers())
def test_mask_write_apply_bitwise(current: int, and_mask: int, or_mask: int) -> None:
    result = MaskWriteRegisterRequest(0, and_mask, or_mask).apply(current)
    assert result in R
    for bit in range(16):
        expected = (current if and_mask >> bit & 1 else or_mask) >> bit & 1
        assert result >> bit & 1 == expected


# Construction


def _rw(read_address: int = 0, read_count: int = 1, write_address: int = 0, n: int = 1) -> object:
    return ReadWriteMultipleRegistersRequest(read_address, read_count, write_address, [0] * n)


INVALID: list[tuple[Callable[[], object], type[InvalidValue], str, object, range]] = []
for _read in (ReadHoldingRegistersRequest, ReadInputRegistersRequest):
    INVALID += [
        (lambda c=_read: c(-1, 1), InvalidRequest, "address", -1, A),
        (lambda c=_read: c(0x10000, 1), InvalidRequest, "address", 0x10000, A),
        (lambda c=_read: c(0, 0), InvalidRequest, "count", 0, READ_COUNT),
        (lambda c=_read: c(0, 126), InvalidRequest, "count", 126, READ_COUNT),
        (lambda c=_read: c(0xFFFF, 2), InvalidRequest, "address + count", 0x10001, END),
    ]
for _response in (ReadHoldingRegistersResponse, ReadInputRegistersResponse):
    INVALID += [
        (lambda c=_response: c([]), InvalidValue, "len(values)", 0, READ_COUNT),
        (lambda c=_response: c([0] * 126), InvalidValue, "len(values)", 126, READ_COUNT),
        (lambda c=_response: c([1, -1]), InvalidValue, "values[1]", -1, R),
        (lambda c=_response: c([0x10000]), InvalidValue, "values[0]", 0x10000, R),
    ]
for _single, _error in (
    (WriteSingleRegisterRequest, InvalidRequest),
    (WriteSingleRegisterResponse, InvalidValue),
):
    INVALID += [
        (lambda c=_single: c(-1, 0), _error, "address", -1, A),
        (lambda c=_single: c(0x10000, 0), _error, "address", 0x10000, A),
        (lambda c=_single: c(0, -1), _error, "value", -1, R),
        (lambda c=_single: c(0, 0x10000), _error, "value", 0x10000, R),
    ]
for _mask, _error in (
    (MaskWriteRegisterRequest, InvalidRequest),
    (MaskWriteRegisterResponse, InvalidValue),
):
    INVALID += [
        (lambda c=_mask: c(-1, 0, 0), _error, "address", -1, A),
        (lambda c=_mask: c(0x10000, 0, 0), _error, "address", 0x10000, A),
        (lambda c=_mask: c(0, -1, 0), _error, "and_mask", -1, R),
        (lambda c=_mask: c(0, 0x10000, 0), _error, "and_mask", 0x10000, R),
        (lambda c=_mask: c(0, 0, -1), _error, "or_mask", -1, R),
        (lambda c=_mask: c(0, 0, 0x10000), _error, "or_mask", 0x10000, R),
    ]
INVALID += [
    (lambda: WriteMultipleRegistersRequest(-1, [0]), InvalidRequest, "address", -1, A),
    (lambda: WriteMultipleRegistersRequest(0x10000, [0]), InvalidRequest, "address", 0x10000, A),
    (lambda: WriteMultipleRegistersRequest(0, []), InvalidRequest, "len(values)", 0, WRITE_COUNT),
    (
        lambda: WriteMultipleRegistersRequest(0, [0] * 124),
        InvalidRequest,
        "len(values)",
        124,
        WRITE_COUNT,
    ),
    (lambda: WriteMultipleRegistersRequest(0, [0, -1]), InvalidRequest, "values[1]", -1, R),
    (lambda: WriteMultipleRegistersRequest(0, [0x10000]), InvalidRequest, "values[0]", 65536, R),
    (
        lambda: WriteMultipleRegistersRequest(0xFFFF, [0, 0]),
        InvalidRequest,
        "address + len(values)",
        0x10001,
        END,
    ),
    (lambda: WriteMultipleRegistersResponse(-1, 1), InvalidValue, "address", -1, A),
    (lambda: WriteMultipleRegistersResponse(0x10000, 1), InvalidValue, "address", 65536, A),
    (lambda: WriteMultipleRegistersResponse(0, 0), InvalidValue, "count", 0, WRITE_COUNT),
    (lambda: WriteMultipleRegistersResponse(0, 124), InvalidValue, "count", 124, WRITE_COUNT),
    (
        lambda: WriteMultipleRegistersResponse(0xFFFF, 2),
        InvalidValue,
        "address + count",
        65537,
        END,
    ),
    (lambda: _rw(read_address=-1), InvalidRequest, "read_address", -1, A),
    (lambda: _rw(read_address=0x10000), InvalidRequest, "read_address", 0x10000, A),
    (lambda: _rw(write_address=-1), InvalidRequest, "write_address", -1, A),
    (lambda: _rw(write_address=0x10000), InvalidRequest, "write_address", 0x10000, A),
    (lambda: _rw(read_count=0), InvalidRequest, "read_count", 0, READ_COUNT),
    (lambda: _rw(read_count=126), InvalidRequest, "read_count", 126, READ_COUNT),
    (lambda: _rw(n=0), InvalidRequest, "len(values)", 0, RW_WRITE_COUNT),
    (lambda: _rw(n=122), InvalidRequest, "len(values)", 122, RW_WRITE_COUNT),
    (
        lambda: ReadWriteMultipleRegistersRequest(0, 1, 0, [0x10000]),
        InvalidRequest,
        "values[0]",
        0x10000,
        R,
    ),
    (
        lambda: _rw(read_address=0xFFFF, read_count=2),
        InvalidRequest,
        "read_address + read_count",
        0x10001,
        END,
    ),
    (
        lambda: _rw(write_address=0xFFFF, n=2),
        InvalidRequest,
        "write_address + len(values)",
        0x10001,
        END,
    ),
    (lambda: ReadWriteMultipleRegistersResponse([]), InvalidValue, "len(values)", 0, READ_COUNT),
    (
        lambda: ReadWriteMultipleRegistersResponse([0] * 126),
        InvalidValue,
        "len(values)",
        126,
        READ_COUNT,
    ),
    (lambda: ReadWriteMultipleRegistersResponse([-1]), InvalidValue, "values[0]", -1, R),
    (lambda: ReadFifoQueueRequest(-1), InvalidRequest, "address", -1, A),
    (lambda: ReadFifoQueueRequest(0x10000), InvalidRequest, "address", 0x10000, A),
    (lambda: ReadFifoQueueResponse([0] * 32), InvalidValue, "len(values)", 32, FIFO_COUNT),
    (lambda: ReadFifoQueueResponse([0, 0x10000]), InvalidValue, "values[1]", 0x10000, R),
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


def test_limits_accepted() -> None:
    assert ReadHoldingRegistersRequest(0x10000 - 125, 125).count == 125
    assert WriteMultipleRegistersRequest(0x10000 - 123, [0xFFFF] * 123).count == 123
    request = ReadWriteMultipleRegistersRequest(0x10000 - 125, 125, 0x10000 - 121, [1] * 121)
    assert request.write_count == 121
    assert ReadFifoQueueResponse([0xFFFF] * 31).values[-1] == 0xFFFF
    assert WriteMultipleRegistersRequest(0, iter([1, 2])).values == (1, 2)  # type: ignore[arg-type]


# Decoding errors


@given(code=st.sampled_from(CODES), body=st.binary(max_size=260))
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


@pytest.mark.parametrize(
    ("pdu", "field"),
    [
        ("10 00 00 00 02 03 00 01 00", "byte_count"),
        ("10 00 00 00 02 04 00 01 00", "length"),
        ("10 00 00 00 02 04 00 01 00 02 00", "length"),
        ("10 00 00 00 01 02", "length"),
        ("17 00 00 00 01 00 00 00 01 01 00 01", "byte_count"),
        ("17 00 00 00 01 00 00 00 01 02 00", "length"),
        ("17 00 00 00 01 00 00 00 00 00 00 00", "write_count"),
        ("17 00 00 00 01 00 00 00 7A F4 00 00", "write_count"),
        ("06 00 00 00", "length"),
        ("16 00 00 00 00 00", "length"),
        ("18 00", "length"),
        ("18 00 00 00", "length"),
    ],
)
def test_malformed_requests(pdu: str, field: str) -> None:
    with pytest.raises(MalformedPDU) as caught:
        decode_request(bytes.fromhex(pdu))
    assert caught.value.field == field
    assert caught.value.exception_code == ExceptionCode.ILLEGAL_DATA_VALUE


@pytest.mark.parametrize(
    ("pdu", "field"),
    [
        ("18 00 04 00 02 00 01 00 02", "byte_count"),
        ("18 00 06 00 02 00 01", "length"),
        ("18 00 42 00 20" + " 00 00" * 32, "fifo_count"),
        ("18 00 02 00 00 00", "length"),
        ("17 03 00 01 00", "byte_count"),
        ("17 00", "length"),
        ("10 00 00 00 00", "count"),
        ("10 00 00 00 7C", "count"),
        ("10 FF FF 00 02", "address + count"),
        ("03 02 00", "length"),
    ],
)
def test_malformed_responses(pdu: str, field: str) -> None:
    with pytest.raises(MalformedPDU) as caught:
        decode_response(bytes.fromhex(pdu))
    assert caught.value.field == field


def _write_pdu(address: int, count: int) -> bytes:
    byte_count = min(2 * count, 255)
    return b"\x10" + words(address, count) + bytes((byte_count,)) + b"\x12" * byte_count


def _rw_pdu(read_address: int, read_count: int, write_address: int, write_count: int) -> bytes:
    byte_count = min(2 * write_count, 255)
    head = words(read_address, read_count, write_address, write_count)
    return b"\x17" + head + bytes((byte_count,)) + b"\x34" * byte_count


def _bad(maximum: int) -> st.SearchStrategy[int]:
    return st.one_of(st.just(0), st.just(maximum + 1), st.integers(maximum + 1, 0xFFFF))


def _good(maximum: int) -> st.SearchStrategy[int]:
    return st.integers(1, maximum)


ADDRESS = st.integers(0, 0xFFFF)

BAD_QUANTITY_PDUS = st.one_of(
    st.builds(
        lambda code, a, n: bytes((code,)) + words(a, n),
        st.sampled_from((3, 4)),
        ADDRESS,
        _bad(MAX_READ_REGISTERS),
    ),
    st.builds(_write_pdu, ADDRESS, _bad(MAX_WRITE_REGISTERS)),
    st.builds(_rw_pdu, ADDRESS, _bad(125), ADDRESS, _good(121)),
    st.builds(_rw_pdu, ADDRESS, _good(125), ADDRESS, _bad(121)),
)


@given(pdu=BAD_QUANTITY_PDUS)
def test_decoded_request_with_bad_quantity_is_exception_3(pdu: bytes) -> None:
    with pytest.raises(MalformedPDU) as caught:
        decode_request(pdu)
    assert caught.value.exception_code == ExceptionCode.ILLEGAL_DATA_VALUE


@st.composite
def _overflowing(draw: st.DrawFn, maximum: int) -> tuple[int, int]:
    count = draw(st.integers(2, maximum))
    address = draw(st.integers(0x10000 - count + 1, 0xFFFF))
    return address, count


@st.composite
def _fitting(draw: st.DrawFn, maximum: int) -> tuple[int, int]:
    count = draw(st.integers(1, maximum))
    return draw(st.integers(0, 0x10000 - count)), count


PAST_THE_END_PDUS = st.one_of(
    st.builds(
        lambda code, span: (bytes((code,)) + words(*span), "address + count"),
        st.sampled_from((3, 4)),
        _overflowing(125),
    ),
    st.builds(lambda span: (_write_pdu(*span), "address + len(values)"), _overflowing(123)),
    st.builds(
        lambda r, w: (_rw_pdu(*r, *w), "read_address + read_count"),
        _overflowing(125),
        _fitting(121),
    ),
    st.builds(
        lambda r, w: (_rw_pdu(*r, *w), "write_address + len(values)"),
        _fitting(125),
        _overflowing(121),
    ),
)


@given(case=PAST_THE_END_PDUS)
def test_decoded_request_past_the_end_is_exception_2(case: tuple[bytes, str]) -> None:
    pdu, field = case
    with pytest.raises(MalformedPDU) as caught:
        decode_request(pdu)
    assert caught.value.exception_code == ExceptionCode.ILLEGAL_DATA_ADDRESS
    assert caught.value.field == field


@pytest.mark.parametrize(
    "pdu",
    [
        bytes.fromhex("03 FF FF 00 7E"),
        _write_pdu(0xFFFF, 0),
        _rw_pdu(0xFFFF, 126, 0, 1),
        _rw_pdu(0, 1, 0xFFFF, 122),
    ],
)
def test_quantity_is_checked_before_the_address_range(pdu: bytes) -> None:
    with pytest.raises(MalformedPDU) as caught:
        decode_request(pdu)
    assert caught.value.exception_code == ExceptionCode.ILLEGAL_DATA_VALUE


def test_class_decode_checks_the_function_code() -> None:
    with pytest.raises(MalformedPDU) as caught:
        ReadHoldingRegistersRequest.decode(bytes.fromhex("04 00 00 00 01"))
    assert caught.value.field == "function_code"
    with pytest.raises(MalformedPDU):
        ReadFifoQueueRequest.decode(b"")


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
    (ReadHoldingRegistersRequest(0, 2), ReadHoldingRegistersResponse([1]), "byte_count"),
    (ReadHoldingRegistersRequest(0, 2), ReadHoldingRegistersResponse([1, 2, 3]), "byte_count"),
    (ReadHoldingRegistersRequest(0, 1), ReadInputRegistersResponse([1]), None),
    (ReadInputRegistersRequest(0, 1), ReadHoldingRegistersResponse([1]), None),
    (ReadHoldingRegistersRequest(0, 1), ReadWriteMultipleRegistersResponse([1]), None),
    (WriteSingleRegisterRequest(1, 2), WriteSingleRegisterResponse(1, 3), "value"),
    (WriteSingleRegisterRequest(1, 2), WriteSingleRegisterResponse(0, 2), "address"),
    (WriteSingleRegisterRequest(1, 1), WriteSingleCoilResponse(1, True), None),
    (WriteMultipleRegistersRequest(1, [2, 3]), WriteMultipleRegistersResponse(1, 3), "count"),
    (WriteMultipleRegistersRequest(1, [2, 3]), WriteMultipleRegistersResponse(2, 2), "address"),
    (WriteMultipleRegistersRequest(1, [2]), WriteSingleRegisterResponse(1, 2), None),
    (MaskWriteRegisterRequest(1, 2, 3), MaskWriteRegisterResponse(0, 2, 3), "address"),
    (MaskWriteRegisterRequest(1, 2, 3), MaskWriteRegisterResponse(1, 0, 3), "and_mask"),
    (MaskWriteRegisterRequest(1, 2, 3), MaskWriteRegisterResponse(1, 2, 0), "or_mask"),
    (MaskWriteRegisterRequest(1, 2, 3), RawPDU(0x16, words(1, 2, 3)), None),
    (
        ReadWriteMultipleRegistersRequest(0, 2, 0, [1]),
        ReadWriteMultipleRegistersResponse([1]),
        "byte_count",
    ),
    (
        ReadWriteMultipleRegistersRequest(0, 1, 0, [1]),
        ReadHoldingRegistersResponse([1]),
        None,
    ),
    (ReadFifoQueueRequest(0), ReadHoldingRegistersResponse([1]), None),
]


@pytest.mark.parametrize(("request_", "reply", "field"), MISMATCHES)
def test_mismatching_reply_is_malformed(
    request_: Request, reply: Response, field: str | None
) -> None:
    with pytest.raises(MalformedPDU) as caught:
        request_.check_response(reply)
    assert caught.value.field == field


@pytest.mark.parametrize(
    ("code", "data", "field"),
    [
        (0x06, "0000 0001", "function_code"),
        (0x03, "0000 00", "len(data)"),
        (0x03, "0000 0000", "count"),
        (0x04, "0000 007E", "count"),
        (0x03, "FFFF 0002", "address + count"),
    ],
)
def test_a_raw_register_read_checks_what_the_decoded_read_checks(
    code: int, data: str, field: str
) -> None:
    with pytest.raises(InvalidRequest) as caught:
        RawRegisterRead(code, bytes.fromhex(data))
    assert caught.value.field == field


@pytest.mark.parametrize(
    "reply",
    [
        "03 06 0001 0002 0003",  # the usual reply
        "03 04 0001 0002",  # two registers of three
        "03 06 0001 0002",  # a byte count that lies about what follows
        "03 06 0001 0002 0003 04",  # a byte too many
        "03 07 0001 0002 0003 04",  # an odd byte count
        "03",  # nothing after the function code
        "04 06 0001 0002 0003",  # another function code
    ],
)
def test_a_raw_register_read_takes_the_replies_the_decoded_read_takes(reply: str) -> None:
    pdu = bytes.fromhex(reply)
    raw = RawRegisterRead(0x03, bytes.fromhex("0010 0003"))
    decoded = ReadHoldingRegistersRequest(0x10, 3)

    def answers(request: Request, response: Response) -> bool:
        try:
            request.check_response(response)
        except MalformedPDU:
            return False
        return True

    try:
        response = decode_response(pdu)
    except MalformedPDU:
        decoded_takes = False
    else:
        decoded_takes = answers(decoded, response)
        # A late reply is checked against a raw read decoded, as the machine decodes it.
        assert answers(raw, response) is decoded_takes
    assert answers(raw, RawPDU.decode(pdu)) is decoded_takes
    assert decoded_takes is (reply == "03 06 0001 0002 0003")

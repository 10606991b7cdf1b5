"""The PDUs of the serial-line functions: 07, 08, 0B, 0C and 11."""

from __future__ import annotations

from typing import Any

import pytest
from hypothesis import given
from hypothesis import strategies as st

from aiortu.core.codes import DiagnosticSubFunction, FunctionCode
from aiortu.core.errors import InvalidRequest, InvalidValue, MalformedPDU
from aiortu.core.pdu import (
    DiagnosticsRequest,
    DiagnosticsResponse,
    GetCommEventCounterRequest,
    GetCommEventCounterResponse,
    GetCommEventLogRequest,
    GetCommEventLogResponse,
    ReadExceptionStatusRequest,
    ReadExceptionStatusResponse,
    ReportServerIdRequest,
    ReportServerIdResponse,
    decode_request,
    decode_response,
)
from aiortu.core.pdu import _serial_line as sl
from tests.core.pdu_contract import assert_invalid, assert_only_malformed, assert_round_trip
from tests.core.strategies_serial_files_devid import (
    COUNTER_SUB_FUNCTIONS,
    REQUEST_STRATEGIES,
    RESPONSE_STRATEGIES,
    ZERO_WORD_SUB_FUNCTIONS,
    mutations,
)

REQUESTS = [cls for cls in REQUEST_STRATEGIES if vars(sl).get(cls.__name__) is cls]
RESPONSES = [cls for cls in RESPONSE_STRATEGIES if vars(sl).get(cls.__name__) is cls]
CODES = (0x07, 0x08, 0x0B, 0x0C, 0x11)
D = DiagnosticSubFunction


def test_every_class_has_a_strategy() -> None:
    public = {getattr(sl, name) for name in sl.__all__}
    assert {cls for cls in public if isinstance(cls, type)} == set(REQUESTS) | set(RESPONSES)
    assert isinstance(sl.__all__, tuple)


@pytest.mark.parametrize("cls", REQUESTS, ids=lambda cls: cls.__name__)
@given(data=st.data())
def test_request_round_trip(cls: type, data: st.DataObject) -> None:
    assert_round_trip(data.draw(REQUEST_STRATEGIES[cls]))


@pytest.mark.parametrize("cls", RESPONSES, ids=lambda cls: cls.__name__)
@given(data=st.data())
def test_response_round_trip(cls: type, data: st.DataObject) -> None:
    assert_round_trip(data.draw(RESPONSE_STRATEGIES[cls]))


# Byte-exact vectors (the first ones from the spec's examples).


@pytest.mark.parametrize(
    ("pdu", "wire"),
    [
        (ReadExceptionStatusRequest(), "07"),
        (ReadExceptionStatusResponse(0x6D), "07 6D"),
        (DiagnosticsRequest(D.RETURN_QUERY_DATA, b"\xa5\x37"), "08 00 00 A5 37"),
        (DiagnosticsResponse(D.RETURN_QUERY_DATA, b"\xa5\x37"), "08 00 00 A5 37"),
        (DiagnosticsRequest(D.RESTART_COMMUNICATIONS, b"\xff\x00"), "08 00 01 FF 00"),
        (DiagnosticsRequest(D.RETURN_DIAGNOSTIC_REGISTER), "08 00 02 00 00"),
        (DiagnosticsResponse(D.RETURN_DIAGNOSTIC_REGISTER, b"\x12\x34"), "08 00 02 12 34"),
        (DiagnosticsRequest(D.CHANGE_ASCII_INPUT_DELIMITER, b"\x0a\x00"), "08 00 03 0A 00"),
        (DiagnosticsRequest(D.RETURN_BUS_MESSAGE_COUNT), "08 00 0B 00 00"),
        (GetCommEventCounterRequest(), "0B"),
        (GetCommEventCounterResponse(0xFFFF, 0x0108), "0B FF FF 01 08"),
        (GetCommEventLogRequest(), "0C"),
        (
            GetCommEventLogResponse(0x0000, 0x0108, 0x0121, b"\x20\x00"),
            "0C 08 00 00 01 08 01 21 20 00",
        ),
        (ReportServerIdRequest(), "11"),
        (ReportServerIdResponse(b"\x2a", True, b"PLC-7"), "11 07 2A FF 50 4C 43 2D 37"),
        (ReportServerIdResponse(b"\x01", False), "11 02 01 00"),
    ],
    ids=repr,
)
def test_vectors(pdu: Any, wire: str) -> None:
    assert pdu.encode() == bytes.fromhex(wire)
    assert_round_trip(pdu)


def test_decoded_sub_function_is_the_enum_when_known() -> None:
    decoded = decode_request(bytes.fromhex("08 00 0E 00 00"))
    assert isinstance(decoded, DiagnosticsRequest)
    assert decoded.sub_function is D.RETURN_SERVER_MESSAGE_COUNT
    unknown = decode_request(bytes.fromhex("08 00 15 00 03 01"))
    assert isinstance(unknown, DiagnosticsRequest)
    assert type(unknown.sub_function) is int
    assert unknown.sub_function == 0x15
    assert unknown.data == b"\x00\x03\x01"


def test_properties() -> None:
    assert ReadExceptionStatusResponse(0b1000_0101).bits == (
        True, False, True, False, False, False, False, True,
    )  # fmt: skip
    assert GetCommEventCounterResponse(0xFFFF, 3).busy
    assert not GetCommEventLogResponse(0, 1, 2).busy
    assert DiagnosticsResponse(D.RETURN_BUS_MESSAGE_COUNT, b"\x01\x02").value == 0x0102
    assert not DiagnosticsRequest(D.FORCE_LISTEN_ONLY_MODE).expects_reply
    assert DiagnosticsRequest(D.RETURN_QUERY_DATA, b"").expects_reply


# Report server ID: the decode rule and re-splitting.


def test_report_server_id_multi_byte_id_decodes_up_to_the_run_indicator() -> None:
    decoded = ReportServerIdResponse.decode(bytes.fromhex("11 06 41 42 43 FF 01 02"))
    assert decoded == ReportServerIdResponse(b"ABC", True, b"\x01\x02")


def test_report_server_id_ambiguous_id_is_lossless_and_can_be_re_split() -> None:
    original = ReportServerIdResponse(b"\x07\x00\x09", True, b"x")
    decoded = ReportServerIdResponse.decode(original.encode())
    assert decoded == ReportServerIdResponse(b"\x07", False, b"\x09\xffx")
    assert decoded.encode() == original.encode()
    assert decoded.with_id_length(3) == original
    assert_invalid(lambda: decoded.with_id_length(2), InvalidValue, "byte 2 (run indicator)", 9)
    assert_invalid(lambda: decoded.with_id_length(0), InvalidValue, "id_length", 0)
    assert_invalid(lambda: decoded.with_id_length(5), InvalidValue, "id_length", 5)


def test_report_server_id_without_a_run_indicator_is_malformed() -> None:
    with pytest.raises(MalformedPDU) as caught:
        ReportServerIdResponse.decode(bytes.fromhex("11 03 41 42 43"))
    assert caught.value.field == "run_indicator"


# Construction rejects every field out of range.


@pytest.mark.parametrize(
    ("build", "error", "field", "value", "allowed"),
    [
        (lambda: ReadExceptionStatusResponse(256), InvalidValue, "status", 256, range(256)),
        (lambda: ReadExceptionStatusResponse(-1), InvalidValue, "status", -1, range(256)),
        (lambda: DiagnosticsRequest(-1), InvalidRequest, "sub_function", -1, range(0x10000)),
        (
            lambda: DiagnosticsResponse(0x10000, b""),
            InvalidValue,
            "sub_function",
            0x10000,
            range(0x10000),
        ),
        (
            lambda: DiagnosticsRequest(0, b"\x01"),
            InvalidRequest,
            "len(data)",
            1,
            range(0, 251, 2),
        ),
        (
            lambda: DiagnosticsResponse(0, b"\x01\x02\x03"),
            InvalidValue,
            "len(data)",
            3,
            range(0, 251, 2),
        ),
        (lambda: DiagnosticsRequest(0, bytes(252)), InvalidRequest, "len(data)", 252, None),
        (lambda: DiagnosticsRequest(0x15, bytes(251)), InvalidRequest, "len(data)", 251, None),
        (lambda: DiagnosticsRequest(1, b"\x12\x34"), InvalidRequest, "data", 0x1234, None),
        (lambda: DiagnosticsResponse(1, b"\x00\x01"), InvalidValue, "data", 1, None),
        (lambda: DiagnosticsRequest(1, b""), InvalidRequest, "len(data)", 0, range(2, 3)),
        (lambda: DiagnosticsRequest(2, b"\x00\x01"), InvalidRequest, "data", 1, range(1)),
        (lambda: DiagnosticsRequest(2, b"\x00\x00\x00"), InvalidRequest, "len(data)", 3, None),
        (lambda: DiagnosticsResponse(0x0B, b"\x00"), InvalidValue, "len(data)", 1, range(2, 3)),
        (lambda: DiagnosticsRequest(3, b"\x0a\x01"), InvalidRequest, "data", 0x0A01, None),
        (lambda: DiagnosticsResponse(3, b"\x0a\x01"), InvalidValue, "data", 0x0A01, None),
        (lambda: DiagnosticsRequest(4, b"\xff\x00"), InvalidRequest, "data", 0xFF00, range(1)),
        (lambda: DiagnosticsResponse(4, b"\x00\x01"), InvalidValue, "data", 1, range(1)),
        (lambda: DiagnosticsRequest(0x14, b"\x00\x01"), InvalidRequest, "data", 1, range(1)),
        (lambda: GetCommEventCounterResponse(1, 0), InvalidValue, "status", 1, None),
        (
            lambda: GetCommEventCounterResponse(0, 0x10000),
            InvalidValue,
            "event_count",
            0x10000,
            range(0x10000),
        ),
        (lambda: GetCommEventLogResponse(0xFF00, 0, 0), InvalidValue, "status", 0xFF00, None),
        (lambda: GetCommEventLogResponse(0, -1, 0), InvalidValue, "event_count", -1, None),
        (lambda: GetCommEventLogResponse(0, 0, 65536), InvalidValue, "message_count", 65536, None),
        (
            lambda: GetCommEventLogResponse(0, 0, 0, bytes(65)),
            InvalidValue,
            "len(events)",
            65,
            range(65),
        ),
        (
            lambda: ReportServerIdResponse(b"", True),
            InvalidValue,
            "len(server_id)",
            0,
            range(1, 252),
        ),
        (
            lambda: ReportServerIdResponse(b"\x01", True, bytes(250)),
            InvalidValue,
            "len(server_id) + 1 + len(additional_data)",
            252,
            range(2, 252),
        ),
    ],
)
def test_fields_out_of_range(
    build: Any, error: type[InvalidValue], field: str, value: object, allowed: object
) -> None:
    assert_invalid(build, error, field, value, allowed)


def test_data_must_be_bytes_not_an_int() -> None:
    with pytest.raises(TypeError):
        DiagnosticsRequest(1, 0xFF00)  # type: ignore[arg-type]
    with pytest.raises(TypeError):
        ReportServerIdResponse(b"\x01", True, 5)  # type: ignore[arg-type]


def test_sub_functions_table_is_complete() -> None:
    # Each defined sub-function has fixed data; only 00 and unknown ones take free data.
    for sub in D:
        if sub in ZERO_WORD_SUB_FUNCTIONS:
            DiagnosticsRequest(sub)
            with pytest.raises(InvalidRequest):
                DiagnosticsRequest(sub, b"\x00\x02")
        if sub in COUNTER_SUB_FUNCTIONS:
            assert DiagnosticsResponse(sub, b"\xbe\xef").value == 0xBEEF


# Decoding: wrong bytes give MalformedPDU and nothing else.


@pytest.mark.parametrize(
    ("decode", "wire", "field"),
    [
        (decode_request, "07 00", "length"),
        (decode_response, "07", "length"),
        (decode_response, "07 01 02", "length"),
        (decode_request, "08 00", "length"),
        (decode_request, "08 00 00 01", "len(data)"),
        (decode_request, "08 00 01 00 01", "data"),
        (decode_response, "08 00 0B 00", "len(data)"),
        (decode_response, "0B 00 00 00", "length"),
        (decode_response, "0B FF 00 00 01", "status"),
        (decode_response, "0C 05 00 00 00 00 00 00", "byte_count"),
        (decode_response, "0C 47 00 00 00 00 00 00", "byte_count"),
        (decode_response, "0C 07 00 00 00 00 00 00", "length"),
        (decode_request, "0C 00", "length"),
        (decode_response, "11 01 41 FF", "byte_count"),
        (decode_response, "11 03 41 FF", "length"),
    ],
    ids=str,
)
def test_malformed_vectors(decode: Any, wire: str, field: str) -> None:
    with pytest.raises(MalformedPDU) as caught:
        decode(bytes.fromhex(wire))
    assert caught.value.field == field
    assert caught.value.exception_code == 3


ALL_STRATEGIES = [
    *(REQUEST_STRATEGIES[cls] for cls in REQUESTS),
    *(RESPONSE_STRATEGIES[cls] for cls in RESPONSES),
]
encoded = st.one_of(ALL_STRATEGIES).map(lambda pdu: pdu.encode())


@given(code=st.sampled_from(CODES), body=st.binary(max_size=260))
def test_arbitrary_bytes_only_malformed(code: int, body: bytes) -> None:
    data = bytes((code,)) + body
    assert_only_malformed(decode_request, data)
    assert_only_malformed(decode_response, data)


@given(data=mutations(encoded))
def test_mutations_only_malformed(data: bytes) -> None:
    assert_only_malformed(decode_request, data)
    assert_only_malformed(decode_response, data)


@pytest.mark.parametrize("cls", REQUESTS + RESPONSES, ids=lambda cls: cls.__name__)
@given(body=st.binary(max_size=300))
def test_class_decode_only_malformed(cls: Any, body: bytes) -> None:
    assert_only_malformed(cls.decode, bytes((cls.function_code,)) + body)


# check_response


@given(data=st.data())
def test_check_response_accepts_the_matching_reply(data: st.DataObject) -> None:
    request = data.draw(REQUEST_STRATEGIES[DiagnosticsRequest])
    reply_data = request.data
    if request.sub_function in COUNTER_SUB_FUNCTIONS:
        reply_data = data.draw(st.binary(min_size=2, max_size=2))
    request.check_response(DiagnosticsResponse(request.sub_function, reply_data))


@pytest.mark.parametrize(
    ("request_", "response"),
    [
        (ReadExceptionStatusRequest(), ReadExceptionStatusResponse(0)),
        (GetCommEventCounterRequest(), GetCommEventCounterResponse(0, 0)),
        (GetCommEventLogRequest(), GetCommEventLogResponse(0, 0, 0)),
        (ReportServerIdRequest(), ReportServerIdResponse(b"\x01", True)),
        (DiagnosticsRequest(0x0A), DiagnosticsResponse(0x0A, b"\x00\x00")),
        (DiagnosticsRequest(0x99, b"abc"), DiagnosticsResponse(0x99, b"other")),
    ],
)
def test_check_response_passes(request_: Any, response: Any) -> None:
    request_.check_response(response)


@pytest.mark.parametrize(
    ("request_", "response", "field"),
    [
        (DiagnosticsRequest(0, b"\x01\x02"), DiagnosticsResponse(0, b"\x01\x03"), "data"),
        (DiagnosticsRequest(0, b"\x01\x02"), DiagnosticsResponse(0, b""), "data"),
        (DiagnosticsRequest(1, b"\xff\x00"), DiagnosticsResponse(1, b"\x00\x00"), "data"),
        (DiagnosticsRequest(3, b"\x3a\x00"), DiagnosticsResponse(3, b"\x0a\x00"), "data"),
        (DiagnosticsRequest(0x0B), DiagnosticsResponse(0x0C, b"\x00\x05"), "sub_function"),
        (ReadExceptionStatusRequest(), GetCommEventCounterResponse(0, 0), None),
        (ReportServerIdRequest(), ReadExceptionStatusResponse(0), None),
        (GetCommEventLogRequest(), GetCommEventCounterResponse(0, 0), None),
    ],
)
def test_check_response_mismatch(request_: Any, response: Any, field: str | None) -> None:
    with pytest.raises(MalformedPDU) as caught:
        request_.check_response(response)
    assert caught.value.field == field


def test_registered() -> None:
    from aiortu.core.pdu import known_function_codes

    assert set(CODES) <= known_function_codes()
    assert FunctionCode.DIAGNOSTICS in CODES
    assert isinstance(decode_response(bytes.fromhex("11 02 01 FF")), ReportServerIdResponse)

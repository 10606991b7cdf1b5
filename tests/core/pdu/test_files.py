"""The PDUs of the file records: read file record (14) and write file record (15)."""

from __future__ import annotations

from typing import Any

import pytest
from hypothesis import given
from hypothesis import strategies as st

from aiortu.core.errors import InvalidRequest, InvalidValue, MalformedPDU
from aiortu.core.pdu import (
    FileRecord,
    FileRecordRequest,
    ReadFileRecordRequest,
    ReadFileRecordResponse,
    WriteFileRecordRequest,
    WriteFileRecordResponse,
    decode_request,
    decode_response,
)
from aiortu.core.pdu import _files as pf
from tests.core.pdu_contract import assert_invalid, assert_only_malformed, assert_round_trip
from tests.core.strategies_serial_files_devid import (
    REQUEST_STRATEGIES,
    RESPONSE_STRATEGIES,
    mutations,
)

REQUESTS = [ReadFileRecordRequest, WriteFileRecordRequest]
RESPONSES = [ReadFileRecordResponse, WriteFileRecordResponse]

SPEC_READ = ReadFileRecordRequest((FileRecordRequest(4, 1, 2), FileRecordRequest(3, 9, 2)))
SPEC_READ_WIRE = "14 0E 06 00 04 00 01 00 02 06 00 03 00 09 00 02"
SPEC_READ_REPLY = ReadFileRecordResponse(((0x0DFE, 0x0020), (0x33CD, 0x0040)))
SPEC_READ_REPLY_WIRE = "14 0C 05 06 0D FE 00 20 05 06 33 CD 00 40"
SPEC_WRITE = WriteFileRecordRequest((FileRecord(4, 7, (0x06AF, 0x04BE, 0x100D)),))
SPEC_WRITE_WIRE = "15 0D 06 00 04 00 07 00 03 06 AF 04 BE 10 0D"


def test_public_names() -> None:
    assert isinstance(pf.__all__, tuple)
    assert all(hasattr(pf, name) for name in pf.__all__)
    assert WriteFileRecordRequest.broadcastable
    assert not ReadFileRecordRequest.broadcastable


@pytest.mark.parametrize("cls", REQUESTS, ids=lambda cls: cls.__name__)
@given(data=st.data())
def test_request_round_trip(cls: type, data: st.DataObject) -> None:
    assert_round_trip(data.draw(REQUEST_STRATEGIES[cls]))


@pytest.mark.parametrize("cls", RESPONSES, ids=lambda cls: cls.__name__)
@given(data=st.data())
def test_response_round_trip(cls: type, data: st.DataObject) -> None:
    assert_round_trip(data.draw(RESPONSE_STRATEGIES[cls]))


@pytest.mark.parametrize(
    ("pdu", "wire"),
    [
        (SPEC_READ, SPEC_READ_WIRE),
        (SPEC_READ_REPLY, SPEC_READ_REPLY_WIRE),
        (SPEC_WRITE, SPEC_WRITE_WIRE),
        (WriteFileRecordResponse(SPEC_WRITE.records), SPEC_WRITE_WIRE),
    ],
    ids=repr,
)
def test_spec_vectors(pdu: Any, wire: str) -> None:
    assert pdu.encode() == bytes.fromhex(wire)
    assert_round_trip(pdu)
    SPEC_READ.check_response(SPEC_READ_REPLY)
    SPEC_WRITE.check_response(WriteFileRecordResponse(SPEC_WRITE.records))


def test_file_record_normalises_values() -> None:
    record = FileRecord(1, 2, [3, 4])  # type: ignore[arg-type]
    assert record.values == (3, 4)
    assert record.record_length == 2
    assert WriteFileRecordRequest([record]).records == (record,)  # type: ignore[arg-type]


def test_limits_at_the_edge() -> None:
    # 35 sub-requests of one record: request byte count 0xF5, reply 2 + 35 * 4 bytes.
    most = ReadFileRecordRequest(tuple(FileRecordRequest(0xFFFF, 9999, 1) for _ in range(35)))
    assert len(most.encode()) == 247
    assert most.encode()[1] == 0xF5
    # One sub-request: the reply holds at most (253 - 4) // 2 = 124 records.
    ReadFileRecordRequest((FileRecordRequest(1, 0, 124),))
    assert len(ReadFileRecordResponse((tuple(range(124)),)).encode()) == 252
    # One sub-record written: at most (253 - 9) // 2 = 122 values.
    assert len(WriteFileRecordRequest((FileRecord(1, 0, (0,) * 122),)).encode()) == 253


# Construction rejects every field out of range.

R = FileRecordRequest
W = FileRecord


@pytest.mark.parametrize(
    ("build", "error", "field", "value", "allowed"),
    [
        (lambda: ReadFileRecordRequest(()), InvalidRequest, "len(sub_requests)", 0, range(1, 36)),
        (
            lambda: ReadFileRecordRequest((R(1, 0, 1),) * 36),
            InvalidRequest,
            "len(sub_requests)",
            36,
            range(1, 36),
        ),
        (
            lambda: ReadFileRecordRequest((R(1, 0, 1), R(0, 0, 1))),
            InvalidRequest,
            "sub_requests[1].file_number",
            0,
            range(1, 0x10000),
        ),
        (
            lambda: ReadFileRecordRequest((R(0x10000, 0, 1),)),
            InvalidRequest,
            "sub_requests[0].file_number",
            0x10000,
            range(1, 0x10000),
        ),
        (
            lambda: ReadFileRecordRequest((R(1, 10000, 1),)),
            InvalidRequest,
            "sub_requests[0].record_number",
            10000,
            range(10000),
        ),
        (
            lambda: ReadFileRecordRequest((R(1, -1, 1),)),
            InvalidRequest,
            "sub_requests[0].record_number",
            -1,
            range(10000),
        ),
        (
            lambda: ReadFileRecordRequest((R(1, 0, 0),)),
            InvalidRequest,
            "sub_requests[0].record_length",
            0,
            range(1, 10001),
        ),
        (
            lambda: ReadFileRecordRequest((R(1, 9990, 11),)),
            InvalidRequest,
            "sub_requests[0].record_number + record_length",
            10001,
            range(10001),
        ),
        (
            lambda: ReadFileRecordRequest((R(1, 0, 125),)),
            InvalidRequest,
            "len(response PDU)",
            254,
            range(254),
        ),
        (
            lambda: ReadFileRecordRequest((R(1, 0, 60), R(2, 0, 64))),
            InvalidRequest,
            "len(response PDU)",
            254,
            range(254),
        ),
        (lambda: ReadFileRecordResponse(()), InvalidValue, "len(records)", 0, None),
        (lambda: ReadFileRecordResponse(((1,), ())), InvalidValue, "len(records[1])", 0, None),
        (
            lambda: ReadFileRecordResponse(((1, 0x10000),)),
            InvalidValue,
            "records[0][1]",
            0x10000,
            range(0x10000),
        ),
        (
            lambda: ReadFileRecordResponse(((-1,),)),
            InvalidValue,
            "records[0][0]",
            -1,
            range(0x10000),
        ),
        (
            lambda: ReadFileRecordResponse(((0,) * 125,)),
            InvalidValue,
            "len(PDU)",
            254,
            range(254),
        ),
        (lambda: WriteFileRecordRequest(()), InvalidRequest, "len(records)", 0, None),
        (
            lambda: WriteFileRecordRequest((W(0, 0, (1,)),)),
            InvalidRequest,
            "records[0].file_number",
            0,
            range(1, 0x10000),
        ),
        (
            lambda: WriteFileRecordResponse((W(0, 0, (1,)),)),
            InvalidValue,
            "records[0].file_number",
            0,
            range(1, 0x10000),
        ),
        (
            lambda: WriteFileRecordRequest((W(1, 0, (1,)), W(1, 10000, (1,)))),
            InvalidRequest,
            "records[1].record_number",
            10000,
            range(10000),
        ),
        (
            lambda: WriteFileRecordRequest((W(1, 0, ()),)),
            InvalidRequest,
            "records[0].record_length",
            0,
            range(1, 10001),
        ),
        (
            lambda: WriteFileRecordRequest((W(1, 9999, (1, 2)),)),
            InvalidRequest,
            "records[0].record_number + record_length",
            10001,
            range(10001),
        ),
        (
            lambda: WriteFileRecordRequest((W(1, 0, (1, 0x10000)),)),
            InvalidRequest,
            "records[0].values[1]",
            0x10000,
            range(0x10000),
        ),
        (
            lambda: WriteFileRecordRequest((W(1, 0, (0,) * 123),)),
            InvalidRequest,
            "len(PDU)",
            255,
            range(254),
        ),
        (
            lambda: WriteFileRecordResponse((W(1, 0, (0,) * 60), W(1, 0, (0,) * 60))),
            InvalidValue,
            "len(PDU)",
            256,
            range(254),
        ),
    ],
)
def test_fields_out_of_range(
    build: Any, error: type[InvalidValue], field: str, value: object, allowed: object
) -> None:
    assert_invalid(build, error, field, value, allowed)


# Decoding: wrong bytes give MalformedPDU with the exception code a slave answers.


@pytest.mark.parametrize(
    ("decode", "wire", "field", "code"),
    [
        (decode_request, "14 06 06 00 01 00 00 00", "length", 3),
        (decode_request, "14 08 06 00 01 00 00 00 01 00", "byte_count", 3),
        (decode_request, "14 07 06 00 01 00 00 00", "length", 3),
        (decode_request, "14 07 05 00 01 00 00 00 01", "sub_requests[0].reference_type", 2),
        (decode_request, "14 07 06 00 00 00 00 00 01", "sub_requests[0].file_number", 2),
        (decode_request, "14 07 06 00 01 27 10 00 01", "sub_requests[0].record_number", 2),
        (
            decode_request,
            "14 07 06 00 01 27 0F 00 02",
            "sub_requests[0].record_number + record_length",
            2,
        ),
        (decode_request, "14 07 06 00 01 00 00 00 00", "sub_requests[0].record_length", 3),
        (decode_request, "14 07 06 00 01 00 00 00 7D", "len(response PDU)", 3),
        (decode_response, "14 04 03 06 00", "length", 3),
        (decode_response, "14 04 04 06 00 01", "records[0] length", 3),
        (decode_response, "14 05 03 06 00 01 01", "records[1] length", 3),
        (decode_response, "14 05 05 06 00 01 00", "records[0] length", 3),
        (decode_response, "14 04 03 07 00 01", "records[0].reference_type", 2),
        (decode_request, "15 09 06 00 01 00 00 00 01 00", "length", 3),
        (decode_request, "15 08 06 00 01 00 00 00 00 00 00", "byte_count", 3),
        (decode_request, "15 0A 06 00 01 00 00 00 01 00 01 06", "records[1] header", 3),
        (decode_request, "15 09 06 00 01 00 00 00 02 00 01", "records[0].record_length", 3),
        (decode_request, "15 09 06 00 00 00 00 00 01 00 01", "records[0].file_number", 2),
        (decode_request, "15 09 01 00 01 00 00 00 01 00 01", "records[0].reference_type", 2),
        (decode_response, "15 09 06 00 01 27 10 00 01 00 01", "records[0].record_number", 2),
        (
            decode_request,
            "15 10 06 00 01 00 00 00 00 06 00 01 00 00 00 01 00 05",
            "records[0].record_length",
            3,
        ),
    ],
    ids=str,
)
def test_malformed_vectors(decode: Any, wire: str, field: str, code: int) -> None:
    with pytest.raises(MalformedPDU) as caught:
        decode(bytes.fromhex(wire))
    assert caught.value.field == field
    assert caught.value.exception_code == code


def test_a_bad_record_length_names_the_odd_lengths_that_fit() -> None:
    # A record is its reference type and whole registers: 3, 5, ... bytes, up to the PDU's end.
    with pytest.raises(MalformedPDU) as caught:
        decode_response(bytes.fromhex("14 06 04 06 00 01 00 02"))
    assert caught.value.allowed == range(3, 6, 2)
    assert str(caught.value).endswith("records[0] length = 4, allowed 3..5 in steps of 2")


encoded = st.one_of(
    *(REQUEST_STRATEGIES[cls] for cls in REQUESTS),
    *(RESPONSE_STRATEGIES[cls] for cls in RESPONSES),
).map(lambda pdu: pdu.encode())


@given(code=st.sampled_from((0x14, 0x15)), body=st.binary(max_size=260))
def test_arbitrary_bytes_only_malformed(code: int, body: bytes) -> None:
    data = bytes((code,)) + body
    assert_only_malformed(decode_request, data)
    assert_only_malformed(decode_response, data)


@given(data=mutations(encoded))
def test_mutations_only_malformed(data: bytes) -> None:
    assert_only_malformed(decode_request, data)
    assert_only_malformed(decode_response, data)


@st.composite
def plausible_read_requests(draw: st.DrawFn) -> bytes:
    # Well-formed framing with random fields, to reach the checks behind the byte count.
    count = draw(st.integers(1, 35))
    body = b"".join(
        bytes((draw(st.sampled_from((6, 6, 6, 0, 7))),)) + draw(st.binary(min_size=6, max_size=6))
        for _ in range(count)
    )
    return bytes((0x14, len(body))) + body


@given(data=plausible_read_requests())
def test_plausible_read_requests_only_malformed(data: bytes) -> None:
    assert_only_malformed(decode_request, data)


# check_response


@given(data=st.data())
def test_check_response_accepts_a_matching_read_reply(data: st.DataObject) -> None:
    request = data.draw(REQUEST_STRATEGIES[ReadFileRecordRequest])
    records = tuple(
        tuple(data.draw(st.lists(st.integers(0, 0xFFFF), min_size=n, max_size=n)))
        for n in (sub.record_length for sub in request.sub_requests)
    )
    request.check_response(ReadFileRecordResponse(records))


@given(data=st.data())
def test_check_response_accepts_the_write_echo(data: st.DataObject) -> None:
    request = data.draw(REQUEST_STRATEGIES[WriteFileRecordRequest])
    request.check_response(WriteFileRecordResponse.decode(request.encode()))


@pytest.mark.parametrize(
    ("request_", "response", "field"),
    [
        (SPEC_READ, ReadFileRecordResponse(((1, 2),)), "len(records)"),
        (SPEC_READ, ReadFileRecordResponse(((1, 2), (3, 4), (5,))), "len(records)"),
        (SPEC_READ, ReadFileRecordResponse(((1, 2), (3,))), "len(records[1])"),
        (SPEC_READ, WriteFileRecordResponse(SPEC_WRITE.records), None),
        (SPEC_WRITE, WriteFileRecordResponse((W(4, 7, (0x06AF, 0x04BE, 0x100E)),)), "records"),
        (SPEC_WRITE, WriteFileRecordResponse((W(4, 8, (0x06AF, 0x04BE, 0x100D)),)), "records"),
        (SPEC_WRITE, WriteFileRecordResponse(SPEC_WRITE.records * 2), "records"),
        (SPEC_WRITE, SPEC_READ_REPLY, None),
    ],
)
def test_check_response_mismatch(request_: Any, response: Any, field: str | None) -> None:
    with pytest.raises(MalformedPDU) as caught:
        request_.check_response(response)
    assert caught.value.field == field

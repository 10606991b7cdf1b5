"""Hypothesis strategies for the PDUs of the serial-line functions (07, 08, 0B, 0C, 11), the
file records (14, 15) and read device identification (2B/0E).

Every strategy draws only valid objects whose ``decode(encode())`` gives them back, so
report server ID draws a server id whose later bytes hold no 0x00 or 0xFF (see the decode
rule of :class:`ReportServerIdResponse`).
"""

from __future__ import annotations

from typing import Any

from hypothesis import strategies as st
from hypothesis.strategies import DrawFn, SearchStrategy

from aiortu.core.codes import DeviceIdReadCode, DiagnosticSubFunction
from aiortu.core.pdu import (
    CONFORMITY_LEVELS,
    DiagnosticsRequest,
    DiagnosticsResponse,
    FileRecord,
    FileRecordRequest,
    GetCommEventCounterRequest,
    GetCommEventCounterResponse,
    GetCommEventLogRequest,
    GetCommEventLogResponse,
    ReadDeviceIdentificationRequest,
    ReadDeviceIdentificationResponse,
    ReadExceptionStatusRequest,
    ReadExceptionStatusResponse,
    ReadFileRecordRequest,
    ReadFileRecordResponse,
    ReportServerIdRequest,
    ReportServerIdResponse,
    WriteFileRecordRequest,
    WriteFileRecordResponse,
)

__all__ = (
    "REQUEST_STRATEGIES",
    "RESPONSE_STRATEGIES",
    "ZERO_WORD_SUB_FUNCTIONS",
    "COUNTER_SUB_FUNCTIONS",
    "UNKNOWN_SUB_FUNCTIONS",
    "mutations",
)

S = DiagnosticSubFunction
COUNTER_SUB_FUNCTIONS = (
    S.RETURN_DIAGNOSTIC_REGISTER,
    *(member for member in S if 0x0A <= member <= 0x14),
)
"""Request data 0x0000, reply one 16-bit value."""
ZERO_WORD_SUB_FUNCTIONS = (*COUNTER_SUB_FUNCTIONS, S.FORCE_LISTEN_ONLY_MODE)
"""Request data 0x0000."""
UNKNOWN_SUB_FUNCTIONS = st.integers(0, 0xFFFF).filter(lambda value: value not in set(S))

words = st.integers(0, 0xFFFF)
byte_values = st.integers(0, 0xFF)
word_bytes = words.map(lambda value: value.to_bytes(2, "big"))
status_words = st.sampled_from((0x0000, 0xFFFF))
even_data = st.lists(word_bytes, max_size=125).map(b"".join)
restart_data = st.sampled_from((b"\x00\x00", b"\xff\x00"))
delimiter_data = byte_values.map(lambda char: bytes((char, 0)))


def _diagnostics(cls: type[Any], *, reply: bool) -> SearchStrategy[Any]:
    counters = (
        st.builds(cls, st.sampled_from(COUNTER_SUB_FUNCTIONS), word_bytes)
        if reply
        else st.builds(cls, st.sampled_from(COUNTER_SUB_FUNCTIONS), st.just(b"\x00\x00"))
    )
    return st.one_of(
        st.builds(cls, st.just(S.RETURN_QUERY_DATA), even_data),
        st.builds(cls, st.just(S.RESTART_COMMUNICATIONS), restart_data),
        st.builds(cls, st.just(S.CHANGE_ASCII_INPUT_DELIMITER), delimiter_data),
        st.builds(cls, st.just(S.FORCE_LISTEN_ONLY_MODE), st.just(b"\x00\x00")),
        counters,
        st.builds(cls, UNKNOWN_SUB_FUNCTIONS, st.binary(max_size=250)),
    )


def _sizes(draw: DrawFn, count: int, budget: int, low: int = 1, high: int = 10**9) -> list[int]:
    """*count* sizes in low..high that add up to at most *budget* (budget >= count * low)."""
    sizes = []
    for left in range(count, 0, -1):
        most = min(high, budget - (left - 1) * low)
        size = draw(st.integers(low, most))
        sizes.append(size)
        budget -= size
    return sizes


@st.composite
def read_file_record_requests(draw: DrawFn) -> ReadFileRecordRequest:
    count = draw(st.integers(1, 35))
    # The reply must fit: 2 + sum(2 + 2 * length) <= 253.
    lengths = _sizes(draw, count, (251 - 2 * count) // 2)
    subs = tuple(
        FileRecordRequest(
            draw(st.integers(1, 0xFFFF)), draw(st.integers(0, 10000 - length)), length
        )
        for length in lengths
    )
    return ReadFileRecordRequest(subs)


@st.composite
def read_file_record_responses(draw: DrawFn) -> ReadFileRecordResponse:
    count = draw(st.integers(1, 40))
    lengths = _sizes(draw, count, (251 - 2 * count) // 2)
    return ReadFileRecordResponse(
        tuple(tuple(draw(st.lists(words, min_size=n, max_size=n))) for n in lengths)
    )


@st.composite
def file_records(draw: DrawFn) -> tuple[FileRecord, ...]:
    count = draw(st.integers(1, 20))
    # 2 + sum(7 + 2 * length) <= 253.
    lengths = _sizes(draw, count, (251 - 7 * count) // 2)
    return tuple(
        FileRecord(
            draw(st.integers(1, 0xFFFF)),
            draw(st.integers(0, 10000 - n)),
            tuple(draw(st.lists(words, min_size=n, max_size=n))),
        )
        for n in lengths
    )


@st.composite
def report_server_id_responses(draw: DrawFn) -> ReportServerIdResponse:
    first = draw(byte_values)
    rest = draw(st.binary(max_size=20)).replace(b"\x00", b"").replace(b"\xff", b"")
    server_id = bytes((first,)) + rest
    additional = draw(st.binary(max_size=250 - len(server_id)))
    return ReportServerIdResponse(server_id, draw(st.booleans()), additional)


@st.composite
def device_id_responses(draw: DrawFn) -> ReadDeviceIdentificationResponse:
    count = draw(st.integers(0, 12))
    # 7 + sum(2 + len(value)) <= 253.
    lengths = _sizes(draw, count, 246 - 2 * count, low=0, high=255) if count else []
    objects = tuple((draw(byte_values), draw(st.binary(min_size=n, max_size=n))) for n in lengths)
    return ReadDeviceIdentificationResponse(
        draw(st.sampled_from(DeviceIdReadCode)),
        draw(st.sampled_from(CONFORMITY_LEVELS)),
        objects,
        draw(st.booleans()),
        draw(byte_values),
    )


REQUEST_STRATEGIES: dict[type, SearchStrategy[Any]] = {
    ReadExceptionStatusRequest: st.just(ReadExceptionStatusRequest()),
    DiagnosticsRequest: _diagnostics(DiagnosticsRequest, reply=False),
    GetCommEventCounterRequest: st.just(GetCommEventCounterRequest()),
    GetCommEventLogRequest: st.just(GetCommEventLogRequest()),
    ReportServerIdRequest: st.just(ReportServerIdRequest()),
    ReadFileRecordRequest: read_file_record_requests(),
    WriteFileRecordRequest: file_records().map(WriteFileRecordRequest),
    ReadDeviceIdentificationRequest: st.builds(
        ReadDeviceIdentificationRequest, st.sampled_from(DeviceIdReadCode), byte_values
    ),
}

RESPONSE_STRATEGIES: dict[type, SearchStrategy[Any]] = {
    ReadExceptionStatusResponse: st.builds(ReadExceptionStatusResponse, byte_values),
    DiagnosticsResponse: _diagnostics(DiagnosticsResponse, reply=True),
    GetCommEventCounterResponse: st.builds(GetCommEventCounterResponse, status_words, words),
    GetCommEventLogResponse: st.builds(
        GetCommEventLogResponse, status_words, words, words, st.binary(max_size=64)
    ),
    ReportServerIdResponse: report_server_id_responses(),
    ReadFileRecordResponse: read_file_record_responses(),
    WriteFileRecordResponse: file_records().map(WriteFileRecordResponse),
    ReadDeviceIdentificationResponse: device_id_responses(),
}


@st.composite
def mutations(draw: DrawFn, pdus: SearchStrategy[bytes]) -> bytes:
    """A valid PDU from *pdus*, truncated, extended, or with one byte changed."""
    data = bytearray(draw(pdus))
    kind = draw(st.sampled_from(("truncate", "extend", "flip")))
    if kind == "truncate":
        return bytes(data[: draw(st.integers(1, max(1, len(data) - 1)))])
    if kind == "extend":
        return bytes(data) + draw(st.binary(min_size=1, max_size=8))
    index = draw(st.integers(1, len(data) - 1)) if len(data) > 1 else 0
    data[index] ^= draw(st.integers(1, 0xFF))
    return bytes(data)
